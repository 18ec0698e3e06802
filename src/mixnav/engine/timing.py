"""IMU/measurement time alignment.

GNSS epochs rarely fall on IMU sample times. Rather than interpolating the
state, the IMU increment that straddles a measurement time is split in two at
that time (each part scaled by its share of the interval, i.e. constant rate
and specific force within the interval), so the INS is mechanized exactly to
the measurement time (as KF-GINS does). Splitting is done once, up front, for
all event times, so the filter loop only ever walks contiguous slices.
"""

from __future__ import annotations

import numpy as np

from ..data import ImuData

#: Event times closer than this to an IMU sample time are taken as on it [s].
TIME_TOLERANCE = 1e-6


def split_at_times(imu: ImuData, times: np.ndarray) -> tuple[ImuData, np.ndarray]:
    """Insert the given times into the IMU stream by splitting increments.

    Parameters
    ----------
    imu : ImuData
    times : ndarray (E,)
        Increasing event times [s] inside ``(imu.start_time, imu.time[-1]]``.

    Returns
    -------
    imu_split : ImuData
        Increments whose end times include every event time; the sums of
        ``dtheta``, ``dvel`` and ``dt`` are unchanged.
    end_index : ndarray of int (E,)
        ``imu_split.time[end_index[e]]`` is event ``e``'s time: mechanizing
        increments ``[end_index[e-1] + 1, end_index[e]]`` reaches it.
    """
    times = np.asarray(times, dtype=float)
    t_end = imu.time
    t_start = t_end - imu.dt
    k = np.searchsorted(t_end, times - TIME_TOLERANCE)  # first increment ending at/after t
    k = np.minimum(k, len(t_end) - 1)
    on_sample = np.abs(t_end[k] - times) <= TIME_TOLERANCE
    split = ~on_sample & (times > t_start[k])
    if not split.any():
        return imu, k.astype(np.int64)
    # Several events may fall in one increment: it is cut into several parts. Every part is
    # named by its increment and the fraction of it where the part ends (1 for the last part);
    # sorted, each part starts where the one before it in the same increment ended. Vectorised:
    # a Python loop over the cuts was most of a 10 Hz constraint run's set-up.
    ks = k[split]
    cut = (times[split] - t_start[ks]) / imu.dt[ks]
    inc = np.concatenate([ks, np.arange(len(imu))])
    hi = np.concatenate([cut, np.ones(len(imu))])
    order = np.lexsort((hi, inc))
    inc, hi = inc[order], hi[order]
    lo = np.zeros_like(hi)
    same = inc[1:] == inc[:-1]
    lo[1:][same] = hi[:-1][same]
    share = hi - lo
    time = np.where(hi < 1.0, t_start[inc] + hi * imu.dt[inc], t_end[inc])
    dt = share * imu.dt[inc]
    dth = share[:, None] * imu.dtheta[inc]
    dv = share[:, None] * imu.dvel[inc]
    out = ImuData(time=time, dt=dt, dtheta=dth, dvel=dv, source=imu.source)
    end_index = np.searchsorted(time, times - TIME_TOLERANCE)
    return out, end_index.astype(np.int64)
