"""Attitude representations and their conversions.

Conventions (tested in ``tests/test_attitude.py`` against scipy):

* Quaternions are Hamilton, scalar first ``[w, x, y, z]``; ``q_nb`` rotates a
  body-frame vector into the navigation frame: ``v_n = q_nb * v_b * conj(q_nb)``.
* ``C_nb`` is the matching direction-cosine matrix: ``v_n = C_nb @ v_b``.
* Euler angles are ``[roll, pitch, yaw]`` [rad] in the aerospace z-y-x order:
  ``C_nb = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
* A rotation vector ``rv`` is axis times angle [rad]; ``exp(rv)`` is the
  rotation by that angle about that axis.

Every function broadcasts over leading axes: a quaternion is ``(..., 4)``, a
DCM ``(..., 3, 3)``, Euler angles and rotation vectors ``(..., 3)``.
"""

from __future__ import annotations

import numpy as np


def skew(v):
    """Cross-product matrix ``[v x]`` so that ``skew(a) @ b == cross(a, b)``."""
    v = np.asarray(v, dtype=float)
    if v.ndim == 1:  # one vector: a literal is ~10x cheaper than the stacks (measurement hot paths)
        x, y, w = v
        return np.array([[0.0, -w, y], [w, 0.0, -x], [-y, x, 0.0]])
    z = np.zeros_like(v[..., 0])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def wrap_angle(a):
    """Wrap angles [rad] to ``[-pi, pi)``."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def euler_to_dcm(rpy):
    """Roll, pitch, yaw [rad] to ``C_nb``."""
    rpy = np.asarray(rpy, dtype=float)
    sr, cr = np.sin(rpy[..., 0]), np.cos(rpy[..., 0])
    sp, cp = np.sin(rpy[..., 1]), np.cos(rpy[..., 1])
    sy, cy = np.sin(rpy[..., 2]), np.cos(rpy[..., 2])
    return np.stack(
        [
            np.stack([cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy], -1),
            np.stack([cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy], -1),
            np.stack([-sp, sr * cp, cr * cp], -1),
        ],
        -2,
    )


def dcm_to_euler(c_nb):
    """``C_nb`` to roll, pitch, yaw [rad]; yaw in ``(-pi, pi]``."""
    c = np.asarray(c_nb, dtype=float)
    pitch = -np.arcsin(np.clip(c[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(c[..., 2, 1], c[..., 2, 2])
    yaw = np.arctan2(c[..., 1, 0], c[..., 0, 0])
    return np.stack([roll, pitch, yaw], -1)


def quat_multiply(p, q):
    """Hamilton product ``p * q``."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        -1,
    )


def quat_conjugate(q):
    """Conjugate (inverse of a unit quaternion)."""
    q = np.array(q, dtype=float)
    q[..., 1:] *= -1.0
    return q


def quat_normalize(q):
    """Scale to unit norm with a non-negative scalar part (one sign per rotation)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_to_dcm(q):
    """Unit quaternion ``q_nb`` to ``C_nb``."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z], -1),
        ],
        -2,
    )


def dcm_to_quat(c):
    """``C_nb`` to unit quaternion, by Shepperd's method (stable for any angle)."""
    c = np.asarray(c, dtype=float)
    tr = c[..., 0, 0] + c[..., 1, 1] + c[..., 2, 2]
    # Candidates 4*q_i*q_j from each of the four pivots; pick the largest pivot.
    cand = np.stack(
        [
            np.stack([1 + tr, c[..., 2, 1] - c[..., 1, 2], c[..., 0, 2] - c[..., 2, 0], c[..., 1, 0] - c[..., 0, 1]], -1),
            np.stack([c[..., 2, 1] - c[..., 1, 2], 1 + 2 * c[..., 0, 0] - tr, c[..., 0, 1] + c[..., 1, 0], c[..., 0, 2] + c[..., 2, 0]], -1),
            np.stack([c[..., 0, 2] - c[..., 2, 0], c[..., 0, 1] + c[..., 1, 0], 1 + 2 * c[..., 1, 1] - tr, c[..., 1, 2] + c[..., 2, 1]], -1),
            np.stack([c[..., 1, 0] - c[..., 0, 1], c[..., 0, 2] + c[..., 2, 0], c[..., 1, 2] + c[..., 2, 1], 1 + 2 * c[..., 2, 2] - tr], -1),
        ],
        -2,
    )
    pivot = np.argmax(np.stack([1 + tr, 1 + 2 * c[..., 0, 0] - tr, 1 + 2 * c[..., 1, 1] - tr, 1 + 2 * c[..., 2, 2] - tr], -1), -1)
    q = np.take_along_axis(cand, pivot[..., None, None], axis=-2)[..., 0, :]
    return quat_normalize(q)


def euler_to_quat(rpy):
    """Roll, pitch, yaw [rad] to ``q_nb``."""
    rpy = np.asarray(rpy, dtype=float)
    hr, hp, hy = 0.5 * rpy[..., 0], 0.5 * rpy[..., 1], 0.5 * rpy[..., 2]
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    q = np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        -1,
    )
    return quat_normalize(q)


def quat_to_euler(q):
    """``q_nb`` to roll, pitch, yaw [rad]."""
    return dcm_to_euler(quat_to_dcm(q))


def rotvec_to_quat(rv):
    """Rotation vector [rad] to unit quaternion; exact, with a series near zero."""
    rv = np.asarray(rv, dtype=float)
    a2 = np.sum(rv * rv, axis=-1)
    a = np.sqrt(a2)
    small = a < 1e-8
    # sin(a/2)/a by its Taylor series where a is tiny, to avoid 0/0.
    safe_a = np.where(small, 1.0, a)
    k = np.where(small, 0.5 - a2 / 48.0, np.sin(0.5 * safe_a) / safe_a)
    return np.concatenate([np.cos(0.5 * a)[..., None], k[..., None] * rv], -1)


def quat_to_rotvec(q):
    """Unit quaternion to rotation vector [rad], angle in ``[0, pi]``."""
    q = quat_normalize(q)
    s = np.linalg.norm(q[..., 1:], axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 0])
    small = s < 1e-12
    k = np.where(small, 2.0, angle / np.where(small, 1.0, s))
    return k[..., None] * q[..., 1:]


def rotvec_to_dcm(rv):
    """Rotation vector [rad] to DCM."""
    return quat_to_dcm(rotvec_to_quat(rv))


def dcm_to_rotvec(c):
    """DCM to rotation vector [rad]."""
    return quat_to_rotvec(dcm_to_quat(c))


def attitude_error(q_est, q_true):
    """Attitude error of ``q_est`` as a rotation vector in the n-frame [rad].

    ``phi`` with ``C_true = exp([phi x]) C_est``: the small rotation that takes
    the estimate to the truth. This is the INS error-state convention
    (``dx = x_true - x_est``).
    """
    return quat_to_rotvec(quat_multiply(q_true, quat_conjugate(q_est)))
