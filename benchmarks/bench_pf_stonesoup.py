"""mixnav's SIR particle filter against Stone Soup's, side by side in one process.

    python benchmarks/bench_pf_stonesoup.py     # writes benchmarks/results/pf_stonesoup.{json,md}

Needs ``stonesoup`` (not a mixnav dependency: install it in a separate environment
with numpy, numba and scipy, and mixnav on PYTHONPATH); without it the script prints
why and exits 0.

The model both can run: 2-D constant velocity, state ``[x, vx, y, vy]`` (Stone Soup's
order), white-acceleration density ``q`` per axis, ``dt`` = 1 s, position fixes with
``sigma`` per axis; 5000 particles, prior ``N(0, P0)``, 100 epochs per run. Both filters
are plain SIR with the same policy: propagate every particle through the transition with
its own process noise, weigh by the Gaussian likelihood, normalise in log space,
resample systematically when the effective sample size falls below N/2, report the
weighted mean. mixnav runs its estimator without the engine
(:func:`mixnav.filters.particle.linear_gaussian_particles`: the engine's particle
filter mechanizes particles with the strapdown INS and maps them to full states by
the INS feedback map, which the constant-velocity layout does not have), serial
kernels (the default) and numba-parallel; roughening off (Stone Soup: no regulariser).

Per epoch each filter's predict and update (including its weighted mean) are timed;
the runs alternate (Stone Soup seed s, mixnav seed s, ...) so both share the machine's
load. Accuracy: position RMSE of each filter and of the Kalman filter (the optimum on
this model) over the same simulated runs: the speed ratio counts only if the RMSEs
agree.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

try:
    import stonesoup
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.particle import ParticlePredictor
    from stonesoup.resampler.particle import ESSResampler, SystematicResampler
    from stonesoup.types.array import StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import ParticleState
    from stonesoup.updater.particle import ParticleUpdater
except ImportError as e:  # pragma: no cover
    print(f"bench_pf_stonesoup: skipped, stonesoup is not importable ({e}); "
          "install it in a separate environment: pip install stonesoup numpy numba scipy")
    sys.exit(0)

import numba

from mixnav import __version__
from mixnav.filters.particle import linear_gaussian_particles

RESULTS = Path(__file__).resolve().parent / "results"
N = 5000
STEPS = 100
SEEDS = range(6)
DT = 1.0
Q_DENSITY = 0.5          # m^2/s^3 per axis
SIGMA = 5.0              # m per axis
P0 = np.diag([100.0, 4.0, 100.0, 4.0])


def model():
    q1 = Q_DENSITY * np.array([[DT ** 3 / 3, DT ** 2 / 2], [DT ** 2 / 2, DT]])
    F1 = np.array([[1.0, DT], [0.0, 1.0]])
    F = np.kron(np.eye(2), F1)
    Q = np.kron(np.eye(2), q1)
    H = np.zeros((2, 4))
    H[0, 0] = H[1, 2] = 1.0
    return F, Q, H, np.full(2, SIGMA ** 2)


def simulate(seed):
    F, Q, H, r = model()
    rng = np.random.default_rng(1000 + seed)
    x = rng.multivariate_normal(np.zeros(4), P0)
    xs, ys = [], []
    for _ in range(STEPS):
        x = F @ x + rng.multivariate_normal(np.zeros(4), Q)
        xs.append(x)
        ys.append(H @ x + rng.standard_normal(2) * np.sqrt(r))
    return np.array(xs), np.array(ys)


def kalman(ys):
    F, Q, H, r = model()
    x, P = np.zeros(4), P0.copy()
    out = []
    for y in ys:
        x, P = F @ x, F @ P @ F.T + Q
        S = H @ P @ H.T + np.diag(r)
        K = np.linalg.solve(S, H @ P).T
        x, P = x + K @ (y - H @ x), P - K @ S @ K.T
        out.append(x)
    return np.array(out)


def run_mixnav(ys, seed, parallel):
    F, Q, H, r = model()
    est = linear_gaussian_particles(P0, N, np.random.default_rng(seed), resample_threshold=0.5, roughening=0.0,
                                    parallel=parallel)
    tp, tu, tc, xs = [], [], [], []
    for y in ys:
        c0 = time.process_time()
        t0 = time.perf_counter()
        est.propagate_linear_noise(F, Q)
        t1 = time.perf_counter()
        corr = est.weigh(y, est.D @ H.T, r)
        t2 = time.perf_counter()
        tc.append(time.process_time() - c0)
        tp.append(t1 - t0)
        tu.append(t2 - t1)
        xs.append(corr.dx.copy())
    return np.array(xs), np.array(tp), np.array(tu), np.array(tc), est.counts["pf_resampled"]


def run_stonesoup(ys, seed):
    F, Q, H, r = model()
    np.random.seed(seed)      # Stone Soup draws from numpy's global stream
    trans = CombinedLinearGaussianTransitionModel([ConstantVelocity(Q_DENSITY), ConstantVelocity(Q_DENSITY)])
    meas = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag(r))
    predictor = ParticlePredictor(transition_model=trans)
    updater = ParticleUpdater(measurement_model=meas,
                              resampler=ESSResampler(threshold=N / 2, resampler=SystematicResampler()))
    t = datetime.datetime(2026, 1, 1)
    samples = np.random.multivariate_normal(np.zeros(4), P0, size=N)
    state = ParticleState(StateVectors(samples.T), log_weight=np.full(N, np.log(1.0 / N)), timestamp=t)
    tp, tu, tc, xs = [], [], [], []
    resampled = 0
    for y in ys:
        t += datetime.timedelta(seconds=DT)
        c0 = time.process_time()
        t0 = time.perf_counter()
        pred = predictor.predict(state, timestamp=t)
        t1 = time.perf_counter()
        post = updater.update(SingleHypothesis(pred, Detection(y.reshape(2, 1), timestamp=t,
                                                               measurement_model=meas)))
        mean = np.asarray(post.mean, dtype=float).ravel()
        t2 = time.perf_counter()
        tc.append(time.process_time() - c0)
        # the weighted mean before a resampling (as mixnav's correction); after one the
        # weights are uniform, and the mean of the resampled cloud is the same in expectation
        resampled += bool(np.all(post.log_weight == post.log_weight[0]))
        tp.append(t1 - t0)
        tu.append(t2 - t1)
        xs.append(mean)
        state = post
    return np.array(xs), np.array(tp), np.array(tu), np.array(tc), resampled


def pos_rmse(xs, truth):
    return float(np.sqrt(np.mean((xs[:, 0] - truth[:, 0]) ** 2 + (xs[:, 2] - truth[:, 2]) ** 2)))


def main():
    threads = numba.get_num_threads()
    # warm: compile/load mixnav's kernels, import Stone Soup's lazily loaded parts
    truth, ys = simulate(99)
    run_mixnav(ys[:3], 0, False)
    run_mixnav(ys[:3], 0, True)
    run_stonesoup(ys[:3], 0)
    acc = {"stonesoup": [], "mixnav": [], "mixnav_parallel": [], "kalman": []}
    times = {k: {"predict": [], "update": [], "cpu": []} for k in ("stonesoup", "mixnav", "mixnav_parallel")}
    resampled = {k: 0 for k in times}
    load = []
    runs = [(seed, simulate(seed)) for seed in SEEDS]
    for seed, (truth, ys) in runs:
        acc["kalman"].append(pos_rmse(kalman(ys), truth))
    # the pairs first, alternating; the parallel runs after them, so that numba's worker
    # threads (which may spin after a parallel region) cannot slow either side of a pair
    order = [(name, seed, truth, ys) for seed, (truth, ys) in runs for name in ("stonesoup", "mixnav")]
    order += [("mixnav_parallel", seed, truth, ys) for seed, (truth, ys) in runs]
    for name, seed, truth, ys in order:
        load.append(os.getloadavg()[0])
        if name == "stonesoup":
            xs, tp, tu, tc, nres = run_stonesoup(ys, seed)
        else:
            xs, tp, tu, tc, nres = run_mixnav(ys, seed, name == "mixnav_parallel")
        acc[name].append(pos_rmse(xs, truth))
        times[name]["predict"].append(tp)
        times[name]["update"].append(tu)
        times[name]["cpu"].append(tc)
        resampled[name] += nres
    out = {"particles": N, "epochs_per_run": STEPS, "runs": len(SEEDS), "numba_threads": threads,
           "load_average_1min": [min(load), max(load)], "stonesoup_version": stonesoup.__version__}
    for name, tt in times.items():
        p = np.concatenate(tt["predict"]) * 1e6
        u = np.concatenate(tt["update"]) * 1e6
        s = p + u
        c = np.concatenate(tt["cpu"]) * 1e6
        out[name] = {"predict_us_median": float(np.median(p)), "update_us_median": float(np.median(u)),
                     "cpu_us_median": float(np.median(c)), "cpu_us_mean": float(np.mean(c)),
                     "step_us_median": float(np.median(s)), "step_us_mean": float(np.mean(s)),
                     "step_us_p10": float(np.percentile(s, 10)),
                     "pos_rmse_m": float(np.sqrt(np.mean(np.square(acc[name])))),
                     "pos_rmse_per_run_m": acc[name], "resampled": resampled[name]}
    out["kalman_pos_rmse_m"] = float(np.sqrt(np.mean(np.square(acc["kalman"]))))
    ss = out["stonesoup"]
    for name in ("mixnav", "mixnav_parallel"):
        m = out[name]
        out[f"speedup_{name}"] = {k: ss[k] / m[k] for k in ("step_us_median", "step_us_mean", "predict_us_median",
                                                          "update_us_median", "cpu_us_median", "cpu_us_mean")}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "pf_stonesoup.json").write_text(json.dumps(out, indent=1))
    md = ["# Particle filter: mixnav against Stone Soup (bench_pf_stonesoup.py)", "",
          f"2-D constant velocity (state [x, vx, y, vy], q = {Q_DENSITY} m^2/s^3 per axis, dt = {DT} s), "
          f"position fixes sigma {SIGMA} m per axis, prior N(0, diag(100, 4, 100, 4)); "
          f"**{N} particles** on both sides, {STEPS} epochs x {len(SEEDS)} runs (the same simulated runs), "
          "plain SIR on both: systematic resampling when ESS < N/2, no roughening/regulariser, weighted mean "
          "as the estimate. One process, runs alternating (Stone Soup, mixnav serial per seed; the "
          "numba-parallel runs after all pairs); wall time per step (perf_counter) and the process's CPU "
          "time (process_time: all its threads, not the time it waited for a core); "
          f"numba threads {threads}; 1-min load average during the runs "
          f"{min(load):.1f}-{max(load):.1f} (a 2-core machine shared with other jobs).", "",
          "mixnav side: `linear_gaussian_particles` (the estimator's own compiled propagation, weights, "
          "resampling and moments, without the engine: the engine's particle filter mechanizes particles "
          "through the strapdown INS and its feedback map, which the constant-velocity layout does not have).",
          "", "Per epoch (predict + update incl. the weighted mean), microseconds:", "",
          "| filter | predict (median) | update (median) | step (median) | step (mean) | step (p10) | "
          "CPU per step (median / mean) | pos RMSE [m] | resamplings |", "|---|---|---|---|---|---|---|---|---|"]
    for name in ("stonesoup", "mixnav", "mixnav_parallel"):
        r = out[name]
        md.append(f"| {name} | {r['predict_us_median']:.0f} | {r['update_us_median']:.0f} | "
                  f"{r['step_us_median']:.0f} | {r['step_us_mean']:.0f} | {r['step_us_p10']:.0f} | "
                  f"{r['cpu_us_median']:.0f} / {r['cpu_us_mean']:.0f} | {r['pos_rmse_m']:.3f} | {r['resampled']} |")
    md += ["", f"Kalman filter (optimal here): position RMSE {out['kalman_pos_rmse_m']:.3f} m.", "",
           "Speed-up (Stone Soup time / mixnav time, same process):", "",
           "| mixnav | step (median) | step (mean) | predict | update | CPU (median) | CPU (mean) |",
           "|---|---|---|---|---|---|---|"]
    for name in ("mixnav", "mixnav_parallel"):
        r = out[f"speedup_{name}"]
        md.append(f"| {name} | {r['step_us_median']:.1f} x | {r['step_us_mean']:.1f} x | "
                  f"{r['predict_us_median']:.1f} x | {r['update_us_median']:.1f} x | {r['cpu_us_median']:.1f} x | "
                  f"{r['cpu_us_mean']:.1f} x |")
    md += ["", "RMSE per run [m] (Stone Soup / mixnav / Kalman): " + "; ".join(
        f"{a:.2f} / {b:.2f} / {c:.2f}" for a, b, c in zip(acc["stonesoup"], acc["mixnav"], acc["kalman"])), "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__}, Stone Soup {stonesoup.__version__}, "
        f"mixnav {__version__}.", ""]
    (RESULTS / "pf_stonesoup.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
