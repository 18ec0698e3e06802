"""The outputs every pipeline writes (a simulated run, a processed dataset): the solution
table of a method (:func:`solution_table`, columns in docs/outputs.md) and the output folder
(:func:`write_outputs`: solution tables, reference, metrics.json, figures, report.html).

Output folder (every file written atomically, the folder policy of :mod:`mixnav.io.outdir`):

    solution_<method>.csv / .parquet   the solution table of each method
    reference.parquet                  the truth (run) or the reference (process)
    metrics.json                       per-method metrics, timing, recoveries
    <figure>.png                       error and trajectory figures
    map.html                           the trajectories on a web map (Leaflet, tiles online)
    report.html                        one self-contained report
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .._version import __version__
from ..attitude import attitude_error, quat_to_dcm, quat_to_euler, wrap_angle
from ..data import Trajectory
from ..filters.ekf import FilterResult
from ..geodesy.frames import displace, ned_displacement
from ..io.atomic import atomic_write_dataframe, atomic_write_json
from ..io.outdir import staged_output
from ..sim.gnss import in_windows
from . import figures
from .webmap import map_html
from .metrics import NIS_CAUSES, NIS_CAUSES_NO_INS, method_metrics, nees, nis_warnings
from .report import write_report


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
            # antenna_lla for every record at once (a loop of it was 40 % of a tuning evaluation)
            c_nb = quat_to_dcm(res.nav[:, 0:4])
            pos = displace(lla_out, np.einsum("kij,kj->ki", c_nb, lever))
            vel = vel + np.einsum("kij,kj->ki", c_nb, np.cross(res.w_b, lever))
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
    from ..filters.vb_akf import channel_label
    t, chans, sig = out["vb_time"], out["vb_channel"], out["vb_sigma"]
    cols = {}
    for ch in dict.fromkeys(chans[chans >= 0].tolist()):   # first-seen order
        k, j = np.nonzero(chans == ch)
        held = _held(t[k], sig[k, j][:, None], np.full(1, np.nan), res.time)
        cols[f"vb_sigma_{channel_label(ch)}"] = held[:, 0]
    return cols


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


def write_outputs(out_dir: Path, title: str, header: dict, results: dict[str, FilterResult],
                  tables: dict[str, pd.DataFrame], outages, reference: pd.DataFrame | None,
                  gnss: pd.DataFrame | None, notes=(), config_text: str | None = None, gnss_bias=None,
                  noise_truth: tuple | None = None, command: str = "run", overwrite: bool = False,
                  protect=(), sweeps=(), segments=()) -> dict:
    """Write solution tables, metrics.json, figures and report.html; returns the metrics.

    Shared by ``mixnav run`` (simulation, truth as reference) and ``mixnav
    process`` (real data, e.g. RTK fixes as reference). ``gnss_bias``: the fixes'
    systematic error (:func:`bias_metrics`); ``noise_truth``: ``(times, {channel: sd})`` of
    the simulated GNSS noise, drawn under the sigma a VB-adaptive filter tracked; ``sweeps``:
    :class:`~mixnav.experiment.sweep.SweepResult` s written beside (``<kind>.csv``, a
    ``<kind>`` block per method and the settings in metrics.json, a figure, a report
    table); ``segments``: ``(name, start_s, end_s)`` scored on their own (a scenario's
    ``[scoring]``: ``segments_s`` and a ``segments`` block per method). The
    folder follows the output-folder policy (:mod:`mixnav.io.outdir`): written whole into
    a temporary sibling and swapped in, a folder of another command (or with foreign
    files) refused unless ``overwrite``.
    """
    with staged_output(out_dir, command, overwrite, protect) as folder:
        return _write_outputs(folder, title, header, results, tables, outages, reference, gnss, notes,
                              config_text, gnss_bias, noise_truth, sweeps, segments)


def _write_outputs(folder, title, header, results, tables, outages, reference, gnss, notes, config_text,
                   gnss_bias, noise_truth, sweeps=(), segments=()):
    out_dir = folder.path
    metrics = dict(header)
    metrics["mixnav_version"] = __version__
    metrics["outages_s"] = [list(map(float, o)) for o in outages]
    if segments:
        metrics["segments_s"] = {str(n): [float(a), float(b)] for n, a, b in segments}
    metrics["methods"] = {name: method_metrics(results[name], tables[name], outages, gnss_bias, segments)
                          for name in tables}
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
    sections = add_sweeps(out_dir, metrics, figs, sweeps)
    # metrics.json last: its presence marks a complete output folder.
    write_report(out_dir, title, metrics, figs, notes=list(notes), config_text=config_text, sections=sections,
                 web_map=map_html(tables, reference, gnss, outages, title=title))
    atomic_write_json(out_dir / "metrics.json", metrics)
    return metrics


def add_sweeps(out_dir: Path, metrics: dict, figs: dict, sweeps=()) -> list[tuple[str, str]]:
    """Write each sweep's rows (``<kind>.csv``), put its settings and per-method blocks into
    ``metrics`` and its figure into ``figs``; the report sections (:mod:`mixnav.experiment.sweep`)."""
    sections = []
    for sw in sweeps:
        atomic_write_dataframe(Path(out_dir) / f"{sw.kind}.csv", sw.rows)
        metrics[sw.kind] = sw.settings
        for name, block in sw.summary.items():
            if name in metrics["methods"]:
                metrics["methods"][name][sw.kind] = block
        figs[sw.kind] = sw.figure()
        sections.append((sw.kind.replace("_", " "), sw.section_html()))
    return sections


def lla_frame(time, lla) -> pd.DataFrame:
    """time_s, lat_deg, lon_deg, height_m of positions ``lla`` (K, 3) [rad, rad, m] (a reference or GNSS table)."""
    return pd.DataFrame({"time_s": time, "lat_deg": np.degrees(lla[:, 0]),
                         "lon_deg": np.degrees(lla[:, 1]), "height_m": lla[:, 2]})
