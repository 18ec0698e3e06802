"""IMU noise from the recording's own still segments: overlapping Allan deviation.

A land vehicle stops at junctions; while it stands still (engine running) the gyros read
the Earth rate plus bias plus noise and the accelerometers gravity plus bias plus noise.
The overlapping Allan deviation of each channel over the still segments gives the white
noise densities the filter's process noise needs (IEEE Std 952-1997, annex C):

* angle / velocity random walk N: the Allan deviation of the rate at tau = 1 s (the -1/2
  slope read at 1 s: ``sigma(tau) = N / sqrt(tau)``), in rad/s/sqrt(Hz) (m/s^2/sqrt(Hz));
* bias instability B: the minimum of the Allan deviation divided by
  ``sqrt(2 ln 2 / pi) = 0.664``, only a bound when the longest segment is too short to reach
  the flat part (the usual case for a car: stops of 10-60 s; said in ``bias_instability_bound``).

Segments are pooled: each still segment contributes its own overlapping differences (no
difference spans two segments), summed over segments at each tau. The overlapping Allan
variance at ``tau = m dt`` from the integrated rate ``theta``:
``sum_k (theta[k+2m] - 2 theta[k+m] + theta[k])^2 / (2 tau^2 (n - 2m))``. Checked against
``allantools.oadev`` and the white-noise closed form in tests/test_tuning.py.

With the engine running on a roof mount the short-tau deviation is vibration rather than
sensor noise; it is still what the filter sees between GNSS fixes, so it is what the
noise model needs (the criterion of :mod:`.criterion` then scales it: a moving car vibrates
more than a parked one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: B = min ADEV / this (IEEE Std 952: sqrt(2 ln 2 / pi))
BIAS_INSTABILITY_FACTOR = float(np.sqrt(2.0 * np.log(2.0) / np.pi))


def overlapping_adev(segments, dt: float, taus) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of rate samples pooled over segments.

    Parameters
    ----------
    segments : list of ndarray (n_i,) or (n_i, k)
        Rate samples of each segment (k channels), sampled every ``dt`` [s].
    dt : float
        Sample interval [s].
    taus : array (T,)
        Averaging times [s]; each is rounded to a whole number of samples.

    Returns
    -------
    adev : ndarray (T,) or (T, k)
        NaN where no segment is at least ``2 tau`` long.
    count : ndarray of int (T,)
        Number of overlapping differences summed at each tau.
    """
    taus = np.asarray(taus, float)
    segs = [np.asarray(s, float) for s in segments]
    k_shape = segs[0].shape[1:] if segs else ()
    num = np.zeros((len(taus),) + k_shape)
    cnt = np.zeros(len(taus), int)
    for s in segs:
        theta = np.concatenate([np.zeros((1,) + k_shape), np.cumsum(s, axis=0) * dt])
        n = len(theta) - 1
        for i, tau in enumerate(taus):
            m = max(int(round(tau / dt)), 1)
            if 2 * m > n:
                continue
            d = theta[2 * m:] - 2.0 * theta[m:-m] + theta[:-2 * m]
            num[i] += np.sum(d * d, axis=0) / (2.0 * (m * dt) ** 2)
            cnt[i] += len(d)
    with np.errstate(invalid="ignore", divide="ignore"):
        avar = num / np.where(cnt > 0, cnt, np.nan).reshape((-1,) + (1,) * len(k_shape))
    return np.sqrt(avar), cnt


@dataclass(frozen=True)
class StillNoise:
    """IMU noise read from still segments (per installed axis x, y, z).

    Attributes
    ----------
    arw : ndarray (3,)
        Angle random walk [rad/s/sqrt(Hz)] (Allan deviation of the gyro rate at 1 s).
    vrw : ndarray (3,)
        Velocity random walk [m/s^2/sqrt(Hz)].
    arw_rel_sigma, vrw_rel_sigma : float
        Relative 1-sigma of those estimates: ``1 / sqrt(2 (K - 1))`` for K independent
        1 s differences (the chi-square spread of an Allan variance).
    gyro_bias_instability, accel_bias_instability : ndarray (3,)
        [rad/s], [m/s^2]: the minimum Allan deviation / 0.664.
    bias_instability_bound : bool
        True when the deviation still falls at the longest tau the segments allow: then the
        two values above are upper bounds, not estimates.
    still_s : float
        Total still time used [s]; ``segments`` how many segments.
    taus, gyro_adev, accel_adev : ndarray
        The curves (T,), (T, 3), (T, 3), for the report.
    """

    arw: np.ndarray
    vrw: np.ndarray
    arw_rel_sigma: float
    vrw_rel_sigma: float
    gyro_bias_instability: np.ndarray
    accel_bias_instability: np.ndarray
    bias_instability_bound: bool
    still_s: float
    segments: int
    taus: np.ndarray
    gyro_adev: np.ndarray
    accel_adev: np.ndarray


def still_noise(imu, intervals, min_segment: float = 3.0) -> StillNoise | None:
    """Allan-deviation noise of the IMU over its still ``intervals`` ((K, 2) [s]); None when
    no segment is at least ``min_segment`` [s] long (2 s are needed for tau = 1 s and a
    few differences more for any confidence)."""
    dt = float(np.median(imu.dt))
    segs_g, segs_a = [], []
    for a, b in np.asarray(intervals, float).reshape(-1, 2):
        if b - a < min_segment:
            continue
        sel = (imu.time > a) & (imu.time <= b)
        if sel.sum() < 3:
            continue
        segs_g.append(imu.dtheta[sel] / imu.dt[sel, None])
        segs_a.append(imu.dvel[sel] / imu.dt[sel, None])
    if not segs_g:
        return None
    longest = max(len(s) for s in segs_g) * dt
    taus = np.unique(np.round(np.geomspace(dt, max(longest / 2.0, dt), 40) / dt)) * dt
    g, cnt = overlapping_adev(segs_g, dt, taus)
    acc, _ = overlapping_adev(segs_a, dt, taus)
    ok = cnt > 0
    taus, g, acc, cnt = taus[ok], g[ok], acc[ok], cnt[ok]
    i1 = int(np.argmin(np.abs(np.log(taus))))   # tau nearest 1 s
    still = float(sum(len(s) for s in segs_g) * dt)
    k_indep = max(still / max(taus[i1], dt) - len(segs_g), 2.0)
    rel = float(1.0 / np.sqrt(2.0 * (k_indep - 1.0)))
    imin_g, imin_a = np.argmin(g, axis=0), np.argmin(acc, axis=0)
    bound = bool(np.any(imin_g == len(taus) - 1) or np.any(imin_a == len(taus) - 1))
    # N = sigma(tau) sqrt(tau): exact at tau = 1 s, the nearest tau otherwise
    return StillNoise(arw=g[i1] * np.sqrt(taus[i1]), vrw=acc[i1] * np.sqrt(taus[i1]), arw_rel_sigma=rel,
                      vrw_rel_sigma=rel, gyro_bias_instability=g.min(axis=0) / BIAS_INSTABILITY_FACTOR,
                      accel_bias_instability=acc.min(axis=0) / BIAS_INSTABILITY_FACTOR,
                      bias_instability_bound=bound, still_s=still, segments=len(segs_g), taus=taus,
                      gyro_adev=g, accel_adev=acc)
