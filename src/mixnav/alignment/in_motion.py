"""In-motion alignment from GNSS velocity (for IMUs that cannot sense Earth rate).

A land vehicle moves along its body x axis, so once it drives fast enough
the GNSS velocity gives the heading ``atan2(vE, vN)`` and the pitch
``atan2(-vD, |v_h|)``; roll is set to zero and left to the filter (its sigma
should say so). Without GNSS velocity the velocity comes from central
differences of the positions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..attitude import euler_to_quat, quat_to_dcm
from ..data import GnssFixes
from ..errors import DataError
from ..geodesy.frames import ned_displacement
from ..geodesy.frames import displace


@dataclass(frozen=True)
class MotionAlignment:
    time: float
    q_nb: np.ndarray
    v_n: np.ndarray
    lla: np.ndarray      # of the IMU
    index: int           # the fix used


def fix_velocities(fixes: GnssFixes) -> np.ndarray:
    """GNSS velocity, or central differences of the positions when absent."""
    if fixes.vel_n is not None:
        return fixes.vel_n
    d = ned_displacement(fixes.lla, fixes.lla[0])
    v = np.gradient(d, fixes.time, axis=0)
    return v


def align_from_gnss_velocity(fixes: GnssFixes, lever_b: np.ndarray, min_speed: float,
                             after: float = -np.inf) -> MotionAlignment:
    """Attitude, velocity and IMU position at the first fix moving at ``min_speed`` or more.

    Parameters
    ----------
    fixes : GnssFixes
    lever_b : ndarray (3,)
        Antenna relative to the IMU in the body frame [m].
    min_speed : float
        [m/s].
    after : float
        Only fixes after this time [s] are considered.

    Raises
    ------
    DataError
        If no fix reaches the speed.
    """
    v = fix_velocities(fixes)
    speed = np.hypot(v[:, 0], v[:, 1])
    ok = np.nonzero((speed >= min_speed) & (fixes.time > after))[0]
    if ok.size == 0:
        raise DataError(f"no GNSS epoch reaches {min_speed:g} m/s: cannot align in motion "
                        f"(fastest {speed.max():.2f} m/s)", file=fixes.source)
    i = int(ok[0])
    yaw = np.arctan2(v[i, 1], v[i, 0])
    pitch = np.arctan2(-v[i, 2], speed[i])
    q = euler_to_quat(np.array([0.0, pitch, yaw]))
    d_n = quat_to_dcm(q) @ np.asarray(lever_b, dtype=float)
    lla = displace(fixes.lla[i], -d_n)
    return MotionAlignment(time=float(fixes.time[i]), q_nb=q, v_n=v[i].copy(), lla=lla, index=i)
