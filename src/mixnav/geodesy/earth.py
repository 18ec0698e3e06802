"""WGS-84 Earth model: radii of curvature, normal gravity, Earth and transport rate.

All functions take latitude in radians and height in metres, broadcast over
numpy arrays, and use only arithmetic numba can compile, so the INS kernels
(`mixnav.ins._kernels`) jit these same functions instead of keeping twins.
"""

from __future__ import annotations

import numpy as np

#: Semi-major axis [m].
A_WGS84 = 6378137.0
#: Flattening.
F_WGS84 = 1.0 / 298.257223563
#: First eccentricity squared.
E2_WGS84 = F_WGS84 * (2.0 - F_WGS84)
#: Earth rotation rate [rad/s].
OMEGA_EARTH = 7.2921151467e-5

# Somigliana normal gravity on the ellipsoid and its free-air height terms
# (as used by KF-GINS and the Chinese INS textbooks the papers follow).
_GAMMA_E = 9.7803253359  # gravity at the equator [m/s^2]
_K_SOMIGLIANA = 0.00193185265241
_H1 = 3.087691089e-6  # [1/s^2]
_H1_LAT = 4.397731e-9  # [1/s^2]
_H2 = 0.721e-12  # [1/(m s^2)]


def radii(lat):
    """Meridian and prime-vertical radii of curvature.

    Parameters
    ----------
    lat : float or ndarray
        Geodetic latitude [rad].

    Returns
    -------
    rm, rn : float or ndarray
        Meridian (north-south) and prime-vertical (east-west) radii [m].
    """
    return radii_from_sin(np.sin(lat))


def radii_from_sin(s):
    """:func:`radii` from ``s = sin(lat)`` (for callers that already have the sine)."""
    s2 = s ** 2
    w = 1.0 - E2_WGS84 * s2
    rn = A_WGS84 / np.sqrt(w)
    rm = rn * (1.0 - E2_WGS84) / w
    return rm, rn


def normal_gravity(lat, h):
    """Magnitude of normal gravity (gravitation plus centrifugal) [m/s^2].

    Somigliana's formula on the ellipsoid with a second-order free-air term in
    height; points down along the ellipsoid normal.
    """
    return normal_gravity_from_sin(np.sin(lat), h)


def normal_gravity_from_sin(s, h):
    """:func:`normal_gravity` from ``s = sin(lat)``."""
    s2 = s ** 2
    g0 = _GAMMA_E * (1.0 + _K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2_WGS84 * s2)
    return g0 - (_H1 - _H1_LAT * s2) * h + _H2 * h * h


def normal_gravity_dh(lat, h):
    """Derivative of :func:`normal_gravity` with respect to height [1/s^2]."""
    s2 = np.sin(lat) ** 2
    return -(_H1 - _H1_LAT * s2) + 2.0 * _H2 * h


def gravity_ned(lat, h):
    """Normal gravity vector in NED, shape ``(..., 3)`` [m/s^2]."""
    g = normal_gravity(lat, h)
    z = np.zeros_like(g)
    return np.stack([z, z, g], axis=-1)


def earth_rate_ned(lat):
    """Earth rotation rate omega_ie^n in NED, shape ``(..., 3)`` [rad/s]."""
    lat = np.asarray(lat, dtype=float)
    return np.stack(
        [OMEGA_EARTH * np.cos(lat), np.zeros_like(lat), -OMEGA_EARTH * np.sin(lat)], axis=-1
    )


def transport_rate_ned(lat, h, v_n):
    """Transport rate omega_en^n (rotation of NED over the Earth) [rad/s].

    Parameters
    ----------
    lat, h : float or ndarray
        Latitude [rad] and ellipsoidal height [m].
    v_n : ndarray, shape (..., 3)
        Velocity north, east, down [m/s].
    """
    v_n = np.asarray(v_n, dtype=float)
    rm, rn = radii(lat)
    vn, ve = v_n[..., 0], v_n[..., 1]
    return np.stack(
        [ve / (rn + h), -vn / (rm + h), -ve * np.tan(lat) / (rn + h)], axis=-1
    )
