"""Accuracy metrics of a solution table (column names in docs/outputs.md), and the
per-method metrics every pipeline reports (:func:`method_metrics`: accuracy, timing,
recoveries, NIS; :func:`nees`; :func:`nis_warnings`).

Errors in the table are estimate minus truth. Every metric is a plain Python
number so the result can go straight into ``metrics.json``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from ..filters.ekf import FilterResult

#: Every key :func:`compute_metrics` returns, with its meaning and unit, plus the
#: timing and consistency keys :func:`method_metrics` adds per method.
#: docs/outputs.md lists the same keys (checked by tests/test_cli.py).
METRIC_KEYS_DOC: dict[str, str] = {
    "roll_rmse_deg": "RMS of the roll error [deg]",
    "roll_max_deg": "largest absolute roll error [deg]",
    "pitch_rmse_deg": "RMS of the pitch error [deg]",
    "pitch_max_deg": "largest absolute pitch error [deg]",
    "yaw_rmse_deg": "RMS of the yaw error, wrapped to [-180, 180) [deg]",
    "yaw_max_deg": "largest absolute yaw error [deg]",
    "roll_p95_deg": "95th percentile of the absolute roll error [deg]",
    "pitch_p95_deg": "95th percentile of the absolute pitch error [deg]",
    "yaw_p95_deg": "95th percentile of the absolute yaw error [deg]",
    "horizontal_rmse_m": "RMS of the horizontal position error hypot(north, east) [m]",
    "horizontal_max_m": "largest horizontal position error [m]",
    "horizontal_p95_m": "95th percentile of the horizontal position error [m]",
    "vertical_rmse_m": "RMS of the vertical position error [m]",
    "vertical_max_m": "largest absolute vertical position error [m]",
    "vertical_p95_m": "95th percentile of the absolute vertical error [m]",
    "velocity_rmse_mps": "RMS of the 3-D velocity error norm [m/s]",
    "velocity_max_mps": "largest 3-D velocity error norm [m/s]",
    "velocity_p95_mps": "95th percentile of the 3-D velocity error norm [m/s]",
    "n_epochs": "number of epochs scored",
    "outages": "per GNSS outage window: start_s, end_s, unaided_end_s (the first epoch after end_s with a "
               "GNSS update: the unaided stretch ends there, it is scored up to just before it), "
               "horizontal_max_m, vertical_max_m, horizontal_rmse_m, vertical_rmse_m (over the window and "
               "the unaided stretch after it), horizontal_final_m (at the last epoch scored), nees_pos_mean and "
               "nees_vel_mean (the mean NEES over the same epochs, when the filter gives covariances)",
    "segments": "per scored segment of a scenario's [scoring] (docs/scenarios.md), {name: metrics}: "
                "start_s, end_s and every whole-run accuracy key above (RMSE, max, p95 of horizontal, "
                "vertical, velocity and attitude errors, n_epochs, NEES means) over the epochs with "
                "start_s <= time_s < end_s; only when the scenario declares segments",
    "horizontal_rmse_outside_outages_m": "RMS of the horizontal error over the epochs outside every "
                                         "outage window [m] (only when there are outages)",
    "vertical_rmse_outside_outages_m": "RMS of the vertical error outside every outage window [m]",
    "nees_pos_mean": "mean NEES of the 3-D position error (3 for a consistent filter)",
    "nees_vel_mean": "mean NEES of the 3-D velocity error (3 for a consistent filter)",
    "nees_singular_epochs": "epochs whose position or velocity covariance was singular or nearly so "
                            "(:func:`nees`; their NEES "
                            "is NaN in the solution table and left out of the means; e.g. a collapsed particle cloud)",
    "epoch_time_mean_us": "filter wall time per GNSS epoch, mechanization included [us]",
    "update_time_mean_us": "measurement model + correction + feedback per GNSS epoch [us]",
    "wall_time_s": "wall time of the filter run [s]",
    "learning_time_s": "Gaussian-mixture methods: time spent learning the noise mixtures offline [s]",
    "bank_components_max": "Gaussian-mixture methods: largest bank before a reduction (kept x process "
                           "components)",
    "online_refits": "M4 online re-learning: number of VB refits of a window (one per observable kind each time)",
    "online_refit_time_s": "M4 online re-learning: time spent in the refits [s] (part of wall_time_s)",
    "online_floored": "M4 online re-learning: refitted components whose deconvolved scale was raised to its floor",
    "online_failed": "M4 online re-learning: refits that failed (the mixture in use was kept)",
    "online_rows_gated": "M4 online re-learning: window rows left out of a fit by the gate (counted per refit)",
    "sage_husa_scale_<kind>": "Sage-Husa EKF: the measurement-noise variance scale learned for an observable kind "
                              "at the end of the run (1: the model's R was right)",
    "vb_sigma_<channel>": "VB-adaptive filters (vb-aukf, vb-akf): the measurement-noise standard deviation "
                          "tracked for a channel (position_n ... velocity_d) at the end of the run [m, m/s]",
    "vb_sigma_mean": "VB-adaptive filters: per channel, the tracked noise standard deviation averaged over "
                     "the solution records [m, m/s]",
    "total_time_s": "wall_time_s + learning_time_s [s]",
    "smoother_time_s": "smoothed methods (<name>-smoothed): time of the RTS smoother's backward pass and "
                       "injection [s]; they have none of the forward pass's timing keys",
    "measurement_epochs": "number of GNSS epochs processed",
    "los_weight_final": "epoch mixture: the band-free line-of-sight weight at the end of the run",
    "delay_mean_m_final": "epoch mixture: the learned mean of the non-line-of-sight delay at the end [m]",
    "delay_sd_m_final": "epoch mixture: the learned spread of the non-line-of-sight delay at the end [m]",
    "innovation_log_likelihood": "epoch mixture: sum over the rows of the log predictive density of each "
                                 "innovation under the mixture (compares settings without a reference)",
    "recoveries": "counts of numerical recoveries (see mixnav.engine.engine); the robust adaptive EKF "
                  "adds its row and epoch counts (see mixnav.filters.robust_adaptive); learned-mixture methods add "
                  "learner_not_converged (offline fits that stopped before converging); mixture banks add "
                  "bank_reset (the divergence safeguard re-opened the covariance)",
    "mode_probability_mean": "IMM methods: {mode: mean probability} over the solution records",
    "mode_probability_mean_in_windows": "IMM methods: {mode: mean probability} inside the outage/withheld windows",
    "bias_error_rms_m": "EM-IMM methods, when the fixes' systematic error is known (simulation, injected "
                        "corruption): RMS of the 3-D error of the removed bias at the fixes where one was removed [m]",
    "bias_error_horizontal_axis_rms_m": "the same per north/east axis (P4's measure) [m]",
    "bias_detected_share": "share of the truly biased fixes where a bias was removed",
    "bias_false_share": "share of the removals on fixes with no bias",
    "bias_epochs_removed": "fixes where a bias was removed",
    "bias_epochs_biased": "fixes truly biased (among those the method saw)",
    "nis_mean_per_dof": "mean NIS divided by the measurement dimension (1 if consistent)",
    "nis_median_per_dof": "median NIS divided by the measurement dimension (about 0.8-0.9 if consistent; "
                          "above 5 the run is warned about, see docs/validation.md)",
}

_NEEDED = ("time_s", "err_n_m", "err_e_m", "err_d_m")
# Optional as whole groups: a reference may carry no velocity or no attitude
# (RTK positions), but a group present in part is an error.
_VEL = ("err_vn_mps", "err_ve_mps", "err_vd_mps")
_ATT = ("err_roll_deg", "err_pitch_deg", "err_yaw_deg")


def _col(df: pd.DataFrame, name: str) -> np.ndarray:
    """Column ``name`` as floats; ValueError naming it when missing or not finite."""
    if name not in df.columns:
        raise ValueError(f"solution table has no column '{name}'")
    a = df[name].to_numpy(dtype=float)
    bad = ~np.isfinite(a)
    if bad.any():
        raise ValueError(f"solution column '{name}' has a NaN or infinite value at row "
                         f"{int(np.argmax(bad))}")
    return a


def _finite_mean(x: np.ndarray) -> float:
    """Mean of the finite values (NaN when there are none)."""
    ok = np.isfinite(x)
    return float(np.mean(x[ok])) if ok.any() else float("nan")


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def compute_metrics(solution: pd.DataFrame,
                    outages: Sequence[tuple[float, float]] = (),
                    segments: Sequence[tuple[str, float, float]] = ()) -> dict:
    """RMSE, maxima and per-outage maxima of a solution table.

    Parameters
    ----------
    solution : pandas.DataFrame
        One row per epoch with ``time_s`` [s] and the error columns
        ``err_n_m, err_e_m, err_d_m`` [m], ``err_vn_mps, err_ve_mps,
        err_vd_mps`` [m/s] and ``err_roll_deg, err_pitch_deg, err_yaw_deg``
        [deg] (yaw already wrapped to [-180, 180)); optionally ``nees_pos``
        and ``nees_vel`` [-].
    outages : sequence of (start_s, end_s)
        GNSS outage windows [s]; a row belongs to a window when
        ``start_s <= time_s <= end_s``.
    segments : sequence of (name, start_s, end_s)
        Scored segments [s] (a scenario's ``[scoring] segments``); a row
        belongs to one when ``start_s <= time_s < end_s`` (half open).

    Returns
    -------
    dict
        ``{roll,pitch,yaw}_{rmse,max}_deg``, ``horizontal_{rmse,max,p95}_m``,
        ``vertical_{rmse,max}_m``, ``velocity_{rmse,max}_mps`` (floats),
        ``n_epochs`` (int), ``outages`` (one dict per window with
        ``start_s, end_s, horizontal_max_m, vertical_max_m,
        horizontal_final_m``) and, when the NEES columns exist,
        ``nees_pos_mean``, ``nees_vel_mean``; with ``segments``, ``segments``:
        ``{name: metrics}``, every whole-run metric above (no outages) of
        the segment's rows plus its ``start_s, end_s``. See :data:`METRIC_KEYS_DOC`.
        Horizontal error is ``hypot(err_n, err_e)``, vertical ``|err_d|``,
        velocity the 3-D norm; RMSE is over all rows, max of the absolute
        error.

    Raises
    ------
    ValueError
        If a needed column is missing or holds a NaN/infinity (the message
        names the column), if the table is empty, or if an outage window or
        a segment holds no row (the message names it).
    """
    groups = [g for g in (_VEL, _ATT) if any(k in solution.columns for k in g)]
    c = {k: _col(solution, k) for k in _NEEDED + sum(groups, ())}
    if len(c["time_s"]) == 0:
        raise ValueError("solution table is empty")
    hor = np.hypot(c["err_n_m"], c["err_e_m"])
    ver = np.abs(c["err_d_m"])
    m: dict = {}
    if _ATT in groups:
        for a in ("roll", "pitch", "yaw"):
            e = c[f"err_{a}_deg"]
            m[f"{a}_rmse_deg"] = _rms(e)
            m[f"{a}_max_deg"] = float(np.max(np.abs(e)))
            m[f"{a}_p95_deg"] = float(np.percentile(np.abs(e), 95))
    m["horizontal_rmse_m"] = _rms(hor)
    m["horizontal_max_m"] = float(hor.max())
    m["horizontal_p95_m"] = float(np.percentile(hor, 95))
    m["vertical_rmse_m"] = _rms(ver)
    m["vertical_max_m"] = float(ver.max())
    m["vertical_p95_m"] = float(np.percentile(ver, 95))
    if _VEL in groups:
        vel = np.sqrt(c["err_vn_mps"] ** 2 + c["err_ve_mps"] ** 2 + c["err_vd_mps"] ** 2)
        m["velocity_rmse_mps"] = _rms(vel)
        m["velocity_max_mps"] = float(vel.max())
        m["velocity_p95_mps"] = float(np.percentile(vel, 95))
    m["n_epochs"] = int(len(hor))

    t = c["time_s"]
    used = solution["gnss_used"].to_numpy(dtype=bool) if "gnss_used" in solution.columns else None
    # NaN allowed here: a singular covariance (:func:`nees`), left out of the means
    nees_cols = {k: np.asarray(solution[k], dtype=float) for k in ("nees_pos", "nees_vel") if k in solution.columns}
    windows = []
    for a, b in outages:
        a, b = float(a), float(b)
        sel = (t >= a) & (t <= b)
        if not sel.any():
            # An empty window would give NaN maxima; refuse rather than write them.
            raise ValueError(f"outage window [{a:g}, {b:g}] s holds no solution epoch")
        # the unaided stretch goes on after the window until the next GNSS update (a fix
        # that is not exactly at its end, or one rejected): its epochs before that are scored too
        unaided_end = b
        if used is not None:
            nxt = np.flatnonzero((t > b) & used)
            unaided_end = float(t[nxt[0]]) if nxt.size else float(t[-1])
            sel |= (t > b) & (t < unaided_end) if nxt.size else (t > b)
        h = hor[sel]
        w = {"start_s": a, "end_s": b, "unaided_end_s": unaided_end,
             "horizontal_max_m": float(h.max()),
             "vertical_max_m": float(ver[sel].max()),
             "horizontal_rmse_m": _rms(h), "vertical_rmse_m": _rms(ver[sel]),
             # rows are in time order: the last selected row ends the window
             "horizontal_final_m": float(h[-1])}
        for k, v in nees_cols.items():   # the window's consistency
            w[f"{k}_mean"] = _finite_mean(v[sel])
        windows.append(w)
    m["outages"] = windows
    if windows:
        outside = np.ones(len(t), dtype=bool)
        for a, b in outages:
            outside &= ~((t >= float(a)) & (t <= float(b)))
        if outside.any():
            m["horizontal_rmse_outside_outages_m"] = _rms(hor[outside])
            m["vertical_rmse_outside_outages_m"] = _rms(ver[outside])

    singular = np.zeros(len(solution), dtype=bool)
    for k, v in nees_cols.items():
        singular |= ~np.isfinite(v)
        m[f"{k}_mean"] = _finite_mean(v)
    singular = int(singular.sum())   # epochs where either block was declined
    if singular:   # the filter's covariance was singular there (:func:`nees`): said, not hidden
        m["nees_singular_epochs"] = singular
    if segments:
        m["segments"] = segment_metrics(solution, segments)
    return m


def segment_metrics(solution: pd.DataFrame, segments: Sequence[tuple[str, float, float]]) -> dict:
    """``{name: metrics}`` of each scored segment ``(name, start_s, end_s)``: the whole-run
    metrics of :func:`compute_metrics` (RMSE, max, p95 per group, NEES means, ``n_epochs``)
    of the rows with ``start_s <= time_s < end_s``, plus ``start_s`` and ``end_s``.
    ValueError naming the segment when it holds no row."""
    t = _col(solution, "time_s")
    out = {}
    for name, a, b in segments:
        a, b = float(a), float(b)
        sel = (t >= a) & (t < b)
        if not sel.any():
            raise ValueError(f"scored segment '{name}' [{a:g}, {b:g}) s holds no solution epoch")
        m = compute_metrics(solution.loc[sel])
        m.pop("outages", None)
        out[str(name)] = {"start_s": a, "end_s": b, **m}
    return out


#: A covariance is taken as singular where its correlation matrix's condition number may
#: exceed this (:func:`nees`): beyond it the inverse loses more than about 1e-6 to round-off.
NEES_CONDITION_LIMIT = 1e10


def nees(e: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``e_k^T C_k^-1 e_k`` per epoch (``e`` (K, d), ``cov`` (K, d, d)), as ``|L_R^-1 (e_k / s_k)|^2``
    with ``s_k`` the standard deviations and ``R_k = L_R L_R^T`` the correlation matrix (never
    negative; factoring R, not C, keeps covariances of any scale, even subnormal, accurate).

    NaN at an epoch whose covariance is singular or nearly so (a filter that claims a
    certainty it cannot have, e.g. a collapsed particle cloud): not finite, not positive
    definite, or with a correlation matrix whose condition number may exceed
    ``NEES_CONDITION_LIMIT``, by the bound ``kappa(R) <= d |L_R^-1|_F^2``
    (``lambda_max(R) <= trace R = d``). The correlation matrix, so that axes in different
    units (metres, micro-radians) change nothing. Each epoch is judged alone. Such epochs
    are counted in the metrics (``nees_singular_epochs``), not raised; tests/test_metrics.py
    checks the kept values against exact rational arithmetic. A NEES beyond the float range
    is ``inf`` or NaN (counted the same way); so is one of a non-finite error.
    """
    e = np.asarray(e, dtype=float)
    cov = np.asarray(cov, dtype=float)
    K, d = e.shape
    out = np.full(K, np.nan)
    var = np.diagonal(cov, axis1=1, axis2=2)
    ok = np.all(np.isfinite(cov), axis=(1, 2)) & np.all(var > 0, axis=1)
    sd = np.sqrt(np.where(ok[:, None], var, 1.0))
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        # divided twice: the product of two small deviations could underflow
        R = cov / sd[:, :, None] / sd[:, None, :]
        L = np.zeros_like(cov)
        try:
            L[ok] = np.linalg.cholesky(R[ok])
        except np.linalg.LinAlgError:   # some epoch is not positive definite: each on its own
            for k in np.flatnonzero(ok):
                try:
                    L[k] = np.linalg.cholesky(R[k])
                except np.linalg.LinAlgError:
                    ok[k] = False
        idx = np.flatnonzero(ok)
        inv = np.linalg.inv(L[idx])                      # L_R^-1 (triangular, nonsingular)
        good = d * np.einsum("kij,kij->k", inv, inv) <= NEES_CONDITION_LIMIT
        z = np.einsum("kij,kj->ki", inv[good], e[idx[good]] / sd[idx[good]])
        out[idx[good]] = np.einsum("ki,ki->k", z, z)
    return out


def bias_metrics(res: FilterResult, gnss_bias) -> dict:
    """How well a method that removes a GNSS position bias (an EM-IMM: ``outputs["bias"]``
    (K, 3) NED [m] at ``outputs["bias_times"]``) knew it, against ``gnss_bias = (times (M,),
    bias (M, 3))``, the systematic part of each fix's error (the simulation's multipath
    component means, :attr:`mixnav.sim.scenario.SimulatedRun.gnss_bias`). At the epochs it
    removed a bias: ``bias_error_rms_m`` (3-D) and ``bias_error_horizontal_axis_rms_m`` (per
    north/east axis, P4's measure); ``bias_detected_share`` of the truly biased epochs it
    saw, ``bias_false_share`` of its removals on unbiased ones; the epoch counts. Empty
    without either."""
    out = res.outputs or {}
    if gnss_bias is None or "bias" not in out or not len(out["bias_times"]):
        return {}
    tb, b_true = gnss_bias
    bt, be = np.asarray(out["bias_times"], float), np.asarray(out["bias"], float)
    k = np.clip(np.searchsorted(tb, bt - 1e-6), 0, len(tb) - 1)
    same = np.abs(tb[k] - bt) < 1e-6
    be, bk = be[same], b_true[k[same]]
    removed = np.linalg.norm(be, axis=1) > 0
    biased = np.linalg.norm(bk, axis=1) > 0
    m = {"bias_epochs_removed": int(removed.sum()), "bias_epochs_biased": int(biased.sum())}
    if removed.any():
        e = be[removed] - bk[removed]
        m["bias_error_rms_m"] = float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))
        m["bias_error_horizontal_axis_rms_m"] = float(np.sqrt(np.mean(e[:, :2] ** 2)))
        m["bias_false_share"] = float((removed & ~biased).sum() / removed.sum())
    if biased.any():
        m["bias_detected_share"] = float((removed & biased).sum() / biased.sum())
    return m


def method_metrics(res: FilterResult, table: pd.DataFrame, outages, gnss_bias=None, segments=()) -> dict:
    """Accuracy metrics plus timing, recoveries and NIS of one method; with ``gnss_bias``
    (the fixes' systematic error, simulation or injected) the bias-estimate metrics
    (:func:`bias_metrics`); with ``segments`` (``(name, start_s, end_s)``, a scenario's
    ``[scoring]``) the metrics of each (:func:`segment_metrics`)."""
    # without a reference there is nothing to score: timing and health only
    m = compute_metrics(table, outages=list(outages), segments=list(segments)) if "err_n_m" in table else {}
    m.update({k: float(v) for k, v in res.timing.items()})
    if "wall_time_s" in m:  # a smoothed method has only its smoother_time_s (rts_smooth)
        m["total_time_s"] = m["wall_time_s"] + m.get("learning_time_s", 0.0)
    m["recoveries"] = dict(res.recoveries)
    if len(res.nis):
        m["nis_mean_per_dof"] = float(np.mean(res.nis / res.nis_dim))
        m["nis_median_per_dof"] = float(np.median(res.nis / res.nis_dim))
    tracked = [c for c in table.columns if c.startswith("vb_sigma_")]
    if tracked:   # a VB-adaptive filter: the mean noise sigma it tracked per channel
        m["vb_sigma_mean"] = {c.removeprefix("vb_sigma_"): float(np.nanmean(table[c])) for c in tracked}
    modes = [c for c in table.columns if c.startswith("p_mode_")]
    if modes:   # an IMM: mean probability of each mode, overall and inside the windows
        m["mode_probability_mean"] = {c.removeprefix("p_mode_"): float(table[c].mean()) for c in modes}
        inside = table["in_outage"].to_numpy(dtype=bool)
        if inside.any():
            m["mode_probability_mean_in_windows"] = {c.removeprefix("p_mode_"): float(table.loc[inside, c].mean())
                                                     for c in modes}
    m.update(bias_metrics(res, gnss_bias))
    return m


#: median NIS per degree of freedom above which a run is warned about (docs/validation.md): a
#: consistent filter gives about 0.8-0.9 (the chi-square median per dof); the median, unlike the
#: mean, is not moved by a few outliers of heavy-tailed noise
NIS_WARN_MEDIAN = 5.0
NIS_CAUSES = ("the IMU installation (imu_rotation, misalignment) or the lever arm is wrong",
              "a unit is wrong (rates in rad/s declared as deg/s, g as m/s^2, degrees as radians)",
              "the IMU time offset or the GNSS velocity delay is wrong",
              "the GNSS or IMU noise (sigmas, grade) is set far too small for the data")
#: the same for runs without an INS (dead reckoning, constant velocity)
NIS_CAUSES_NO_INS = ("the odometry's yaw-rate axis (yaw_rate_axis) or a unit is wrong",
                     "the pseudorange variances or the motion noise are far too small for the data",
                     "the errors are not what the method's noise model says (non-line-of-sight delays are "
                     "positive and time-correlated: a Gaussian or row-by-row model in an urban canyon)")


def nis_warnings(methods: dict, causes=NIS_CAUSES) -> list[str]:
    """One warning per method whose median NIS per dof exceeds :data:`NIS_WARN_MEDIAN`
    (``causes``: the likely causes named, :data:`NIS_CAUSES` for INS runs)."""
    out = []
    for name, m in methods.items():
        v = m.get("nis_median_per_dof")
        if v is not None and v > NIS_WARN_MEDIAN:
            out.append(f"method '{name}': median NIS per degree of freedom is {v:.3g} (a consistent filter "
                       f"gives about 1; warned above {NIS_WARN_MEDIAN:g}): its measurements disagree with its "
                       "model. Likely causes: " + "; ".join(causes) + ".")
    return out
