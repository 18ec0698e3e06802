"""What the data says before any filter runs: the still segments' IMU noise (Allan deviation),
the ZUPT/ZARU thresholds from the stillness statistics and the IMU's latency against the fixes
(the turn-rate lag), all inside the tuning span; and, from one run, the bias walks and the
NHC's suspension pitch."""

from __future__ import annotations

import numpy as np

from .allan import still_noise
from .criterion import nearest

#: a 1 s window counts as still (moving) for the threshold statistics when the nearest GNSS
#: velocity within 0.5 s says below (above) this speed [m/s]
STILL_BELOW_MPS, MOVING_ABOVE_MPS = 0.05, 1.0


def _window_stats(imu, window: float = 1.0):
    """Per window of ``window`` s: centre time, std of the specific-force magnitude [m/s^2],
    mean angular-rate magnitude [rad/s] (the statistics the stillness detector tests)."""
    dt = float(np.median(imu.dt))
    n = max(int(round(window / dt)), 2)
    k = len(imu.time) // n
    f = np.linalg.norm(imu.dvel[:k * n] / imu.dt[:k * n, None], axis=1).reshape(k, n)
    w = np.linalg.norm(imu.dtheta[:k * n] / imu.dt[:k * n, None], axis=1).reshape(k, n)
    return imu.time[:k * n].reshape(k, n).mean(axis=1), f.std(axis=1), w.mean(axis=1)


def _speed_at(fixes, t, gap: float = 0.5):
    """GNSS horizontal speed nearest each time (NaN without a fix within ``gap`` s or without velocities)."""
    if fixes.vel_n is None or len(fixes.time) == 0:
        return np.full(len(t), np.nan)
    j = nearest(fixes.time, t)
    s = np.hypot(fixes.vel_n[j, 0], fixes.vel_n[j, 1])
    return np.where(np.abs(fixes.time[j] - t) <= gap, s, np.nan)


def stillness_thresholds(imu, fixes, span) -> dict:
    """ZUPT/ZARU thresholds from the recording's own stillness statistics.

    1 s windows are labelled still or moving by the GNSS speed (below 0.05 m/s, above 1 m/s);
    each threshold is the geometric mean of the still windows' 90th percentile and the moving
    windows' 5th percentile when those are apart (a margin on both sides), else it is not
    set (``None``, with the reason). Returns ``{"accel_std": (value or None, note),
    "gyro_rate": (...)}`` [m/s^2], [rad/s]."""
    t, fstd, wmean = _window_stats(imu)
    sel = (t >= span[0]) & (t <= span[1])
    v = _speed_at(fixes, t)
    still, moving = sel & (v < STILL_BELOW_MPS), sel & (v > MOVING_ABOVE_MPS)
    out = {}
    for key, x in (("accel_std", fstd), ("gyro_rate", wmean)):
        if still.sum() < 10 or moving.sum() < 10:
            out[key] = (None, f"{int(still.sum())} still and {int(moving.sum())} moving 1 s windows: "
                              "too few to set a threshold (at least 10 of each)")
            continue
        hi_still, lo_moving = np.percentile(x[still], 90), np.percentile(x[moving], 5)
        if hi_still >= lo_moving:
            out[key] = (None, f"still windows' p90 {hi_still:.4g} not below the moving windows' p5 "
                              f"{lo_moving:.4g}: no threshold separates them")
            continue
        out[key] = (float(np.sqrt(hi_still * lo_moving)),
                    f"geometric mean of the still 1 s windows' p90 ({hi_still:.4g}, {int(still.sum())} windows) "
                    f"and the moving ones' p5 ({lo_moving:.4g}, {int(moving.sum())} windows)")
    return out


def imu_noise(imu, fixes, span, min_segment: float = 3.0):
    """The Allan-deviation noise of the still segments inside ``span`` (IMU stillness with the
    GNSS speed's veto at the detector's defaults), or None with none long enough."""
    from ...measurements.stillness import detect_still
    st = detect_still(imu, fixes=fixes)
    iv = np.asarray(st.intervals, float).reshape(-1, 2)
    iv = np.column_stack([np.maximum(iv[:, 0], span[0]), np.minimum(iv[:, 1], span[1])])
    iv = iv[iv[:, 1] > iv[:, 0]]
    return still_noise(imu, iv, min_segment=min_segment)


#: the interval over which the smoothed bias increments are taken [s]: long against the
#: smoother's 0.25 s records and the GNSS noise, short against the drive
BIAS_INCREMENT_S = 10.0
#: the walks are loosened by this factor for the smoothed run that reads them, so that the
#: smoother follows what the data say rather than the file's (possibly far too tight) prior
LOOSEN = 10.0


def bias_walks(evaluator, doc_text: str, span) -> dict | None:
    """Per-axis gyro and accelerometer bias random walks from the smoothed bias estimates.

    The tuned method is run once with the RTS smoother on the whole span (every fix used,
    the walks in the file loosened tenfold), and the smoothed biases' increments over
    :data:`BIAS_INCREMENT_S` give each axis' walk density ``sqrt(mean(db^2) / dT)``. Only the
    recording's own GNSS enters. Returns ``{"gyro_bias_walk": (3,) rad/s^1.5,
    "accel_bias_walk": (3,) m/s^2.5, "increments": n}`` or None when the span holds fewer than
    three increments or the method cannot be smoothed."""
    import tomlkit
    from .parameters import ins_parameters, get_value, set_value
    doc = tomlkit.parse(doc_text)
    for p in ins_parameters():
        if p.name in ("imu.errors.gyro_bias_walk", "imu.errors.accel_bias_walk"):
            v = get_value(doc, p)
            if v is None:
                return None
            set_value(doc, p, v * LOOSEN)
    ds = evaluator.dataset(tomlkit.dumps(doc), smooth=True)
    if not ds.methods or not getattr(ds.methods[0], "smooth", False):
        return None
    po = evaluator.run(ds, [])
    res = po.results.get(f"{evaluator.method}-smoothed")
    if res is None or "gyro_bias" not in res.estimates:
        return None
    grid = np.arange(span[0], span[1] + 1e-9, BIAS_INCREMENT_S)
    if len(grid) < 4:
        return None
    out = {"increments": len(grid) - 1}
    for key, est in (("gyro_bias_walk", "gyro_bias"), ("accel_bias_walk", "accel_bias")):
        b = np.column_stack([np.interp(grid, res.time, res.estimates[est][:, i]) for i in range(3)])
        d = np.diff(b, axis=0)
        out[key] = np.sqrt(np.mean(d * d, axis=0) / BIAS_INCREMENT_S)
    return out


#: the suspension-pitch fit uses the records moving faster than this [m/s] (below it the
#: vertical velocity a pitch makes is lost in the fixes' noise) and forward accelerations
#: below :data:`SQUAT_MAX_ACCEL` [m/s^2] (a GNSS velocity jump is not an acceleration)
SQUAT_MIN_SPEED, SQUAT_MAX_ACCEL = 3.0, 5.0
#: at least this many records, and the slope at least this many standard errors from zero
SQUAT_MIN_RECORDS, SQUAT_MIN_T = 200, 3.0


def suspension_pitch(res, fixes, span, mounting=(0.0, 0.0, 0.0)):
    """``[aiding.nhc] pitch_per_accel`` [rad per m/s^2] from the recording's own GNSS velocity.

    The fixes' velocity is turned into the vehicle frame by the attitude of ``res`` (a run of
    the tuned method without the NHC, which would otherwise pull the attitude towards the
    constraint it is to measure) and ``mounting``; over the records inside ``span`` moving
    faster than :data:`SQUAT_MIN_SPEED`, the vertical velocity is regressed on speed times
    forward acceleration (the acceleration from the velocity's gradient): the body's pitch on
    its suspension per m/s^2 is the slope (drive-0708: 0.30-0.36 deg per m/s^2 on either
    half, benchmarks/results/drive0708_drift.md). Returns ``(k, note)``, or ``(None, why)``
    with too few records or a slope within :data:`SQUAT_MIN_T` standard errors of zero."""
    from ...attitude import euler_to_dcm, quat_to_dcm
    t = np.asarray(res.time, float)
    if fixes.vel_n is None or len(fixes.time) < 2:
        return None, "the fixes carry no velocity"
    j = nearest(fixes.time, t)
    near = np.abs(fixes.time[j] - t) <= 0.3
    v_n = np.column_stack([np.interp(t, fixes.time, fixes.vel_n[:, k]) for k in range(3)])
    c_vn = euler_to_dcm(np.asarray(mounting, float)) @ np.swapaxes(quat_to_dcm(res.nav[:, 0:4]), -1, -2)
    v_v = np.einsum("kij,kj->ki", c_vn, v_n)
    a_x = np.gradient(v_v[:, 0], t)
    sel = (near & (t >= span[0]) & (t <= span[1]) & (v_v[:, 0] > SQUAT_MIN_SPEED)
           & (np.abs(a_x) < SQUAT_MAX_ACCEL) & np.isfinite(v_v).all(axis=1))
    n = int(sel.sum())
    if n < SQUAT_MIN_RECORDS:
        return None, (f"{n} records moving faster than {SQUAT_MIN_SPEED:g} m/s with a fix: too few to fit "
                      f"the suspension pitch (at least {SQUAT_MIN_RECORDS})")
    X = np.column_stack([np.ones(n), v_v[sel, 0] * a_x[sel]])
    y = v_v[sel, 2]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - X @ coef
    # the records (0.25 s apart) are correlated (the fixes' errors, the attitude's): the standard
    # error counts one independent sample a second
    per_second = max(1.0, 1.0 / float(np.median(np.diff(t))))
    cov = np.linalg.inv(X.T @ X) * (e @ e) / (n - 2) * per_second
    k, se = float(coef[1]), float(np.sqrt(cov[1, 1]))
    if abs(k) < SQUAT_MIN_T * se:
        return None, (f"the suspension pitch fit {np.degrees(k):.3f} +- {np.degrees(se):.3f} deg/(m/s^2) over "
                      f"{n} records is not {SQUAT_MIN_T:g} standard errors from zero")
    return k, (f"the fixes' vertical velocity in the vehicle frame (attitude of a run without the NHC) "
               f"regressed on speed x forward acceleration over {n} records above {SQUAT_MIN_SPEED:g} m/s: "
               f"+-{np.degrees(se):.3f} deg/(m/s^2) (1 sigma, one sample a second)")


#: the turn-rate cross-correlation (:func:`turn_rate_lag`): lags searched [s], their step [s], the
#: slowest chord counted [m/s] (below it the fixes' noise swamps the course), and what a peak
#: must reach to be used: its correlation and the number of chord pairs behind it
LAG_RANGE_S, LAG_STEP_S, LAG_MIN_SPEED, LAG_MIN_CORR, LAG_MIN_PAIRS = 1.0, 0.01, 3.0, 0.5, 30


def turn_rate_lag(imu, fixes, span):
    """How much later the IMU's rotation shows than the fixes' turns, from the data alone:
    ``(lag [s], peak correlation, chord pairs)``, or ``(None, why)``.

    The fixes' course between consecutive positions (chords, not the receiver's velocity,
    which may be a filtered, delayed one) changes from one chord to the next by the turn in
    between; the IMU's angular-rate magnitude averaged over the same interval, shifted by a
    lag, is compared with it (Pearson correlation, lags within +-:data:`LAG_RANGE_S` in
    :data:`LAG_STEP_S` steps, the peak refined by a parabola). The magnitude needs no
    mounting: in a car the body turns about its vertical far more than about the others.
    The lag is on the run's time axis, so ``-lag`` is the correction of the configured
    ``imu_time_offset`` at the span's middle (drive-0708: an offset of -0.07 s on the first
    half and -0.19 s on the second, where the innovation likelihood's
    quarters prefer -0.125 to -0.175 and -0.2 to -0.225 s; the same offset within 3 ms whether
    the file had configured -0.125 s or +0.4 s). A coarse start, which the search refines."""
    from ...geodesy.frames import ned_displacement
    t = np.asarray(fixes.time, float)
    if len(t) < 3 or len(imu.time) < 3:
        return None, "too few fixes or IMU samples"
    p = ned_displacement(fixes.lla, fixes.lla[0])
    dt = np.diff(t)
    gap = 1.5 * float(np.median(dt))
    v = np.diff(p[:, :2], axis=0) / dt[:, None]
    course = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
    mid = 0.5 * (t[1:] + t[:-1])
    ok = ((dt[1:] < gap) & (dt[:-1] < gap) & (np.hypot(*v[1:].T) > LAG_MIN_SPEED)
          & (np.hypot(*v[:-1].T) > LAG_MIN_SPEED))
    a, b = mid[:-1][ok], mid[1:][ok]
    turn = np.abs(np.diff(course)[ok] / (b - a))
    # the IMU's rotation angle accumulated, to average |omega| over any interval
    tc = np.r_[imu.time[0] - imu.dt[0], imu.time]
    angle = np.r_[0.0, np.cumsum(np.linalg.norm(imu.dtheta, axis=1))]
    L = LAG_RANGE_S
    sel = (a >= max(span[0], tc[0]) + L) & (b <= min(span[1], tc[-1]) - L)
    a, b, turn = a[sel], b[sel], turn[sel]
    if len(turn) < LAG_MIN_PAIRS or np.std(turn) == 0:
        return None, f"{len(turn)} chord pairs above {LAG_MIN_SPEED:g} m/s in the span (at least {LAG_MIN_PAIRS})"
    lags = np.arange(-L, L + LAG_STEP_S / 2, LAG_STEP_S)
    corr = np.array([np.corrcoef((np.interp(b + x, tc, angle) - np.interp(a + x, tc, angle)) / (b - a), turn)[0, 1]
                     for x in lags])
    corr = np.where(np.isfinite(corr), corr, -1.0)
    k = int(np.argmax(corr))
    if k in (0, len(lags) - 1):
        return None, (f"the correlation peaks at the edge of +-{L:g} s: no lag found inside it (too few turns, "
                      "or the IMU and the fixes misregistered by more than that: GPS and UTC time differ "
                      "by 18 s)")
    if corr[k] < LAG_MIN_CORR:
        return None, f"peak correlation {corr[k]:.2f} below {LAG_MIN_CORR:g} (too few turns, or noisy fixes)"
    c0, c1, c2 = corr[k - 1:k + 2]
    den = c0 - 2 * c1 + c2
    frac = 0.5 * (c0 - c2) / den if den < 0 else 0.0
    return float(lags[k] + frac * LAG_STEP_S), float(c1), int(len(turn))
