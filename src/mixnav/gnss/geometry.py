"""Line-of-sight geometry shared by every GNSS model in mixnav.

Every satellite source (the nominal constellation, broadcast ephemeris) hands
out :class:`SatelliteStates`: ECEF positions and velocities and the satellite
clock of the satellites it knows at one GPS time. Receiver code works on these
arrays only, so simulation and real data share the measurement models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geodesy.frames import dcm_ecef_to_ned, ecef_to_lla

#: Speed of light [m/s] (IS-GPS-200).
C_LIGHT = 299_792_458.0
#: WGS-84 Earth rotation rate used by GPS [rad/s] (IS-GPS-200).
OMEGA_E_GPS = 7.2921151467e-5
#: GPS value of the Earth's gravitational constant [m^3/s^2] (IS-GPS-200).
GM_GPS = 3.986005e14
#: GPS L1 carrier frequency [Hz] and wavelength [m].
F_L1 = 1575.42e6
LAMBDA_L1 = C_LIGHT / F_L1
#: Seconds in a GPS week.
SECONDS_PER_WEEK = 604_800.0


@dataclass(frozen=True)
class SatelliteStates:
    """Satellites at one GPS time (transmit or receive time, as the caller asked).

    Attributes
    ----------
    prn : ndarray of int (n,)
        Satellite numbers.
    pos_ecef : ndarray (n, 3)
        [m], ECEF (WGS-84) at the time asked for.
    vel_ecef : ndarray (n, 3)
        [m/s], in the rotating ECEF frame.
    clock_bias : ndarray (n,)
        Satellite clock offset [s] (relativistic correction included when the
        source models it); the pseudorange carries ``-c * clock_bias``.
    clock_drift : ndarray (n,)
        [s/s].
    """

    prn: np.ndarray
    pos_ecef: np.ndarray
    vel_ecef: np.ndarray
    clock_bias: np.ndarray
    clock_drift: np.ndarray

    def __len__(self) -> int:
        return len(self.prn)

    def select(self, mask) -> "SatelliteStates":
        """The satellites where ``mask`` (bool (n,) or index array) selects."""
        return SatelliteStates(self.prn[mask], self.pos_ecef[mask], self.vel_ecef[mask],
                               self.clock_bias[mask], self.clock_drift[mask])


def earth_rotation_correction(sat_ecef: np.ndarray, travel_time) -> np.ndarray:
    """Satellite ECEF positions rotated into the ECEF frame of the reception time.

    The ECEF frame turns by ``OMEGA_E_GPS * tau`` while the signal travels for
    ``tau`` seconds (Sagnac effect, up to ~30 m of range).

    Parameters
    ----------
    sat_ecef : ndarray (..., 3)
        Positions at the transmit time in the ECEF frame of that time [m].
    travel_time : float or ndarray (...)
        [s].
    """
    sat_ecef = np.asarray(sat_ecef, dtype=float)
    a = OMEGA_E_GPS * np.asarray(travel_time, dtype=float)
    c, s = np.cos(a), np.sin(a)
    x, y, z = sat_ecef[..., 0], sat_ecef[..., 1], sat_ecef[..., 2]
    return np.stack([c * x + s * y, -s * x + c * y, np.broadcast_to(z, np.shape(c * x))], axis=-1)


def line_of_sight(rx_ecef: np.ndarray, sat_ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Geometric range [m] (..., ) and unit vector receiver -> satellite (..., 3)."""
    d = np.asarray(sat_ecef, dtype=float) - np.asarray(rx_ecef, dtype=float)
    r = np.linalg.norm(d, axis=-1)
    return r, d / r[..., None]


def elevation_azimuth(rx_ecef: np.ndarray, sat_ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Elevation and azimuth [rad] of satellites seen from one receiver.

    Parameters
    ----------
    rx_ecef : ndarray (3,)
        Receiver position [m].
    sat_ecef : ndarray (n, 3)
        Satellite positions [m].

    Returns
    -------
    elevation : ndarray (n,)
        Above the local ellipsoidal horizon, in [-pi/2, pi/2].
    azimuth : ndarray (n,)
        From north through east, in [0, 2 pi).
    """
    rx = np.asarray(rx_ecef, dtype=float).reshape(3)
    lla = ecef_to_lla(rx)
    C_ne = dcm_ecef_to_ned(lla[0], lla[1])
    _, u = line_of_sight(rx, sat_ecef)
    u_n = u @ C_ne.T  # (n, 3) in NED
    el = np.arcsin(np.clip(-u_n[:, 2], -1.0, 1.0))
    az = np.mod(np.arctan2(u_n[:, 1], u_n[:, 0]), 2 * np.pi)
    return el, az


def above_mask(rx_ecef: np.ndarray, sat_ecef: np.ndarray, mask_angle: float) -> np.ndarray:
    """bool (n,): satellites at or above ``mask_angle`` [rad]."""
    el, _ = elevation_azimuth(rx_ecef, sat_ecef)
    return el >= mask_angle
