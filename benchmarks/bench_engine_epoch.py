"""The loose EKF epoch of the engine against filterpy 2.0's KalmanFilter, in one run.

    python benchmarks/bench_engine_epoch.py     # writes results/engine_epoch.{md,json}

Model: loose-demo (15 error states, 100 Hz IMU, 1 Hz fixes, 6 rows per epoch;
111 IMU increments per GNSS epoch on average). Four comparisons, each a ratio
measured in the same process (best of several repeats):

(0)   the Kalman maths only: our compiled covariance step (given Phi, Qd) and
      Joseph update against filterpy's predict + update;
(i)   filter work only, same discretisation: ours = the engine's epoch minus the
      mechanization of the same increments (our kernel alone); filterpy =
      ``predict()`` with our Phi and Qd + ``update(z)`` with our H and R (filterpy
      has no INS: the model's matrices are given to it ready-made);
(ii)  whole epoch, same discretisation: ours = the engine's epoch; filterpy =
      our mechanization + our Phi/Qd kernels + our rows + filterpy predict/update
      + the feedback in numpy;
(iii) whole epoch as a filterpy user runs an INS filter: ``predict()`` at every
      IMU increment (Phi = I + F dt) and one update, plus our mechanization.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from _timing import best_time
from mixnav.config import load_scenario
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.ins._error_kernels import apply_feedback, discretize, error_dynamics
from mixnav.ins._kernels import mechanize_block
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate

RESULTS = Path(__file__).resolve().parent / "results"


def best(fn):
    """Best of 7 wall times [s], after one untimed call."""
    return best_time(fn, 7, warmup=True)


def main():
    from filterpy.kalman import KalmanFilter
    import filterpy
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 1, src)
    lay = get_layout(15)
    lever = np.asarray(sc.gnss.lever_arm, float)
    filt = ErrorStateEkf(lay, sim.imu_model)
    meas = [LooseGnss(sim.fixes, lever, lay)]
    res = filt.run(sim.imu, sim.init, meas)
    n_ep = res.timing["measurement_epochs"]
    steps = len(sim.imu) / n_ep
    t_engine = best(lambda: filt.run(sim.imu, sim.init, meas)) / n_ep
    out0 = np.empty((0, 10))
    t_mech = best(lambda: mechanize_block(sim.init.nav.copy(), np.zeros(6), sim.imu.dtheta, sim.imu.dvel,
                                          sim.imu.dt, out0)) / n_ep

    # the model's matrices at a mid-drive epoch, for filterpy
    mot = filt.motion
    nav = res.nav[200].copy()
    F, phi, qd, tmp = (np.empty((15, 15)) for _ in range(4))
    la = lay.as_array()
    kernels = lambda: (error_dynamics(F, nav, np.array([0.3, -1.2, -9.8]), np.array([0.01, -0.02, 0.15]),  # noqa: E731
                                      np.array([0.2, 1.1, -9.8]), np.eye(3), la, mot.tau),
                       discretize(F, mot.qc, 1.0, phi, qd, tmp))
    kernels()
    i_fix = 200
    rows = meas[0].rows(i_fix, nav, np.zeros(3))
    kf = KalmanFilter(dim_x=15, dim_z=6)
    kf.F, kf.Q, kf.H, kf.R = phi.copy(), qd.copy(), rows.H.copy(), np.diag(rows.R)
    P0 = np.diag(res.sigma[200] ** 2)

    def fp_filter():
        kf.x = np.zeros((15, 1))
        kf.P = P0.copy()
        kf.predict()
        kf.update(rows.z.reshape(6, 1))

    t_fp = best(lambda: [fp_filter() for _ in range(500)]) / 500
    t_kern = best(lambda: [kernels() for _ in range(500)]) / 500
    t_rows = best(lambda: [meas[0].rows(i_fix, nav, np.zeros(3)) for _ in range(500)]) / 500
    sens, clk = np.zeros(12), np.zeros(2)

    def fb():
        dx = kf.x[:, 0]
        apply_feedback(nav.copy(), sens, clk, dx, la)
    t_fb = best(lambda: [fb() for _ in range(500)]) / 500
    # (iii): predict at every increment with Phi = I + F dt
    kf2 = KalmanFilter(dim_x=15, dim_z=6)
    kf2.F, kf2.Q, kf2.H, kf2.R = np.eye(15) + F * 0.01, qd * 0.01, rows.H.copy(), np.diag(rows.R)
    n_steps = int(round(steps))

    def fp_imu_rate():
        kf2.x = np.zeros((15, 1))
        kf2.P = P0.copy()
        for _ in range(n_steps):
            kf2.predict()
        kf2.update(rows.z.reshape(6, 1))
    t_fp_rate = best(lambda: [fp_imu_rate() for _ in range(20)]) / 20

    from mixnav.filters._ekf_kernels import kalman_correct
    from mixnav.ins._error_kernels import covariance_predict

    def ours_kf():
        P = P0.copy()
        covariance_predict(P, phi, qd, tmp)
        kalman_correct(P, rows.z, rows.H, rows.R, 1e4)
    t_ours_kf = best(lambda: [ours_kf() for _ in range(500)]) / 500
    ours_filter = t_engine - t_mech
    res_d = {
        "filterpy_version": filterpy.__version__, "imu_steps_per_epoch": steps, "epochs": n_ep,
        "engine_epoch_us": t_engine * 1e6, "mechanization_per_epoch_us": t_mech * 1e6,
        "engine_filter_work_us": ours_filter * 1e6,
        "filterpy_predict_update_us": t_fp * 1e6, "our_phi_qd_kernels_us": t_kern * 1e6,
        "our_rows_us": t_rows * 1e6, "numpy_feedback_us": t_fb * 1e6,
        "filterpy_imu_rate_epoch_us": t_fp_rate * 1e6, "our_predict_update_kernels_us": t_ours_kf * 1e6,
        "ratio_0_kalman_maths": t_fp / t_ours_kf,
        "ratio_i_filter_work": t_fp / ours_filter,
        "ratio_ii_whole_epoch": (t_mech + t_kern + t_rows + t_fp + t_fb) / t_engine,
        "ratio_iii_imu_rate_predicts": (t_mech + t_fp_rate) / t_engine,
        "load_average": open("/proc/loadavg").read().split()[:3],
    }
    (RESULTS / "engine_epoch.json").write_text(json.dumps(res_d, indent=1))
    md = ["# Loose EKF epoch: the engine against filterpy 2.0 (one run, best of 7)", "",
          "Produced by `benchmarks/bench_engine_epoch.py` (definitions in its docstring); loose-demo, 15 states, "
          f"{steps:.0f} IMU increments and 6 rows per epoch; load average {' '.join(res_d['load_average'])}.", "",
          "| quantity | us |", "|---|---|"]
    md += [f"| {k} | {v:.1f} |" for k, v in res_d.items() if k.endswith("_us")]
    md += ["", "| comparison | filterpy / ours |", "|---|---|",
           f"| (0) Kalman maths only: covariance step with given Phi/Qd + 6-row update | {res_d['ratio_0_kalman_maths']:.2f} |",
           f"| (i) filter work only, same discretisation | {res_d['ratio_i_filter_work']:.2f} |",
           f"| (ii) whole epoch, same discretisation | {res_d['ratio_ii_whole_epoch']:.2f} |",
           f"| (iii) whole epoch, filterpy predicting at the IMU rate | {res_d['ratio_iii_imu_rate_predicts']:.2f} |",
           "", "Reading: filterpy 2.0's `KalmanFilter` predict+update is itself about "
           f"{t_fp * 1e6:.0f} us at this size, so the issue's '>= 4x' holds only where filterpy does the work an "
           "INS filter needs at the IMU rate (iii); on the same discretisation the engine's whole filter work "
           "(covariance step, rows, Joseph update, feedback, recording, dispatch) is compared in (i) and the "
           "whole epoch, mechanization included, in (ii)."]
    (RESULTS / "engine_epoch.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
