"""Speed of the navigation core, side by side with filterpy and pyins, in one run.

    python benchmarks/bench_core.py            # writes benchmarks/results/core.{json,md}

Absolute times drift between machines and runs; the ratios measured in the
same process are the numbers to compare. Needs the ``bench`` extra
(``pip install -e ".[bench]"``: filterpy, python-ins).

What is measured (best of several repeats, after a warm-up):

1. mechanization cost per IMU step on the error-free loose-demo drive
   (60 000 steps at 100 Hz): mixnav's numba kernel against pyins's
   (``compute_increments_from_imu`` + ``Integrator.integrate``), with each
   one's final position error against the truth;
2. EKF cost per GNSS epoch at 15 states / 6 measurements: mixnav's compiled
   covariance step plus loose update and feedback, against filterpy's
   ``ExtendedKalmanFilter`` ``predict`` + ``update`` with the same F, Q, H, R;
3. whole loose filters on the same simulated loose-demo run (seed 1): mixnav
   against pyins ``run_feedback_filter`` (covariance step 1 s for both), per
   GNSS epoch and as real-time factor;
4. real-time factor of loose-demo: filter only, simulation + filter, and the
   whole ``mixnav run`` (files, figures, report).
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from _timing import best_time
from mixnav import __version__
from mixnav.attitude import quat_to_euler
from mixnav.config import load_scenario
from mixnav.experiment.run import run_scenario
from mixnav.filters.ekf import _warm_up
from mixnav.filters._ekf_kernels import ekf_correct
from mixnav.geodesy.frames import ned_displacement
from mixnav.ins._error_kernels import covariance_predict, discretize, error_dynamics
from mixnav.ins._kernels import mechanize_block
from mixnav.ins.error_model import get_layout, process_noise
from mixnav.ins.mechanization import nav_vector
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate, truth_and_ideal_imu

RESULTS = Path(__file__).resolve().parent / "results"


def bench_mechanization(truth, imu):
    import pyins.strapdown as ps
    nav0 = nav_vector(truth.q_nb[0], truth.v_n[0], truth.lla[0])
    out = np.empty((0, 10))

    def ours():
        nav = nav0.copy()
        mechanize_block(nav, np.zeros(6), imu.dtheta, imu.dvel, imu.dt, out)
        return nav

    t_ours = best_time(ours, 5, warmup=True) / len(imu)
    nav = ours()
    err_ours = float(np.linalg.norm(ned_displacement(nav[7:10], truth.lla[-1])))

    # pyins: increment-type IMU with a leading "before" sample (its convention)
    t = truth.time
    gyro = np.vstack([np.zeros(3), imu.dtheta])
    accel = np.vstack([np.zeros(3), imu.dvel])
    frame = pd.DataFrame(np.hstack([gyro, accel]), index=t,
                         columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    rpy = np.degrees(quat_to_euler(truth.q_nb[0]))
    pva = pd.Series({"lat": np.degrees(truth.lla[0, 0]), "lon": np.degrees(truth.lla[0, 1]),
                     "alt": truth.lla[0, 2], "VN": truth.v_n[0, 0], "VE": truth.v_n[0, 1],
                     "VD": truth.v_n[0, 2], "roll": rpy[0], "pitch": rpy[1], "heading": rpy[2]},
                    name=t[0])

    def theirs():
        inc = ps.compute_increments_from_imu(frame, "increment")
        integ = ps.Integrator(pva)
        return integ.integrate(inc)

    t_pyins = best_time(theirs, 3, warmup=True) / len(imu)
    last = theirs().iloc[-1]
    lla_p = np.array([np.radians(last["lat"]), np.radians(last["lon"]), last["alt"]])
    err_pyins = float(np.linalg.norm(ned_displacement(lla_p, truth.lla[-1])))
    return {"mixnav_us_per_step": t_ours * 1e6, "pyins_us_per_step": t_pyins * 1e6,
            "ratio_pyins_over_mixnav": t_pyins / t_ours,
            "mixnav_final_position_error_m": err_ours, "pyins_final_position_error_m": err_pyins,
            "steps": len(imu)}


def bench_ekf_epoch(run):
    from filterpy.kalman import ExtendedKalmanFilter
    lay = get_layout(15)
    qc, tau, _ = process_noise(lay, run.imu_model)
    nav = np.concatenate([run.truth.q_nb[20000], run.truth.v_n[20000], run.truth.lla[20000]])
    f_n = np.array([0.3, -1.2, -9.8])
    w_b = np.array([0.01, -0.02, 0.15])
    f_b = np.array([0.2, 1.1, -9.8])
    c = np.eye(3)
    la = lay.as_array()
    F = np.empty((15, 15))
    phi = np.empty((15, 15))
    qd = np.empty((15, 15))
    tmp = np.empty((15, 15))
    P0 = np.diag(np.linspace(0.01, 1.0, 15) ** 2)
    meas = LooseGnss(run.fixes, np.array([0.5, 0.2, -1.0]), lay)
    _warm_up(lay)
    fixes_i = 200

    def ours():
        P = P0.copy()
        error_dynamics(F, nav, f_n, w_b, f_b, c, la, tau)
        discretize(F, qc, 1.0, phi, qd, tmp)
        covariance_predict(P, phi, qd, tmp)
        z, H, r = meas.measure(fixes_i, nav, w_b)
        P, nis, st = ekf_correct(P, z, H, r, 1e4, nav.copy(), np.zeros(12), np.zeros(2), la)
        return P

    t_ours = best_time(ours, 7, number=2000, warmup=True)
    z, H, r = meas.measure(fixes_i, nav, w_b)
    R = np.diag(r)

    ekf = ExtendedKalmanFilter(dim_x=15, dim_z=6)
    ekf.F = phi.copy()
    ekf.Q = qd.copy()
    ekf.R = R

    def theirs():
        ekf.x = np.zeros((15, 1))
        ekf.P = P0.copy()
        ekf.predict()
        ekf.update(z.reshape(6, 1), lambda x: H, lambda x: H @ x)
        return ekf.P

    t_fp = best_time(theirs, 7, number=2000, warmup=True)
    return {"mixnav_us_per_epoch": t_ours * 1e6, "filterpy_us_per_epoch": t_fp * 1e6,
            "ratio_filterpy_over_mixnav": t_fp / t_ours, "states": 15, "measurements": 6}


def bench_filters(sc, src, run):
    """Whole loose filters on the same data: mixnav vs pyins run_feedback_filter."""
    import pyins.filters as pf
    import pyins.inertial_sensor as pis
    import pyins.measurements as pm
    import pyins.strapdown as ps
    from mixnav.filters.ekf import ErrorStateEkf
    lay = get_layout(15)
    ekf = ErrorStateEkf(lay, run.imu_model)
    meas = [LooseGnss(run.fixes, np.asarray(sc.gnss.lever_arm), lay)]
    res = ekf.run(run.imu, run.init, meas)
    t_ours = best_time(lambda: ekf.run(run.imu, run.init, meas), 3, warmup=True)
    n_ep = res.timing["measurement_epochs"]

    t = run.truth.time
    frame = pd.DataFrame(np.hstack([np.vstack([np.zeros(3), run.imu.dtheta]),
                                    np.vstack([np.zeros(3), run.imu.dvel])]), index=t,
                         columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    inc = ps.compute_increments_from_imu(frame, "increment")
    rpy = np.degrees(quat_to_euler(run.init.nav[0:4]))
    pva = pd.Series({"lat": np.degrees(run.init.nav[7]), "lon": np.degrees(run.init.nav[8]),
                     "alt": run.init.nav[9], "VN": run.init.nav[4], "VE": run.init.nav[5],
                     "VD": run.init.nav[6], "roll": rpy[0], "pitch": rpy[1], "heading": rpy[2]}, name=t[0])
    fx = run.fixes
    pos = pd.DataFrame({"lat": np.degrees(fx.lla[:, 0]), "lon": np.degrees(fx.lla[:, 1]), "alt": fx.lla[:, 2]},
                       index=fx.time)
    vel = pd.DataFrame(fx.vel_n, index=fx.time, columns=["VN", "VE", "VD"])
    m = run.imu_model
    gyro = pis.EstimationModel(bias_sd=np.hypot(m.gyro_bias, m.gyro_bias_instability), noise=m.arw)
    accel = pis.EstimationModel(bias_sd=np.hypot(m.accel_bias, m.accel_bias_instability), noise=m.vrw)
    lever = np.asarray(sc.gnss.lever_arm)
    measurements = [pm.Position(pos, float(sc.gnss.position_sigma[0]), lever),
                    pm.NedVelocity(vel, float(sc.gnss.velocity_sigma[0]), lever)]

    def theirs():
        return pf.run_feedback_filter(pva, 2.0, 0.1, 0.5, 2.0, inc, gyro, accel, measurements, time_step=1.0)

    t0 = time.perf_counter()
    theirs()
    t_pyins = time.perf_counter() - t0  # one run: it is slow
    return {"epochs": int(n_ep), "duration_s": float(t[-1] - t[0]),
            "mixnav_filter_s": t_ours, "pyins_filter_s": t_pyins,
            "mixnav_us_per_gnss_epoch": t_ours / n_ep * 1e6, "pyins_us_per_gnss_epoch": t_pyins / n_ep * 1e6,
            "ratio_pyins_over_mixnav": t_pyins / t_ours,
            "mixnav_real_time_factor": float(t[-1] - t[0]) / t_ours,
            "pyins_real_time_factor": float(t[-1] - t[0]) / t_pyins}


def bench_demo(sc, src):
    ideal = truth_and_ideal_imu(sc, src)
    t_sim_filter = best_time(lambda: run_scenario(sc, src, seed=1, ideal=ideal), 3, warmup=True)
    t_all = best_time(lambda: run_scenario(sc, src, seed=1), 3, warmup=True)
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "mixnav.cli", "run", "loose-demo", "--out", d],
                       check=True, capture_output=True)
        t_cli = time.perf_counter() - t0
    dur = sc.duration
    return {"duration_s": dur, "simulate_and_filter_s": t_all, "filter_with_cached_truth_s": t_sim_filter,
            "rtf_simulate_and_filter": dur / t_all, "cli_run_with_report_s": t_cli,
            "rtf_cli_run_with_report": dur / t_cli}


def main():
    sc, src, _ = load_scenario("loose-demo")
    truth, imu = truth_and_ideal_imu(sc, src)
    run = simulate(sc, 1, src, ideal=(truth, imu))
    results = {
        "machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine(),
                    "mixnav": __version__, "date": time.strftime("%Y-%m-%d %H:%M")},
        "mechanization": bench_mechanization(truth, imu),
        "ekf_epoch": bench_ekf_epoch(run),
        "loose_filter_vs_pyins": bench_filters(sc, src, run),
        "loose_demo": bench_demo(sc, src),
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "core.json").write_text(json.dumps(results, indent=2) + "\n")
    md = ["# Core benchmark (benchmarks/bench_core.py)", "",
          f"Recorded {results['machine']['date']}, Python {results['machine']['python']}, "
          f"mixnav {__version__}; one process, side by side.", ""]
    for section, vals in results.items():
        if section == "machine":
            continue
        md.append(f"## {section}")
        md.append("")
        md.append("| quantity | value |")
        md.append("| --- | --- |")
        for k, v in vals.items():
            md.append(f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |")
        md.append("")
    (RESULTS / "core.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
