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
    ks = k[split]
    # Several events may fall in one increment: split it into several parts.
    frac_lo = {}
    for kk, t in zip(ks, times[split]):
        frac_lo.setdefault(int(kk), []).append((t - t_start[kk]) / imu.dt[kk])
    if not frac_lo:
        return imu, k.astype(np.int64)
    n_extra = sum(len(v) for v in frac_lo.values())
    n = len(imu) + n_extra
    time = np.empty(n)
    dt = np.empty(n)
    dth = np.empty((n, 3))
    dv = np.empty((n, 3))
    src = 0
    dst = 0
    for kk in sorted(frac_lo):
        m = kk - src
        time[dst:dst + m] = t_end[src:kk]
        dt[dst:dst + m] = imu.dt[src:kk]
        dth[dst:dst + m] = imu.dtheta[src:kk]
        dv[dst:dst + m] = imu.dvel[src:kk]
        dst += m
        edges = np.concatenate([[0.0], np.sort(frac_lo[kk]), [1.0]])
        for a, b in zip(edges[:-1], edges[1:]):
            time[dst] = t_start[kk] + b * imu.dt[kk] if b < 1.0 else t_end[kk]
            dt[dst] = (b - a) * imu.dt[kk]
            dth[dst] = (b - a) * imu.dtheta[kk]
            dv[dst] = (b - a) * imu.dvel[kk]
            dst += 1
        src = kk + 1
    m = len(imu) - src
    time[dst:] = t_end[src:]
    dt[dst:] = imu.dt[src:]
    dth[dst:] = imu.dtheta[src:]
    dv[dst:] = imu.dvel[src:]
    out = ImuData(time=time, dt=dt, dtheta=dth, dvel=dv, source=imu.source)
    end_index = np.searchsorted(time, times - TIME_TOLERANCE)
    return out, end_index.astype(np.int64)
