"""Which IMU samples were taken at rest: the epochs of ZUPT and ZARU.

A vehicle is taken as still over a window when, in that window,

* the specific-force magnitude barely varies: its standard deviation is below
  ``accel_std`` [m/s^2] (default 0.1; on drive-0708's roof-mounted MEMS unit,
  1 s windows read 0.02-0.08 parked with the engine running and 0.13-1.7 moving), and
* the body turns slowly: the mean angular-rate magnitude is below
  ``gyro_rate`` [rad/s] (default 0.03; it includes the gyro bias and the
  vibration, 0.005-0.025 parked on drive-0708, and a car pulling away or creeping
  round a corner reads 0.03-0.5), and
* the mean specific-force vector stays at the level the still stretch starts at
  (the median of the window means of its first second): it differs from it by
  less than ``accel_drift`` [m/s^2] (default 0.1). At rest the specific force is
  gravity in the body frame and does not change; a smooth pull-away changes its forward component by the
  acceleration (0.3-0.6 m/s^2) while neither test above sees it: the magnitude
  changes by only a^2 / 2g (< 0.02 m/s^2) and a steady acceleration has no spread
  within a window (drive-0708, the 198-207 s stop: the car moved at 0.2-0.6 m/s
  for 0.9 s before the magnitude test ended the stop, and ZUPT/ZARU there turned
  the acceleration into a 2-3 deg tilt error; 1 s window means at rest stay within
  0.015 m/s^2 of their stop's median at four stops, 0.064 m/s^2 at the last one).
  The level is the stretch's start, not its median: a stretch is found still from
  where a vehicle has come to rest, and without vibration (a simulated drive, a
  very smooth road) the steady acceleration after a stop passes the other tests
  and can be the longer part of a stretch (then its median). Windows back at the
  start level later in the stretch (a simulated constant-velocity drive) pass;
  the models' ``max_speed`` gate is what guards those. And
* when GNSS velocity is given, the nearest fix within ``gnss_gap`` says the
  speed is below ``gnss_speed`` [m/s] (a fix further away does not vote), and
  when odometer speeds are given, the nearest sample within ``gnss_gap`` says
  the wheels turn slower than ``gnss_speed`` too. An IMU alone cannot tell rest
  from a perfectly smooth drive (a simulated one): in GNSS outages without an
  odometer only the models' own speed gate (``max_speed``) guards against that.

A sample is still when every window containing it is still (an erosion, so the
first and last half-window of a stop are not used: the vehicle may still be
rolling there). Thresholds and the counts of what was detected are returned
for the report (:class:`Stillness`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data import GnssFixes, ImuData, OdometerData
from ..errors import ArgumentError


@dataclass(frozen=True)
class Stillness:
    """The result of :func:`detect_still`.

    Attributes
    ----------
    mask : ndarray of bool (N,)
        Per IMU sample: still.
    intervals : ndarray (K, 2)
        Start and end [s] of each still stretch.
    settings : dict
        The thresholds used (SI units), for the report.
    """

    mask: np.ndarray
    intervals: np.ndarray
    settings: dict

    @property
    def still_time_s(self) -> float:
        """Total time detected still [s]."""
        return float(np.sum(self.intervals[:, 1] - self.intervals[:, 0])) if len(self.intervals) else 0.0

    def epochs(self, rate: float, start: float | None = None, end: float | None = None) -> np.ndarray:
        """Regularly spaced epochs [s] at ``rate`` [Hz] inside the still stretches."""
        if not (np.isfinite(rate) and rate > 0):
            raise ArgumentError(f"must be a positive rate [Hz], got {rate!r}", argument="rate")
        out = []
        for a, b in self.intervals:
            a = a if start is None else max(a, start)
            b = b if end is None else min(b, end)
            if b > a:
                out.append(np.arange(np.ceil(a * rate) / rate, b + 1e-9, 1.0 / rate))
        return np.concatenate(out) if out else np.zeros(0)


def _moving(x: np.ndarray, w: int) -> np.ndarray:
    """Mean over the windows of ``w`` samples starting at each sample (N - w + 1,)."""
    c = np.concatenate([[0.0], np.cumsum(x)])
    return (c[w:] - c[:-w]) / w


def _eroded(ok: np.ndarray, n: int, w: int) -> np.ndarray:
    """Per sample (N,): every window of ``w`` samples holding it is ``ok`` (``ok[j]``: the
    window starting at sample j), so the first and last ``w - 1`` samples, which fewer
    windows cover, never are."""
    bad = np.concatenate([[0], np.cumsum(~ok)])
    i = np.arange(w - 1, n - w + 1)
    mask = np.zeros(n, dtype=bool)
    mask[i] = bad[i + 1] - bad[i - w + 1] == 0
    return mask


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """First and last index of each run of True."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1))


def _vetoed(t_ref: np.ndarray, speed: np.ndarray, t: np.ndarray, gap: float, threshold: float) -> np.ndarray:
    """Per time of ``t``: the nearest sample of ``t_ref`` (within ``gap`` [s]) moves faster
    than ``threshold`` [m/s] (``speed`` per sample of ``t_ref``)."""
    k = np.clip(np.searchsorted(t_ref, t), 0, len(t_ref) - 1)
    before = np.maximum(k - 1, 0)
    near = np.where(np.abs(t_ref[before] - t) < np.abs(t_ref[k] - t), before, k)
    return (np.abs(t_ref[near] - t) <= gap) & (speed[near] > threshold)


def detect_still(imu: ImuData, window: float = 1.0, accel_std: float = 0.1, gyro_rate: float = 0.03,
                 fixes: GnssFixes | None = None, gnss_speed: float = 0.1, gnss_gap: float = 1.0,
                 min_duration: float = 1.0, odometer: OdometerData | None = None,
                 accel_drift: float = 0.1) -> Stillness:
    """Detect the still stretches of an IMU record (see the module docstring).

    Parameters
    ----------
    imu : ImuData
    window : float
        Window length [s].
    accel_std : float
        Largest standard deviation of the specific-force magnitude at rest [m/s^2].
    gyro_rate : float
        Largest mean angular-rate magnitude at rest [rad/s].
    fixes : GnssFixes, optional
        With velocities, a fix moving faster than ``gnss_speed`` [m/s] vetoes its time
        (within ``gnss_gap`` [s]).
    min_duration : float
        Shorter still stretches are dropped [s].
    odometer : OdometerData, optional
        A wheel speed above ``gnss_speed`` within ``gnss_gap`` vetoes its time.
    accel_drift : float
        Largest distance of a window's mean specific-force vector from its still
        stretch's level (the median of the window means of its first second) [m/s^2].
    """
    for name, v in (("window", window), ("accel_std", accel_std), ("gyro_rate", gyro_rate),
                    ("gnss_speed", gnss_speed), ("gnss_gap", gnss_gap), ("accel_drift", accel_drift)):
        if not (np.isfinite(v) and v > 0):
            raise ArgumentError(f"must be positive, got {v!r}", argument=name)
    if not (np.isfinite(min_duration) and min_duration >= 0):
        raise ArgumentError(f"must be >= 0 s, got {min_duration!r}", argument="min_duration")
    n = len(imu)
    dt = float(np.median(imu.dt))
    w = max(int(round(window / dt)), 2)
    settings = dict(window_s=float(window), accel_std_mps2=float(accel_std), gyro_rate_radps=float(gyro_rate),
                    gnss_speed_mps=float(gnss_speed) if fixes is not None or odometer is not None else None,
                    min_duration_s=float(min_duration), accel_drift_mps2=float(accel_drift))
    if n < w:
        return Stillness(np.zeros(n, dtype=bool), np.zeros((0, 2)), settings)
    f_b = imu.dvel / imu.dt[:, None]
    f = np.linalg.norm(f_b, axis=1)
    rate = np.linalg.norm(imu.dtheta, axis=1) / imu.dt
    mean_f = _moving(f, w)
    var_f = np.maximum(_moving(f * f, w) - mean_f ** 2, 0.0)
    ok = (var_f < accel_std ** 2) & (_moving(rate, w) < gyro_rate)   # window starting at sample j
    vetoes = np.ones(n, dtype=bool)
    if fixes is not None and fixes.vel_n is not None and len(fixes):
        vetoes &= ~_vetoed(fixes.time, np.linalg.norm(fixes.vel_n, axis=1), imu.time, gnss_gap, gnss_speed)
    if odometer is not None and len(odometer):
        vetoes &= ~_vetoed(odometer.time, np.abs(odometer.speed), imu.time, gnss_gap, gnss_speed)
    mask = _eroded(ok, n, w) & vetoes
    # the level test: per still stretch, the windows whose mean specific-force vector left
    # the level the stretch starts at (a pull-away or a creep) are not still either
    mean_fb = np.column_stack([_moving(f_b[:, k], w) for k in range(3)])
    drifted = np.zeros(len(ok), dtype=bool)
    for a, b in _runs(mask):
        first = np.arange(a, max(min(a + w, b - w + 2), a + 1))   # windows in its first second
        level = np.median(mean_fb[first], axis=0)
        j = np.arange(max(a - w + 1, 0), min(b + 1, len(ok)))   # windows holding a sample of it
        drifted[j] = np.linalg.norm(mean_fb[j] - level, axis=1) >= accel_drift
    if drifted.any():
        mask = _eroded(ok & ~drifted, n, w) & vetoes
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    iv = np.column_stack([imu.time[starts], imu.time[ends]]) if len(starts) else np.zeros((0, 2))
    keep = (iv[:, 1] - iv[:, 0]) >= min_duration if len(iv) else np.zeros(0, dtype=bool)
    for a, b in zip(starts[~keep], ends[~keep]):
        mask[a:b + 1] = False
    return Stillness(mask, iv[keep], settings)
