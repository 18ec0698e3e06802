"""Accuracy checks of the navigation core, recorded for the issue notes.

    python benchmarks/accuracy_core.py     # writes benchmarks/results/accuracy.{json,md}

1. error-free loose-demo (600 s at 100 Hz) through the mechanization;
2. Schuler period of a stationary INS with a 1e-4 rad tilt (equator, height held);
3. PSINS laser-gyro record: coarse-alignment heading against the header, and
   the free-inertial horizontal drift over the record (height held, since the
   free-inertial vertical channel diverges);
4. loose EKF on loose-demo, 20 seeds: NEES, NIS, outage drift, RMSE.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from mixnav.alignment import coarse_align
from mixnav.attitude import attitude_error, quat_multiply, rotvec_to_quat, wrap_angle
from mixnav.config import load_scenario
from mixnav.data import ImuData
from mixnav.experiment.run import run_scenario, solution_table
from mixnav.geodesy import earth
from mixnav.geodesy.frames import ned_displacement
from mixnav.ins._kernels import mechanize_block
from mixnav.ins.mechanization import free_inertial, nav_vector
from mixnav.io.psins import read_psins_imu
from mixnav.sim.scenario import truth_and_ideal_imu
from mixnav.sim.trajectory import InitialState, MotionSegment, generate

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MIXNAV_DATA", ROOT.parent / "shared" / "data"))
RESULTS = ROOT / "benchmarks" / "results"


def held_height_run(imu, nav0, h, block):
    nav = nav0.copy()
    prev = np.zeros(6)
    empty = np.empty((0, 10))
    out = []
    for a in range(0, len(imu), block):
        b = min(a + block, len(imu))
        mechanize_block(nav, prev, imu.dtheta[a:b], imu.dvel[a:b], imu.dt[a:b], empty)
        nav[6], nav[9] = 0.0, h
        out.append(nav.copy())
    return np.array(out)


def round_trip():
    sc, src, _ = load_scenario("loose-demo")
    truth, imu = truth_and_ideal_imu(sc, src)
    sol = free_inertial(imu, nav_vector(truth.q_nb[0], truth.v_n[0], truth.lla[0]))
    dpos = ned_displacement(sol.lla, truth.lla)
    datt = attitude_error(sol.q_nb, truth.q_nb)
    return {"final_position_error_m": float(np.linalg.norm(dpos[-1])),
            "max_position_error_m": float(np.linalg.norm(dpos, axis=1).max()),
            "final_attitude_error_rad": float(np.linalg.norm(datt[-1])),
            "max_attitude_error_rad": float(np.linalg.norm(datt, axis=1).max()),
            "max_velocity_error_mps": float(np.abs(sol.v_n - truth.v_n).max())}


def schuler():
    rate = 10.0
    truth, imu = generate([MotionSegment("static", 10200.0)], InitialState((0.0, 0.3, 0.0), 0.0, (0, 0, 0)), rate)
    q0 = quat_multiply(rotvec_to_quat(-np.array([1e-4, 0, 0])), truth.q_nb[0])
    out = held_height_run(imu, nav_vector(q0, truth.v_n[0], truth.lla[0]), 0.0, int(rate))
    t = np.arange(1, len(out) + 1) * 1.0
    e = ned_displacement(truth.lla[::int(rate)][1:len(out) + 1], out[:, 7:10])[:, 1]
    de = np.diff(e)
    ext = np.nonzero(np.sign(de[1:]) != np.sign(de[:-1]))[0]
    measured = 2 * np.mean(np.diff(t[ext + 1]))
    theory = 2 * np.pi * np.sqrt(earth.A_WGS84 / earth.normal_gravity(0.0, 0.0))
    return {"period_measured_min": measured / 60, "period_theory_min": theory / 60,
            "peak_east_error_m": float(np.abs(e).max()), "peak_theory_m": 2 * earth.A_WGS84 * 1e-4}


def lasergyro():
    path = DATA / "psins-lasergyro" / "lasergyro.imu"
    if not path.exists():
        return {"skipped": f"{path} not found"}
    imu, hdr = read_psins_imu(path)
    a = coarse_align(imu, hdr.lla[0], hdr.lla[2])
    out = {"header_yaw_ned_deg": float(np.degrees(hdr.rpy[2])),
           "aligned_roll_deg": float(np.degrees(a.rpy[0])), "aligned_pitch_deg": float(np.degrees(a.rpy[1])),
           "aligned_yaw_ned_deg": float(np.degrees(a.rpy[2])),
           "yaw_error_deg": float(np.degrees(wrap_angle(a.rpy[2] - hdr.rpy[2]))),
           "yaw_sigma_deg_30s_blocks": float(np.degrees(a.yaw_sigma_noise)),
           "record_s": float(imu.time[-1] - imu.start_time)}
    for label, n_level in (("whole_record_alignment", len(imu)), ("level_first_10s", 1000)):
        sub = ImuData(imu.time[:n_level], imu.dt[:n_level], imu.dtheta[:n_level], imu.dvel[:n_level])
        lev = coarse_align(sub, hdr.lla[0], hdr.lla[2], use_gyro_heading=False, yaw=a.rpy[2])
        nav = held_height_run(imu, nav_vector(lev.q_nb, np.zeros(3), hdr.lla), hdr.lla[2], 100)
        d = ned_displacement(nav[:, 7:10], hdr.lla)
        h = np.hypot(d[:, 0], d[:, 1])
        out[f"drift_{label}_at_300s_m"] = float(h[299])
        out[f"drift_{label}_end_m"] = float(h[-1])
    return out


def loose_demo_monte_carlo(runs=20):
    sc, src, _ = load_scenario("loose-demo")
    ideal = truth_and_ideal_imu(sc, src)
    tabs, nis = [], []
    for seed in range(runs):
        run = run_scenario(sc, src, seed=seed, ideal=ideal)
        r = run.results["ekf"]
        tabs.append(solution_table(r, run.sim.truth, run.sim.outages))
        nis.append(np.mean(r.nis / r.nis_dim))
    nees = np.array([t["nees_pv"] for t in tabs]).mean(0)
    lo, hi = chi2.ppf([0.025, 0.975], runs * 6) / runs
    (a, b), = sc.gnss.outages
    sel = lambda t: (t.time_s > a) & (t.time_s <= b)  # noqa: E731
    hmax = np.array([np.hypot(t.err_n_m, t.err_e_m)[sel(t)].max() for t in tabs])
    vmax = np.array([np.abs(t.err_d_m)[sel(t)].max() for t in tabs])
    out_rms = np.array([np.sqrt(np.mean((t.err_n_m ** 2 + t.err_e_m ** 2)[~t.in_outage])) for t in tabs])
    yaw = np.array([np.sqrt(np.mean(t.err_yaw_deg ** 2)) for t in tabs])
    return {"runs": runs, "anees_pv_mean": float(nees.mean()), "dof": 6,
            "band_95": [float(lo), float(hi)], "share_of_epochs_in_band": float(np.mean((nees >= lo) & (nees <= hi))),
            "nees_pos_mean": float(np.mean([t.nees_pos.mean() for t in tabs])),
            "nees_vel_mean": float(np.mean([t.nees_vel.mean() for t in tabs])),
            "nis_per_dof_mean": float(np.mean(nis)),
            "outage_60s_horizontal_max_m": {"median": float(np.median(hmax)), "mean": float(hmax.mean()),
                                            "min": float(hmax.min()), "max": float(hmax.max())},
            "outage_60s_vertical_max_m_median": float(np.median(vmax)),
            "horizontal_rmse_outside_outage_m_mean": float(out_rms.mean()),
            "yaw_rmse_deg_mean": float(yaw.mean())}


def main():
    res = {"date": time.strftime("%Y-%m-%d %H:%M"), "round_trip_loose_demo": round_trip(),
           "schuler": schuler(), "psins_lasergyro": lasergyro(), "loose_demo_20_seeds": loose_demo_monte_carlo()}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "accuracy.json").write_text(json.dumps(res, indent=2) + "\n")
    md = ["# Accuracy checks (benchmarks/accuracy_core.py)", "", f"Recorded {res['date']}.", ""]
    for k, v in res.items():
        if k == "date":
            continue
        md += [f"## {k}", "", "| quantity | value |", "| --- | --- |"]
        md += [f"| {kk} | {vv:.4g} |" if isinstance(vv, float) else f"| {kk} | {vv} |" for kk, vv in v.items()]
        md.append("")
    (RESULTS / "accuracy.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
