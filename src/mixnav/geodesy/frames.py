"""Geodetic, ECEF and local NED coordinates (WGS-84).

Arrays broadcast with the coordinate axis last: ``lla`` is ``(..., 3)`` with
latitude and longitude in radians and ellipsoidal height in metres.
"""

from __future__ import annotations

import numpy as np

from .earth import E2_WGS84, radii


def lla_to_ecef(lla):
    """Geodetic (lat [rad], lon [rad], h [m]) to ECEF [m], shape ``(..., 3)``."""
    lla = np.asarray(lla, dtype=float)
    lat, lon, h = lla[..., 0], lla[..., 1], lla[..., 2]
    _, rn = radii(lat)
    cl = np.cos(lat)
    return np.stack(
        [
            (rn + h) * cl * np.cos(lon),
            (rn + h) * cl * np.sin(lon),
            (rn * (1.0 - E2_WGS84) + h) * np.sin(lat),
        ],
        axis=-1,
    )


def ecef_to_lla(p_ecef):
    """ECEF [m] to geodetic (lat [rad], lon [rad], h [m]).

    Fixed-point iteration on latitude; five iterations reach below 1e-9 m for
    points from the Earth's centre region out to GNSS orbit heights except
    near the Earth's centre, which navigation never visits.
    """
    p = np.asarray(p_ecef, dtype=float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    lon = np.arctan2(y, x)
    rho = np.hypot(x, y)
    lat = np.arctan2(z, rho * (1.0 - E2_WGS84))
    for _ in range(6):
        _, rn = radii(lat)
        h = _height(rho, z, lat, rn)
        lat = np.arctan2(z, rho * (1.0 - E2_WGS84 * rn / (rn + h)))
    _, rn = radii(lat)
    h = _height(rho, z, lat, rn)
    return np.stack([lat, lon, h], axis=-1)


def _height(rho, z, lat, rn):
    # Use the better-conditioned of the two formulas: rho/cos near the
    # equator, z/sin near the poles.
    cl, sl = np.cos(lat), np.sin(lat)
    with np.errstate(divide="ignore", invalid="ignore"):
        h_eq = rho / cl - rn
        h_pole = z / sl - rn * (1.0 - E2_WGS84)
    return np.where(np.abs(cl) > np.abs(sl), h_eq, h_pole)


def dcm_ecef_to_ned(lat, lon):
    """Rotation matrix C_en taking ECEF vectors to NED, shape ``(..., 3, 3)``."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    zero = np.zeros_like(sl * so)
    return np.stack(
        [
            np.stack([-sl * co, -sl * so, cl + zero], axis=-1),
            np.stack([-so + zero, co + zero, zero], axis=-1),
            np.stack([-cl * co, -cl * so, -sl + zero], axis=-1),
        ],
        axis=-2,
    )


def lla_to_ned(lla, lla_ref):
    """Local NED coordinates [m] of ``lla`` about the reference point ``lla_ref``.

    Exact (through ECEF), not a flat-Earth approximation.
    """
    lla_ref = np.asarray(lla_ref, dtype=float)
    d = lla_to_ecef(lla) - lla_to_ecef(lla_ref)
    c_ne = dcm_ecef_to_ned(lla_ref[..., 0], lla_ref[..., 1])
    return np.einsum("...ij,...j->...i", c_ne, d)


def ned_to_lla(p_ned, lla_ref):
    """Inverse of :func:`lla_to_ned`."""
    lla_ref = np.asarray(lla_ref, dtype=float)
    c_ne = dcm_ecef_to_ned(lla_ref[..., 0], lla_ref[..., 1])
    d = np.einsum("...ji,...j->...i", c_ne, np.asarray(p_ned, dtype=float))
    return ecef_to_lla(lla_to_ecef(lla_ref) + d)


def ned_displacement(lla, lla_ref):
    """Small NED displacement [m] of ``lla`` from ``lla_ref`` in curvilinear form.

    Uses the radii of curvature at ``lla_ref``:
    ``dN = dlat (Rm + h)``, ``dE = dlon (Rn + h) cos(lat)``, ``dD = -dh``.
    This is the position-error convention of the INS error state; for metre-
    to kilometre-size differences it agrees with :func:`lla_to_ned` to the
    curvature terms.
    """
    lla = np.asarray(lla, dtype=float)
    lla_ref = np.asarray(lla_ref, dtype=float)
    lat, h = lla_ref[..., 0], lla_ref[..., 2]
    rm, rn = radii(lat)
    dlon = np.angle(np.exp(1j * (lla[..., 1] - lla_ref[..., 1])))
    return np.stack(
        [
            (lla[..., 0] - lat) * (rm + h),
            dlon * (rn + h) * np.cos(lat),
            -(lla[..., 2] - h),
        ],
        axis=-1,
    )


def displace(lla, d_ned):
    """Move ``lla`` by a small NED displacement [m]: the inverse of
    :func:`ned_displacement` (radii at the starting point).

    Parameters
    ----------
    lla : array_like (..., 3)
    d_ned : array_like (..., 3)
        North, east, down [m].
    """
    lla = np.asarray(lla, dtype=float)
    d = np.asarray(d_ned, dtype=float)
    lat, h = lla[..., 0], lla[..., 2]
    rm, rn = radii(lat)
    return np.stack([lat + d[..., 0] / (rm + h), lla[..., 1] + d[..., 1] / ((rn + h) * np.cos(lat)),
                     h - d[..., 2]], axis=-1)
