"""Static coarse alignment: levelling from the accelerometers, heading from the gyros.

With the vehicle at rest the accelerometers sense ``-g`` and the gyros the
Earth rate. Solving Wahba's problem with the specific force as the exact
primary direction (scipy's ``Rotation.align_vectors`` with an infinite
weight, i.e. TRIAD) gives roll and pitch from gravity alone and the heading
from the horizontal Earth rate. MEMS gyros cannot sense the Earth rate
(15 deg/h against biases of 10-1000 deg/h): for them pass
``use_gyro_heading=False`` and get the heading elsewhere (GNSS velocity).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..attitude import dcm_to_euler, dcm_to_quat
from ..data import ImuData
from ..errors import DataError
from ..geodesy import earth


@dataclass(frozen=True)
class CoarseAlignment:
    """Result of a static coarse alignment.

    Attributes
    ----------
    q_nb : ndarray (4,)
    rpy : ndarray (3,)
        Roll, pitch, yaw [rad] (yaw NED, clockwise from north).
    yaw_sigma_noise : float
        1-sigma heading error from the scatter of the gyro signal [rad]:
        ``sigma_east / (Omega cos lat)``, with ``sigma_east`` the standard
        error of the mean east rate estimated from the scatter of block means
        (blocks of ``block`` seconds, so quantisation, which does not
        accumulate, and slow base motion, which does, are both counted
        right). Gyro bias adds ``b_east / (Omega cos lat)`` on top, which a
        static alignment cannot separate.
    level_sigma_noise : float
        1-sigma roll/pitch error from the scatter of the specific force [rad],
        estimated the same way.
    mean_f_b, mean_w_b : ndarray (3,)
        Mean specific force [m/s^2] and angular rate [rad/s] in the body frame.
    duration : float
        Window length [s].
    """

    q_nb: np.ndarray
    rpy: np.ndarray
    yaw_sigma_noise: float
    level_sigma_noise: float
    mean_f_b: np.ndarray
    mean_w_b: np.ndarray
    duration: float


def _mean_sigma(x: np.ndarray, dt: np.ndarray, block: float, c_nb: np.ndarray) -> np.ndarray:
    """Standard error of the mean rate of ``x`` increments, per NED axis."""
    nb = max(int(round(block / np.median(dt))), 1)
    k = len(x) // nb
    if k < 3:
        return np.full(3, np.nan)
    means = x[:k * nb].reshape(k, nb, 3).sum(1) / dt[:k * nb].reshape(k, nb).sum(1)[:, None]
    return np.std(means @ c_nb.T, axis=0, ddof=1) / np.sqrt(k)


def coarse_align(imu: ImuData, lat: float, h: float = 0.0, use_gyro_heading: bool = True,
                 yaw: float = 0.0, block: float = 30.0) -> CoarseAlignment:
    """Align a static IMU.

    Parameters
    ----------
    imu : ImuData
        Increments recorded at rest (body frame).
    lat : float
        Latitude [rad]; ``h`` height [m].
    use_gyro_heading : bool
        Take the heading from the Earth rate (navigation/tactical gyros). If
        False, only level: the heading is set to ``yaw`` [rad].
    block : float
        Block length [s] for the uncertainty estimate.

    Raises
    ------
    DataError
        If the mean specific force is not within 5 % of gravity (the IMU was
        moving, or its units are wrong).
    """
    T = float(np.sum(imu.dt))
    f_b = imu.dvel.sum(0) / T
    w_b = imu.dtheta.sum(0) / T
    g = earth.normal_gravity(lat, h)
    if abs(np.linalg.norm(f_b) / g - 1.0) > 0.05:
        raise DataError(f"mean specific force {np.linalg.norm(f_b):.3f} m/s^2 is not gravity "
                        f"({g:.3f}): the IMU is not static or its accelerometer units are wrong",
                        file=imu.source)
    f_n = np.array([0.0, 0.0, -g])
    if use_gyro_heading:
        w_n = earth.earth_rate_ned(lat)
        rot, _ = Rotation.align_vectors([f_n, w_n], [f_b, w_b], weights=[np.inf, 1.0])
        c_nb = rot.as_matrix()
    else:
        # Level only: roll and pitch from gravity, heading given.
        roll = np.arctan2(-f_b[1], -f_b[2])
        pitch = np.arctan2(f_b[0], np.hypot(f_b[1], f_b[2]))
        c_nb = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    sw = _mean_sigma(imu.dtheta, imu.dt, block, c_nb)
    sf = _mean_sigma(imu.dvel, imu.dt, block, c_nb)
    return CoarseAlignment(
        q_nb=dcm_to_quat(c_nb), rpy=dcm_to_euler(c_nb),
        yaw_sigma_noise=float(sw[1] / (earth.OMEGA_EARTH * np.cos(lat))) if use_gyro_heading else np.nan,
        level_sigma_noise=float(np.hypot(sf[0], sf[1]) / np.sqrt(2) / g), mean_f_b=f_b, mean_w_b=w_b,
        duration=T)
