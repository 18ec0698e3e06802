"""Shared IMU conversions and plausibility checks for the readers."""

from __future__ import annotations

import numpy as np

from ..data import ImuData
from ..errors import DataError

G0 = 9.80665
#: Largest plausible 99th-percentile angular rate of a vehicle [rad/s]: 290 deg/s.
#: Cars stay below 1 rad/s and aircraft below 3; deg/s data declared as rad/s
#: (a 10 deg/s turn read as 10 rad/s) lands above it.
MAX_RATE = 5.0


def rates_to_increments(t, w, f, source=None, lines=None) -> ImuData:
    """Angular rate [rad/s] and specific force [m/s^2] samples to increments.

    The increment over ``(t[k-1], t[k]]`` is the trapezoid of the two samples,
    so N samples give N - 1 increments (the first sample only opens the first
    interval).
    """
    if len(t) < 2:
        raise DataError("need at least two IMU samples", file=source)
    dt = np.diff(t)
    dth = 0.5 * (w[1:] + w[:-1]) * dt[:, None]
    dv = 0.5 * (f[1:] + f[:-1]) * dt[:, None]
    return ImuData(time=np.asarray(t[1:], float), dt=dt, dtheta=dth, dvel=dv, source=source)


def check_plausible(imu: ImuData, gyro_unit: str, accel_unit: str) -> None:
    """Refuse data whose size does not fit the declared units.

    The median specific force over a record must be near gravity (a vehicle
    spends most of its time near 1 g), and the 99th percentile of the rate
    below 5 rad/s (deg/s data declared as rad/s gives tens of "rad/s").
    """
    f = np.linalg.norm(imu.dvel / imu.dt[:, None], axis=1)
    w = np.linalg.norm(imu.dtheta / imu.dt[:, None], axis=1)
    fm = float(np.median(f))
    if not 0.5 * G0 < fm < 1.5 * G0:
        raise DataError(f"median specific force is {fm:.4g} m/s^2 with the accelerometer declared in "
                        f"'{accel_unit}'; gravity is 9.8 m/s^2: the unit is probably wrong", file=imu.source)
    wp = float(np.percentile(w, 99))
    if wp > MAX_RATE:
        raise DataError(f"99 % of angular rates are below {wp:.4g} rad/s with the gyro declared in "
                        f"'{gyro_unit}': implausible for a vehicle (> {MAX_RATE:g} rad/s); "
                        "the unit is probably wrong (deg/s declared as rad/s?)", file=imu.source)
