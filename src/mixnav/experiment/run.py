"""One run of a scenario: simulate, filter with every method, tabulate, write.

Output folder of ``mixnav run`` (every file written atomically; see
docs/outputs.md for the columns and keys):

    solution_<method>.csv / .parquet   the solution table of each method
    truth.parquet                      the true trajectory at the output epochs
    metrics.json                       per-method metrics, timing, recoveries
    <figure>.png                       error and trajectory figures
    report.html                        one self-contained report
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .. import __version__
from ..attitude import attitude_error, quat_to_euler, wrap_angle
from ..config.schema import Scenario
from ..data import Trajectory
from ..filters import registry
from ..filters.ekf import FilterResult
from ..geodesy.frames import ned_displacement
from ..io.atomic import atomic_write_dataframe, atomic_write_json
from ..sim.gnss import in_windows
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


def run_scenario(sc: Scenario, source: str | None = None, seed: int | None = None,
                 ideal=None) -> RunOutput:
    """Simulate one seeded run and filter it with every method of the scenario."""
    seed = sc.scenario.seed if seed is None else seed
    sim = simulate(sc, seed, source, ideal=ideal)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    results = {}
    for m in sc.methods:
        filt, meas = registry.build(m, sim, lever, source)
        results[m.name] = filt.run(sim.imu, sim.init, meas)
    return RunOutput(sc, source or sc.scenario.name, sim, results)


def truth_at(truth: Trajectory, times: np.ndarray) -> Trajectory:
    """The truth at ``times``: exact where they fall on its samples, else interpolated.

    Linear in position and velocity, normalised-linear in the quaternion:
    between 100 Hz samples this is far below any filter's error.
    """
    k = np.clip(np.searchsorted(truth.time, times), 1, len(truth.time) - 1)
    t0, t1 = truth.time[k - 1], truth.time[k]
    w = ((times - t0) / (t1 - t0))[:, None]
    lerp = lambda a: a[k - 1] * (1 - w) + a[k] * w  # noqa: E731
    q0, q1 = truth.q_nb[k - 1], truth.q_nb[k]
    q1 = np.where(np.sum(q0 * q1, 1, keepdims=True) < 0, -q1, q1)
    q = q0 * (1 - w) + q1 * w
    return Trajectory(time=np.asarray(times), lla=lerp(truth.lla), v_n=lerp(truth.v_n),
                      q_nb=q / np.linalg.norm(q, axis=1, keepdims=True))


def solution_table(res: FilterResult, truth: Trajectory | None = None, outages=()) -> pd.DataFrame:
    """The solution table of one method (columns in docs/outputs.md).

    Errors are estimate minus truth; ``sig_roll/pitch/yaw_deg`` are the
    1-sigma of the attitude error about north, east and down, which equal
    the roll, pitch and yaw sigma for a near-level vehicle heading north and
    bound them otherwise.
    """
    lay = res.layout
    rpy = quat_to_euler(res.nav[:, 0:4])
    d = {"time_s": res.time,
         "lat_deg": np.degrees(res.nav[:, 7]), "lon_deg": np.degrees(res.nav[:, 8]),
         "height_m": res.nav[:, 9],
         "vn_mps": res.nav[:, 4], "ve_mps": res.nav[:, 5], "vd_mps": res.nav[:, 6],
         "roll_deg": np.degrees(rpy[:, 0]), "pitch_deg": np.degrees(rpy[:, 1]),
         "yaw_deg": np.degrees(rpy[:, 2])}
    if truth is not None:
        tt = truth_at(truth, res.time)
        e_pos = -ned_displacement(tt.lla, res.nav[:, 7:10])  # estimate - truth
        e_vel = res.nav[:, 4:7] - tt.v_n
        e_rpy = wrap_angle(rpy - tt.rpy)
        for i, ax in enumerate("ned"):
            d[f"err_{ax}_m"] = e_pos[:, i]
        for i, ax in enumerate(("vn", "ve", "vd")):
            d[f"err_{ax}_mps"] = e_vel[:, i]
        for i, ax in enumerate(("roll", "pitch", "yaw")):
            d[f"err_{ax}_deg"] = np.degrees(e_rpy[:, i])
        # NEES of the 3-D position and velocity errors, with the filter's own covariance.
        ev = np.concatenate([e_vel, e_pos], axis=1)
        cov = res.pv_cov
        d["nees_vel"] = np.einsum("ki,ki->k", e_vel, np.linalg.solve(cov[:, :3, :3], e_vel[..., None])[..., 0])
        d["nees_pos"] = np.einsum("ki,ki->k", e_pos, np.linalg.solve(cov[:, 3:, 3:], e_pos[..., None])[..., 0])
        d["nees_pv"] = np.einsum("ki,ki->k", ev, np.linalg.solve(cov, ev[..., None])[..., 0])
        d["att_err_n_deg"], d["att_err_e_deg"], d["att_err_d_deg"] = np.degrees(
            -attitude_error(res.nav[:, 0:4], tt.q_nb)).T
    s = res.sigma
    for i, ax in enumerate("ned"):
        d[f"sig_{ax}_m"] = s[:, lay.pos][:, i]
    for i, ax in enumerate(("vn", "ve", "vd")):
        d[f"sig_{ax}_mps"] = s[:, lay.vel][:, i]
    for i, ax in enumerate(("roll", "pitch", "yaw")):
        d[f"sig_{ax}_deg"] = np.degrees(s[:, lay.att][:, i])
    d["gnss_used"] = res.gnss_used
    d["in_outage"] = in_windows(res.time, outages)
    return pd.DataFrame(d)


def method_metrics(res: FilterResult, table: pd.DataFrame, outages) -> dict:
    """Accuracy metrics plus timing, recoveries and NIS of one method."""
    m = compute_metrics(table, outages=list(outages))
    m.update({k: float(v) for k, v in res.timing.items()})
    m["recoveries"] = dict(res.recoveries)
    if len(res.nis):
        m["nis_mean_per_dof"] = float(np.mean(res.nis / res.nis_dim))
    return m


def write_run(out_dir: Path, run: RunOutput, config_text: str | None = None) -> dict:
    """Write solutions, metrics, figures and the report of one run; returns the metrics."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    sim = run.sim
    tables = {name: solution_table(res, sim.truth, sim.outages) for name, res in run.results.items()}
    metrics = {"scenario": run.scenario.scenario.name, "source": run.source, "seed": sim.seed,
               "mixnav_version": __version__, "outages_s": [list(o) for o in sim.outages],
               "methods": {name: method_metrics(run.results[name], tables[name], sim.outages)
                           for name in tables}}
    for name, table in tables.items():
        atomic_write_dataframe(out_dir / f"solution_{name}.csv", table)
        atomic_write_dataframe(out_dir / f"solution_{name}.parquet", table)
    ref = pd.DataFrame({"time_s": sim.truth.time, "lat_deg": np.degrees(sim.truth.lla[:, 0]),
                        "lon_deg": np.degrees(sim.truth.lla[:, 1]), "height_m": sim.truth.lla[:, 2]})
    gnss = pd.DataFrame({"time_s": sim.fixes.time, "lat_deg": np.degrees(sim.fixes.lla[:, 0]),
                         "lon_deg": np.degrees(sim.fixes.lla[:, 1]), "height_m": sim.fixes.lla[:, 2]})
    atomic_write_dataframe(out_dir / "truth.parquet", ref)
    atomic_write_dataframe(out_dir / "gnss.csv", gnss)
    figs = {
        "errors_attitude": figures.error_figure(tables, "attitude", sim.outages),
        "errors_velocity": figures.error_figure(tables, "velocity", sim.outages),
        "errors_position": figures.error_figure(tables, "position", sim.outages),
        "horizontal_error": figures.horizontal_error_figure(tables, sim.outages),
        "trajectory": figures.trajectory_figure(tables, ref[::10], gnss, sim.outages),
    }
    notes = [f"Seed {sim.seed}; IMU errors drawn: gyro bias "
             f"{np.round(np.degrees(sim.imu_draw.gyro_bias) * 3600, 2).tolist()} deg/h, "
             f"accelerometer bias {np.round(sim.imu_draw.accel_bias / 9.80665e-6, 1).tolist()} ug.",
             "Errors are estimate minus truth; bounds are the filter's own 3-sigma."]
    # metrics.json last: its presence marks a complete output folder.
    write_report(out_dir, f"mixnav run: {run.scenario.scenario.name}", metrics, figs,
                 notes=notes, config_text=config_text)
    atomic_write_json(out_dir / "metrics.json", metrics)
    return metrics
