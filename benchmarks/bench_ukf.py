"""Speed of the UKF family against our EKF and filterpy's UnscentedKalmanFilter, in one run.

    python benchmarks/bench_ukf.py            # writes benchmarks/results/ukf.{json,md}

The unit is one GNSS epoch of loose-demo with 21 states: one 1 s propagation step
(100 IMU increments) followed by one 6-row loose update (position + velocity) and the
feedback. Measured with the engine's step API on the same simulated run (seed 1),
per epoch with a GNSS update, mean over the run, best of several runs:

- mixnav EKF (M1): compiled propagation of the nominal and P, compiled update;
- mixnav UKF (M7): the same nominal propagation (it also gives Qd), then the 43 sigma
  points mechanized over the step (4 merged sub-intervals, the default) with their moments in one
  compiled call; at the update the sigma points again, ``predict_batch`` and the
  compiled unscented correction;
- mixnav VB-AUKF with 3 fixed-point iterations;
- filterpy 2.0 ``UnscentedKalmanFilter`` on the *same model*: the same error-state
  parameterisation, the same nominal propagation and Qd, its ``fx`` mechanizing one
  sigma point over the same 4 merged sub-intervals with mixnav's compiled kernel and
  its ``hx`` mixnav's compiled loose prediction of one state; filterpy builds the
  sigma points (``MerweScaledSigmaPoints``, same alpha, beta, kappa), loops over
  them in Python and forms the moments in numpy. Its solution is checked against ours.

Absolute times drift with the machine's load; the ratios measured in the same process
are the numbers to compare.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

from mixnav import __version__
from mixnav.config import load_scenario
from mixnav.ins._batch_kernels import nav_difference
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.filters.ukf import UnscentedKalmanFilter, VbAdaptiveUkf
from mixnav.ins._error_kernels import apply_feedback, mechanize_batch, propagate_block
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate

RESULTS = Path(__file__).resolve().parent / "results"
N_STATES = 21


def engine_epoch_us(filt, sim, lever, repeats=3):
    """Mean time of the engine steps that end in a GNSS update [us] (best of ``repeats`` runs),
    and the result of the last run."""
    best = np.inf
    for _ in range(repeats):
        eng = filt.engine([LooseGnss(sim.fixes, lever, filt.layout)])
        eng.start(sim.imu, sim.init)
        times = []
        perf = time.perf_counter
        while True:
            ti = eng._ti
            measured = ti in eng._events
            t0 = perf()
            if not eng.step():
                break
            if measured:
                times.append(perf() - t0)
        best = min(best, float(np.mean(times)) * 1e6)
        res = eng.result()
    return best, res


def filterpy_run(sim, lever, n_epochs, substeps=4):
    """filterpy's UKF on the same model over the first ``n_epochs`` GNSS epochs; returns the
    mean time per epoch [us] and the final nominal state."""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter as FUkf
    lay = get_layout(N_STATES)
    ekf = ErrorStateEkf(lay, sim.imu_model)      # for the motion model (nominal, Qd)
    motion = ekf.motion
    la = lay.as_array()
    model = LooseGnss(sim.fixes, lever, lay)
    imu = sim.imu
    n = lay.n
    tau = np.asarray(motion.tau, float)
    clock = np.zeros(2)

    def fx(dx, dt, nav0, prev0, sensor0, gth, gdv, gdt, ref, decay):
        navs = nav0[None].copy()
        sens = sensor0[None].copy()
        apply_feedback(navs[0], sens[0], clock, dx, la)
        prevs = prev0[None].copy()
        mechanize_batch(navs, prevs, sens, gth, gdv, gdt)
        out = dx.copy()
        nav_difference(navs[0], ref, out)
        out[9:] = dx[9:] * decay
        return out

    def hx(dx, nav, w_b, i):
        navs = nav[None].copy()
        apply_feedback(navs[0], np.zeros(12), clock, dx, la)
        return model.predict_batch(i, navs, w_b - dx[9:12])[1][0]

    pts = MerweScaledSigmaPoints(n, alpha=0.6, beta=2.0, kappa=0.0)
    ukf = FUkf(dim_x=n, dim_z=6, dt=1.0, hx=hx, fx=fx, points=pts)
    ukf.P = motion.initial_covariance(sim.init)
    ukf.x = np.zeros(n)
    nav = np.array(sim.init.nav, float)
    prev = np.zeros(6)
    sensor = np.zeros(12)
    work = np.empty((4, n, n))
    scratch = np.zeros((n, n))
    t_imu = imu.time
    k = int(np.searchsorted(t_imu, sim.init.time + 1e-9))
    total, count = 0.0, 0
    perf = time.perf_counter
    for i in range(n_epochs):
        t_fix = sim.fixes.time[i]
        end = int(np.searchsorted(t_imu, t_fix + 1e-9))
        if end - k < substeps:
            k = end
            continue
        t0 = perf()
        nav0, prev0 = nav.copy(), prev.copy()
        dth, dv, dts = imu.dtheta[k:end], imu.dvel[k:end], imu.dt[k:end]
        scratch[:] = 0.0
        T = propagate_block(nav, prev, sensor, dth, dv, dts, scratch, motion.qc, la, tau, work, motion.qb)
        g = (np.arange(end - k) * substeps) // (end - k)
        gth = np.zeros((substeps, 3))
        gdv = np.zeros((substeps, 3))
        gdt = np.zeros(substeps)
        np.add.at(gth, g, dth)
        np.add.at(gdv, g, dv)
        np.add.at(gdt, g, dts)
        ref = nav0[None].copy()
        mechanize_batch(ref, prev0[None].copy(), sensor[None].copy(), gth, gdv, gdt)
        decay = np.ones(n - 9)
        f = np.where(np.isfinite(tau) & (tau > 0), np.exp(-T / np.where(tau > 0, tau, 1.0)), 1.0)
        decay[0:3], decay[3:6] = f[0], f[1]
        if n >= 21:
            decay[6:9], decay[9:12] = f[2], f[3]
        ukf.Q = work[2].copy()
        ukf.predict(dt=T, nav0=nav0, prev0=prev0, sensor0=sensor, gth=gth, gdv=gdv, gdt=gdt, ref=ref[0],
                    decay=decay)
        w_b = prev[0:3] / dts[-1]
        y, _, r = model.predict_batch(i, nav[None], w_b)
        ukf.update(y, R=np.diag(r), nav=nav, w_b=w_b, i=i)
        apply_feedback(nav, sensor, clock, ukf.x, la)
        ukf.x = np.zeros(n)
        total += perf() - t0
        count += 1
        k = end
    return total / count * 1e6, nav, count


def main():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 1, src)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    lay = get_layout(N_STATES)
    filters = {"ekf": ErrorStateEkf(lay, sim.imu_model), "ukf": UnscentedKalmanFilter(lay, sim.imu_model),
               "vb-aukf": VbAdaptiveUkf(lay, sim.imu_model, iterations=3, tolerance=0.0)}
    out, results = {}, {}
    for name, f in filters.items():
        f.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, f.layout)])    # warm up, compile
        out[f"{name}_us_per_epoch"], results[name] = engine_epoch_us(f, sim, lever)
    n_fp = 200
    filterpy_run(sim, lever, 5)                                              # warm up
    fp = [filterpy_run(sim, lever, n_fp) for _ in range(2)]
    out["filterpy_ukf_us_per_epoch"] = min(x[0] for x in fp)
    # check: filterpy's nominal after n_fp epochs against our UKF's at the same time
    ours = results["ukf"]
    t_end = sim.fixes.time[n_fp - 1]
    j = int(np.argmin(np.abs(ours.time - t_end)))
    from mixnav.geodesy.frames import ned_displacement
    out["filterpy_vs_ours_position_diff_m"] = float(np.linalg.norm(ned_displacement(fp[0][1][7:10],
                                                                                    ours.nav[j, 7:10])))
    out["ukf_over_ekf"] = out["ukf_us_per_epoch"] / out["ekf_us_per_epoch"]
    out["filterpy_over_ukf"] = out["filterpy_ukf_us_per_epoch"] / out["ukf_us_per_epoch"]
    out["vbaukf_over_ukf"] = out["vb-aukf_us_per_epoch"] / out["ukf_us_per_epoch"]
    meta = {"mixnav_version": __version__, "python": sys.version.split()[0], "machine": platform.machine(),
            "processor": platform.processor() or "unknown", "states": N_STATES, "imu_steps_per_epoch": 100,
            "rows_per_epoch": 6, "filterpy_epochs": n_fp}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "ukf.json").write_text(json.dumps({"meta": meta, "results": out}, indent=2) + "\n")
    lines = ["# UKF family: time per GNSS epoch (bench_ukf.py)", "",
             f"loose-demo, {N_STATES} states, one epoch = 100 IMU increments + 6 loose rows + feedback; "
             "mean over the run's GNSS epochs, best of 3 runs (filterpy: first 200 epochs, best of 2). "
             "Ratios from the same process.", "",
             "| what | value |", "|---|---|"]
    for k, v in out.items():
        lines.append(f"| {k} | {v:.4g} |")
    lines += ["", "Targets (issue 18): ukf_over_ekf <= 3, filterpy_over_ukf >= 5, vbaukf_over_ukf <= 1.5.", "",
              f"Machine: {meta['machine']}, Python {meta['python']}, mixnav {__version__}."]
    (RESULTS / "ukf.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
