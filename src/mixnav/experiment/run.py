"""One run of a scenario: simulate, filter with every method, tabulate, write.

Output folder of ``mixnav run`` (every file written atomically; see
docs/outputs.md for the columns and keys):

    solution_<method>.csv / .parquet   the solution table of each method
    reference.parquet                  the truth (run) or the reference (process)
    metrics.json                       per-method metrics, timing, recoveries
    <figure>.png                       error and trajectory figures
    report.html                        one self-contained report
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .._version import __version__
from ..attitude import attitude_error, quat_to_dcm, quat_to_euler, wrap_angle
from ..config.schema import Scenario
from ..data import Trajectory
from . import methods
from .aiding import AidingInputs
from ..filters.ekf import FilterResult
from ..geodesy.frames import displace, ned_displacement
from ..measurements.loose import antenna_lla
from ..io.atomic import atomic_write_dataframe, atomic_write_json
from ..io.outdir import staged_output
from ..sim.gnss import in_windows
from ..sim.rng import Streams
from ..sim.scenario import SimulatedRun, simulate
from . import figures
from .metrics import compute_metrics
from .report import write_report


@dataclass
class RunOutput:
    scenario: Scenario
    source: str
    sim: SimulatedRun
    results: dict[str, FilterResult]
    aiding: dict = field(default_factory=dict)   # AidingInputs.summary(): still intervals, thresholds


def run_scenario(sc: Scenario, source: str | None = None, seed: int | None = None,
                 ideal=None) -> RunOutput:
    """Simulate one seeded run and filter it with every method of the scenario."""
    seed = sc.scenario.seed if seed is None else seed
    sim = simulate(sc, seed, source, ideal=ideal)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    results = {}
    clock = None
    if sc.gnss.satellites is not None:
        from ..ins.error_model import ClockModel
        s = sc.gnss.satellites
        clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    training = _training(sc, seed, source)
    aiding = AidingInputs(sc.aiding, sim.imu, sim.fixes, sim.init.time, float(sim.imu.time[-1]),
                          odometer=getattr(sim, "odometer", None), source=source)
    for i, m in enumerate(sc.methods):
        filt, meas = methods.build(m, sim.imu_model, sim.fixes, lever, source, i,
                                    observations=sim.observations, clock=clock, training=training,
                                    seed=seed, aiding=aiding)
        # each estimator its own stream, independent of the simulation's and of the other methods'
        results.update(methods.run_method(m, filt, sim.imu, sim.init, meas, source, i, [x.name for x in sc.methods],
                                          rng=Streams(seed).get(f"filter:{m.name}")))
    return RunOutput(sc, source or sc.scenario.name, sim, results, aiding.summary())


def _training(sc: Scenario, seed: int, source):
    """Training residuals for the methods that learn their mixtures (one draw shared by all),
    and training series for the coloured-noise methods (M6) that fit or whiten with them."""
    mixture_tables = [m.mixture for m in sc.methods if m.mixture is not None]
    mixture_tables += [mode.mixture for m in sc.methods if m.imm is not None for mode in m.imm.modes
                       if mode.mixture is not None]           # an IMM's mixture modes learn too
    learners = [mc.learn for mc in mixture_tables if mc.learn is not None and mc.learn.offline]
    colored = [m.mixture for m in sc.methods if m.mixture is not None and m.mixture.colored is not None]
    if not learners and not colored:
        return None
    from ..sim.training import training_residuals, training_series
    out = {}
    if learners:
        kinds = sorted({k for lc in learners for k in lc.observables})
        n = max(lc.training_samples for lc in learners)
        out = training_residuals(sc, seed, kinds, n, any(lc.learn_process for lc in learners), source)
    if colored:
        from ..sim.training import TRAINING_CHANNELS
        kinds = sorted({k for mc in colored for k in mc.colored.measurement} |
                       {k for mc in colored if mc.learn is not None for k in mc.learn.observables})
        process = any(mc.colored.process == "fit" or (mc.learn is not None and mc.learn.learn_process)
                      for mc in colored)
        n = max([mc.learn.training_samples for mc in colored if mc.learn is not None] + [2000])
        out["series"] = training_series(sc, seed, [k for k in kinds if k in ("pseudorange", "range_rate")],
                                        -(-n // TRAINING_CHANNELS) + 1, process, source)
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


def truth_at(truth: Trajectory, times: np.ndarray) -> Trajectory:
    """The truth at ``times``: exact where they fall on its samples, else interpolated.

    Linear in position and velocity, normalised-linear in the quaternion:
    between 100 Hz samples this is far below any filter's error. Missing
    velocity or attitude stays missing.
    """
    k = np.clip(np.searchsorted(truth.time, times), 1, len(truth.time) - 1)
    t0, t1 = truth.time[k - 1], truth.time[k]
    w = ((times - t0) / (t1 - t0))[:, None]
    lerp = lambda a: None if a is None else a[k - 1] * (1 - w) + a[k] * w  # noqa: E731
    q = None
    if truth.q_nb is not None:
        q0, q1 = truth.q_nb[k - 1], truth.q_nb[k]
        q1 = np.where(np.sum(q0 * q1, 1, keepdims=True) < 0, -q1, q1)
        q = q0 * (1 - w) + q1 * w
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return Trajectory(time=np.asarray(times), lla=lerp(truth.lla), v_n=lerp(truth.v_n), q_nb=q)


def solution_table(res: FilterResult, truth: Trajectory | None = None, outages=(),
                   lever=None) -> pd.DataFrame:
    """The solution table of one method (columns in docs/outputs.md).

    Errors are estimate minus truth; ``sig_roll/pitch/yaw_deg`` are the
    1-sigma of the attitude error about north, east and down, which equal
    the roll, pitch and yaw sigma for a near-level vehicle heading north and
    bound them otherwise. When ``lever`` (body frame [m]) is given, the
    truth is of that point (a GNSS antenna serving as reference) and the
    solution is moved there before the errors are taken. Error columns of a
    quantity the truth lacks (velocity, attitude) are left out.

    A method that estimates the IMU time offset (``imu_time_offset`` states,
    :mod:`mixnav.measurements.loose`) reports its state at the true time of
    each record: the INS labelled ``t`` is the vehicle at ``t + dt``, so the
    position is moved by ``-v dt`` and the velocity by ``-a dt`` (``a`` from
    the records' velocities). One that estimates the antenna lever arm moves
    the solution to the antenna with the corrected lever ``lever + dl``.
    """
    lay = res.layout
    rpy = quat_to_euler(res.nav[:, 0:4])
    lla_out, v_out = _at_true_time(res)
    d = {"time_s": res.time,
         "lat_deg": np.degrees(lla_out[:, 0]), "lon_deg": np.degrees(lla_out[:, 1]),
         "height_m": lla_out[:, 2],
         "vn_mps": v_out[:, 0], "ve_mps": v_out[:, 1], "vd_mps": v_out[:, 2],
         "roll_deg": np.degrees(rpy[:, 0]), "pitch_deg": np.degrees(rpy[:, 1]),
         "yaw_deg": np.degrees(rpy[:, 2])}
    if truth is not None:
        tt = truth_at(truth, res.time)
        pos, vel = lla_out, v_out
        if lever is not None:
            lever = np.broadcast_to(np.asarray(lever, dtype=float), (len(res.time), 3))
            if "gnss_lever" in res.estimates:
                lever = lever + res.estimates["gnss_lever"]
            nav = res.nav.copy()
            nav[:, 7:10] = lla_out
            pos = np.array([antenna_lla(n, la) for n, la in zip(nav, lever)])
            vel = vel + np.einsum("kij,kj->ki", quat_to_dcm(res.nav[:, 0:4]), np.cross(res.w_b, lever))
        e_pos = -ned_displacement(tt.lla, pos)  # estimate - truth
        for i, ax in enumerate("ned"):
            d[f"err_{ax}_m"] = e_pos[:, i]
        cov = res.pv_cov
        d["nees_pos"] = nees(e_pos, cov[:, 3:, 3:])
        if tt.v_n is not None:
            e_vel = vel - tt.v_n
            for i, ax in enumerate(("vn", "ve", "vd")):
                d[f"err_{ax}_mps"] = e_vel[:, i]
            # NEES of the 3-D position and velocity errors, with the filter's own covariance.
            ev = np.concatenate([e_vel, e_pos], axis=1)
            d["nees_vel"] = nees(e_vel, cov[:, :3, :3])
            d["nees_pv"] = nees(ev, cov)
        if tt.q_nb is not None:
            e_rpy = wrap_angle(rpy - tt.rpy)
            for i, ax in enumerate(("roll", "pitch", "yaw")):
                d[f"err_{ax}_deg"] = np.degrees(e_rpy[:, i])
            d["att_err_n_deg"], d["att_err_e_deg"], d["att_err_d_deg"] = np.degrees(
                -attitude_error(res.nav[:, 0:4], tt.q_nb)).T
    s = res.sigma
    for i, ax in enumerate("ned"):
        d[f"sig_{ax}_m"] = s[:, lay.pos][:, i]
    if lay.vel is not None:     # a dead-reckoning layout has no velocity or attitude block
        for i, ax in enumerate(("vn", "ve", "vd")):
            d[f"sig_{ax}_mps"] = s[:, lay.vel][:, i]
    if lay.att is not None:
        for i, ax in enumerate(("roll", "pitch", "yaw")):
            d[f"sig_{ax}_deg"] = np.degrees(s[:, lay.att][:, i])
    elif lay.has("heading"):
        d["sig_yaw_deg"] = np.degrees(s[:, lay.slice("heading")][:, 0])
    d["gnss_used"] = res.gnss_used
    d["in_outage"] = in_windows(res.time, outages)
    d.update(_mode_columns(res))
    d.update(_bias_columns(res))
    d.update(_noise_columns(res))
    return pd.DataFrame(d)


def _noise_columns(res: FilterResult) -> dict:
    """``vb_sigma_<channel>`` (e.g. ``vb_sigma_position_n`` [m], ``vb_sigma_velocity_d``
    [m/s], ``vb_sigma_pseudorange_12`` [m] for PRN 12): the measurement-noise standard
    deviation a VB-adaptive filter (vb-aukf, vb-akf) tracked for each channel, at that
    channel's latest update at or before each record (NaN before its first)."""
    out = getattr(res, "outputs", None) or {}
    if "vb_sigma" not in out or not len(out["vb_time"]):
        return {}
    from ..filters.vb import channel_label
    t, chans, sig = out["vb_time"], out["vb_channel"], out["vb_sigma"]
    cols = {}
    for ch in dict.fromkeys(chans[chans >= 0].tolist()):   # first-seen order
        k, j = np.nonzero(chans == ch)
        held = _held(t[k], sig[k, j][:, None], np.full(1, np.nan), res.time)
        cols[f"vb_sigma_{channel_label(ch)}"] = held[:, 0]
    return cols


def gnss_noise_sd(scenario, source: str, times: np.ndarray) -> dict:
    """The true standard deviation of the simulated GNSS noise per loose channel at
    ``times``: ``{"position_n": (n,), ..., "velocity_d": (n,)}`` (the noise process's
    :meth:`~mixnav.noise.processes.NoiseProcess.sd`, or the stated sigma when the file
    gives no process); a channel whose process has no closed-form sd is left out."""
    from ..config.loader import gnss_noise
    pos, vel = gnss_noise(scenario, source)
    g = scenario.gnss
    t = np.asarray(times, dtype=float)
    out = {}
    for name, proc, stated in (("position", pos, g.position_sigma), ("velocity", vel, g.velocity_sigma)):
        if proc is not None:
            sd = proc.sd(t, 3)
        elif stated is not None:
            sd = np.broadcast_to(np.asarray(stated, dtype=float), (t.size, 3))
        else:
            sd = None
        if sd is not None:
            out.update({f"{name}_{ax}": sd[:, i] for i, ax in enumerate("ned")})
    return out


def _bias_columns(res: FilterResult) -> dict:
    """``bias_n_m``, ``bias_e_m``, ``bias_d_m``: the multipath bias an EM-IMM removed at the
    latest GNSS epoch at or before each record (zero where it removed none)."""
    out = getattr(res, "outputs", None) or {}
    if "bias" not in out:
        return {}
    held = _held(out["bias_times"], out["bias"], np.zeros(3), res.time)
    return {f"bias_{ax}_m": held[:, i] for i, ax in enumerate("ned")}


def _mode_columns(res: FilterResult) -> dict:
    """``p_mode_<name>``: an IMM's mode probabilities at each record, those of the latest
    cycle at or before it (the initial ones before the first)."""
    out = getattr(res, "outputs", None) or {}
    if "mode_probabilities" not in out:
        return {}
    held = _held(out["mode_times"], out["mode_probabilities"], out["mode_initial"], res.time)
    return {f"p_mode_{name}": held[:, j] for j, name in enumerate(out["mode_names"])}


def _held(times: np.ndarray, values: np.ndarray, before: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``values`` (K, d) at ``times`` (K,) held to the query times ``at`` (N,): the latest
    row at or before each (``before`` (d,) ahead of the first); (N, d)."""
    rows = np.vstack([np.asarray(before, dtype=float)[None, :],
                      np.asarray(values, dtype=float).reshape(len(times), -1)])
    return rows[np.searchsorted(times, at + 1e-9, side="right")]


def _at_true_time(res: FilterResult) -> tuple[np.ndarray, np.ndarray]:
    """Position (lla) and NED velocity of each record at its true time (see
    :func:`solution_table`): the INS's own without an ``imu_time_offset`` estimate."""
    lla, v = res.nav[:, 7:10], res.nav[:, 4:7]
    est = res.estimates.get("imu_time_offset")
    if est is None or len(res.time) < 2:
        return lla, v
    dt = est[:, 0:1]
    # records at repeated times (none from the engine today) would make the gradient infinite
    a = np.gradient(v, res.time, axis=0) if np.all(np.diff(res.time) > 0) else np.zeros_like(v)
    return displace(lla, -v * dt), v - a * dt


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


def method_metrics(res: FilterResult, table: pd.DataFrame, outages, gnss_bias=None) -> dict:
    """Accuracy metrics plus timing, recoveries and NIS of one method; with ``gnss_bias``
    (the fixes' systematic error, simulation or injected) the bias-estimate metrics
    (:func:`bias_metrics`)."""
    # without a reference there is nothing to score: timing and health only
    m = compute_metrics(table, outages=list(outages)) if "err_n_m" in table else {}
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


def write_outputs(out_dir: Path, title: str, header: dict, results: dict[str, FilterResult],
                  tables: dict[str, pd.DataFrame], outages, reference: pd.DataFrame | None,
                  gnss: pd.DataFrame | None, notes=(), config_text: str | None = None, gnss_bias=None,
                  noise_truth: tuple | None = None, command: str = "run", overwrite: bool = False,
                  protect=()) -> dict:
    """Write solution tables, metrics.json, figures and report.html; returns the metrics.

    Shared by ``mixnav run`` (simulation, truth as reference) and ``mixnav
    process`` (real data, e.g. RTK fixes as reference). ``gnss_bias``: the fixes'
    systematic error (:func:`bias_metrics`); ``noise_truth``: ``(times, {channel: sd})`` of
    the simulated GNSS noise, drawn under the sigma a VB-adaptive filter tracked. The
    folder follows the output-folder policy (:mod:`mixnav.io.outdir`): written whole into
    a temporary sibling and swapped in, a folder of another command (or with foreign
    files) refused unless ``overwrite``.
    """
    with staged_output(out_dir, command, overwrite, protect) as folder:
        return _write_outputs(folder, title, header, results, tables, outages, reference, gnss, notes,
                              config_text, gnss_bias, noise_truth)


def _write_outputs(folder, title, header, results, tables, outages, reference, gnss, notes, config_text,
                   gnss_bias, noise_truth):
    out_dir = folder.path
    metrics = dict(header)
    metrics["mixnav_version"] = __version__
    metrics["outages_s"] = [list(map(float, o)) for o in outages]
    metrics["methods"] = {name: method_metrics(results[name], tables[name], outages, gnss_bias) for name in tables}
    ins = any(getattr(r.layout, "is_ins", True) for r in results.values())
    warned = nis_warnings(metrics["methods"], NIS_CAUSES if ins else NIS_CAUSES_NO_INS)
    if warned:
        metrics["warnings"] = warned
        notes = [*notes, *("Warning: " + w for w in warned)]
    for name, table in tables.items():
        atomic_write_dataframe(folder.file(f"solution_{name}.csv"), table)
        atomic_write_dataframe(folder.file(f"solution_{name}.parquet"), table)
    if reference is not None:
        atomic_write_dataframe(out_dir / "reference.parquet", reference)
    if gnss is not None:
        atomic_write_dataframe(out_dir / "gnss.csv", gnss)
    first = next(iter(tables.values()))
    figs = {}
    if "err_n_m" in first:
        figs["horizontal_error"] = figures.horizontal_error_figure(tables, outages)
        figs["errors_position"] = figures.error_figure(tables, "position", outages)
    if "err_vn_mps" in first:
        figs["errors_velocity"] = figures.error_figure(tables, "velocity", outages)
    if "err_roll_deg" in first:
        figs["errors_attitude"] = figures.error_figure(tables, "attitude", outages)
    figs["trajectory"] = figures.trajectory_figure(tables, reference, gnss, outages)
    modes = figures.mode_probability_figure(tables, outages)
    if modes is not None:
        figs["mode_probabilities"] = modes
    tracked = figures.noise_sigma_figure(tables, noise_truth, outages)
    if tracked is not None:
        figs["tracked_noise_sigma"] = tracked
    # metrics.json last: its presence marks a complete output folder.
    write_report(out_dir, title, metrics, figs, notes=list(notes), config_text=config_text)
    atomic_write_json(out_dir / "metrics.json", metrics)
    return metrics


def _lla_frame(time, lla) -> pd.DataFrame:
    return pd.DataFrame({"time_s": time, "lat_deg": np.degrees(lla[:, 0]),
                         "lon_deg": np.degrees(lla[:, 1]), "height_m": lla[:, 2]})


def run_tables(run: RunOutput) -> dict[str, pd.DataFrame]:
    """The solution table of every method of a simulated run, errors against the truth."""
    return {name: solution_table(res, run.sim.truth, run.sim.outages) for name, res in run.results.items()}


def write_run(out_dir: Path, run: RunOutput, config_text: str | None = None, overwrite: bool = False) -> dict:
    """Write solutions, metrics, figures and the report of one simulated run (the folder
    policy of :mod:`mixnav.io.outdir`; ``overwrite`` clears a folder it would refuse)."""
    sim = run.sim
    tables = run_tables(run)
    notes = [f"Seed {sim.seed}; IMU errors drawn: gyro bias "
             f"{np.round(np.degrees(sim.imu_draw.gyro_bias) * 3600, 2).tolist()} deg/h, "
             f"accelerometer bias {np.round(sim.imu_draw.accel_bias / 9.80665e-6, 1).tolist()} ug.",
             "Errors are estimate minus truth; bounds are the filter's own 3-sigma."]
    header = {"scenario": run.scenario.scenario.name, "source": run.source, "seed": sim.seed}
    if run.aiding:
        header["aiding"] = run.aiding
    truth = None
    if any(c.startswith("vb_sigma_") for t in tables.values() for c in t.columns):
        truth = (sim.fixes.time, gnss_noise_sd(run.scenario, run.source, sim.fixes.time))
    return write_outputs(out_dir, f"mixnav run: {run.scenario.scenario.name}", header, run.results, tables,
                         sim.outages, _lla_frame(sim.truth.time, sim.truth.lla)[::10],
                         _lla_frame(sim.fixes.time, sim.fixes.lla), notes, config_text, sim.gnss_bias,
                         noise_truth=truth, command="run", overwrite=overwrite, protect=[run.source])
