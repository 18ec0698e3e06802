"""Compiled vehicle-frame velocity and its Jacobian (see :mod:`mixnav.measurements.vehicle`).

NHC runs at up to 10 Hz over hour-long drives: in Python each epoch cost ~60 us
of small-array overhead, the largest share of an aided filter's time
(benchmarks/results/aiding_drive0708.md). One compiled call does it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..ins._kernels import quat_to_dcm_into


@njit(cache=True)
def vehicle_velocity_jac(nav, w_b, lever, rpy, n, i_mount):
    """``v_v`` (3,) [m/s] of the vehicle point at ``lever`` (body [m]) and its Jacobian
    ``H`` (3, n) over the error state; ``rpy`` the mounting (roll, pitch, yaw) [rad] with
    any estimated corrections already added; ``i_mount`` the first column of the
    mounting (pitch, yaw) states or -1."""
    sr, cr = math.sin(rpy[0]), math.cos(rpy[0])
    sp, cp = math.sin(rpy[1]), math.cos(rpy[1])
    sy, cy = math.sin(rpy[2]), math.cos(rpy[2])
    cvb = np.empty((3, 3))                       # euler_to_dcm(rpy)
    cvb[0, 0], cvb[0, 1], cvb[0, 2] = cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy
    cvb[1, 0], cvb[1, 1], cvb[1, 2] = cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy
    cvb[2, 0], cvb[2, 1], cvb[2, 2] = -sp, sr * cp, cr * cp
    cnb = np.empty((3, 3))
    quat_to_dcm_into(nav[0:4], cnb)
    vn = nav[4:7]
    # v_b = C_bn v_n + w_b x l
    v_b = np.empty(3)
    for i in range(3):
        v_b[i] = cnb[0, i] * vn[0] + cnb[1, i] * vn[1] + cnb[2, i] * vn[2]
    v_b[0] += w_b[1] * lever[2] - w_b[2] * lever[1]
    v_b[1] += w_b[2] * lever[0] - w_b[0] * lever[2]
    v_b[2] += w_b[0] * lever[1] - w_b[1] * lever[0]
    v_v = cvb @ v_b
    cvn = np.empty((3, 3))                       # C_vb C_bn
    for i in range(3):
        for j in range(3):
            cvn[i, j] = cvb[i, 0] * cnb[j, 0] + cvb[i, 1] * cnb[j, 1] + cvb[i, 2] * cnb[j, 2]
    H = np.zeros((3, n))
    # d/dphi: C_vn [v_n x]; d/ddv: C_vn; d/ddbg: C_vb [l x]
    for i in range(3):
        H[i, 0] = cvn[i, 1] * vn[2] - cvn[i, 2] * vn[1]
        H[i, 1] = -cvn[i, 0] * vn[2] + cvn[i, 2] * vn[0]
        H[i, 2] = cvn[i, 0] * vn[1] - cvn[i, 1] * vn[0]
        for j in range(3):
            H[i, 3 + j] = cvn[i, j]
        H[i, 9] = cvb[i, 1] * lever[2] - cvb[i, 2] * lever[1]
        H[i, 10] = -cvb[i, 0] * lever[2] + cvb[i, 2] * lever[0]
        H[i, 11] = cvb[i, 0] * lever[1] - cvb[i, 1] * lever[0]
    if i_mount >= 0:
        # pitch about Rz(yaw) e_y = (-sy, cy, 0); yaw about e_z: columns a x v_v
        H[0, i_mount] = cy * v_v[2]
        H[1, i_mount] = sy * v_v[2]
        H[2, i_mount] = -sy * v_v[1] - cy * v_v[0]
        H[0, i_mount + 1] = -v_v[1]
        H[1, i_mount + 1] = v_v[0]
        H[2, i_mount + 1] = 0.0
    return v_v, H
