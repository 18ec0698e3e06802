"""The SIR particle filter against the EKF and the UKF on loose-demo: time per GNSS epoch
and accuracy, in one run; the speed targets of issue 19 at 5000 particles.

    python benchmarks/bench_pf.py            # writes benchmarks/results/pf.{json,md}

One epoch = one 1 s propagation step (100 IMU increments) ending in a 6-row loose
update (position + velocity) and the feedback; 15 states; mean over the run's GNSS
epochs, best of 2 runs, with the engine's step API (as bench_ukf.py). For the PF the
propagation (all particles mechanized in one compiled call, 4 merged sub-intervals,
process noise) and the update (particles as full states, predict_batch, weights,
resampling, moments) are also timed apart, and the update split into epochs with and
without a resampling; the 5000-particle run is repeated with the generic update path
(full states + predict_batch, ``fused=False``) side by side.

Update split (5000 particles, ``update_split``): the estimator's state captured before
12 loose-demo epochs, restored before each timed update, so every variant (resampling
forced or off, Liu-West jitter h = 0.9 or none, fused or generic) sees the same inputs;
then each stage of the fused update timed alone on those epochs (with the pass over the
resampled cloud that stop 31 dropped: the estimate is the weighted moments before the
resampling).

IMU step (5000 particles, 15 states, kernels called directly on particles spread as
on loose-demo): (a) one mechanization sub-interval of the whole array (5000 particles
as full states + the reference, ``pf_mechanize``: the reference in RECORD mode, the
particles in NEAR mode, as ``pf_step``), (b) one whole propagation call over a block of one
IMU increment (feedback, one mechanization, difference, noise, and the draw of the
5000 x 15 normals): the cost per IMU increment if the filter stepped at every one.
Serial kernels and numba-parallel ones on 1 and 2 threads; the parallel ones last
(their worker threads must not slow the serial timings).

Memory: the peak of Python-traced allocations (tracemalloc: numpy's arrays included)
over a 5000-particle run of loose-demo's first 120 s, and the process's max RSS.

Accuracy: position RMS over the run against the EKF's, mean position NEES, resamplings
and degeneracies, for 500, 1000, 2000 and 5000 particles (roughening 0.9, threshold 0.5),
filter seeds 0-2 on the one simulated run (simulation seed 3, as tests/test_particle.py).
"""

from __future__ import annotations

import json
import os
import platform
import resource
import time
import tracemalloc
from pathlib import Path

import numpy as np

from mixnav import __version__
from mixnav.config import load_scenario
from mixnav.engine.protocols import Epoch
from mixnav.experiment.run import solution_table
from mixnav.filters.ekf import ErrorStateEkf
import numba

from mixnav.filters import _pf_kernels as K
from mixnav.ins import _particle_kernels as PK
from mixnav.filters.particle import ParticleEstimator, ParticleFilter
from mixnav.filters.ukf import UnscentedKalmanFilter
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate

RESULTS = Path(__file__).resolve().parent / "results"


def engine_epoch_us(filt, sim, lever, repeats=2, fused=True):
    """Mean wall time per GNSS epoch [us] (best of ``repeats`` runs) and, for the PF, its
    predict / update means and the update's mean over epochs with / without a resampling
    (``fused=False``: the PF's generic update path, for the side-by-side)."""
    best, parts = np.inf, None
    for _ in range(repeats):
        eng = filt.engine([LooseGnss(sim.fixes, lever, filt.layout)])
        eng.start(sim.imu, sim.init)
        est = eng.estimator if hasattr(eng, "estimator") else filt.estimator
        if isinstance(est, ParticleEstimator):
            est.fused = fused
        split = {"predict": [], "update": [], "resampled": [], "predict_cpu": [], "update_cpu": []}
        if isinstance(est, ParticleEstimator):
            for name in ("predict", "update"):
                f = getattr(est, name)

                def timed(*a, _f=f, _k=name):
                    n0 = est.counts["pf_resampled"]
                    c0 = time.process_time()
                    t0 = time.perf_counter()
                    out = _f(*a)
                    split[_k].append(time.perf_counter() - t0)
                    split[_k + "_cpu"].append(time.process_time() - c0)
                    if _k == "update":
                        split["resampled"].append(est.counts["pf_resampled"] > n0)
                    return out
                setattr(est, name, timed)
        times = []
        while True:
            measured = eng._ti in eng._events
            t0 = time.perf_counter()
            if not eng.step():
                break
            if measured:
                times.append(time.perf_counter() - t0)
        t = float(np.mean(times)) * 1e6
        if t < best:
            best = t
            parts = {k: float(np.mean(v)) * 1e6 for k, v in split.items() if v and k != "resampled"}
            if split["update"]:
                u, r = np.array(split["update"]), np.array(split["resampled"])
                parts["update_resampled"] = float(u[r].mean()) * 1e6 if r.any() else float("nan")
                parts["update_not_resampled"] = float(u[~r].mean()) * 1e6 if (~r).any() else float("nan")
                parts["resampled_fraction"] = float(r.mean())
    return best, parts


def imu_step_us(N=5000, repeats=40):
    """Median and best wall time [us] of (a) one mechanization sub-interval of N particles +
    the reference and (b) one propagation call over a one-increment block (with the draw of
    the normals), for the serial kernels and the parallel ones on 1 and 2 threads."""
    lay = get_layout(15)
    n = lay.n
    rng = np.random.default_rng(0)
    nav0 = np.array([0.9, 0.1, 0.2, 0.3, 10.0, 2.0, -0.1, 0.6, 0.2, 100.0])
    nav0[:4] /= np.linalg.norm(nav0[:4])
    D = rng.standard_normal((N, n)) * np.r_[[1e-3] * 3, [0.1] * 3, [2.0] * 3, [1e-4] * 3, [1e-2] * 3]
    SQT = np.eye(n) * 1e-3
    dth = rng.standard_normal((1, 3)) * 1e-3
    dv = np.array([[0.0, 0.0, -0.098]])
    dt = np.full(1, 0.01)
    la, tau = lay.as_array(), np.array([3600.0, 3600.0, np.inf, np.inf])
    navs, prevs, sensors = np.empty((N + 1, 10)), np.empty((N + 1, 6)), np.empty((N + 1, 12))
    scr, g, Z, Dn = np.empty((N + 1, PK.SCRATCH)), np.empty((4, 7)), np.empty((N, n)), np.empty((N, n))
    navs0 = np.empty((N + 1, 10))       # the particles as full states, the reference last (as pf_step)
    PK.pf_member_navs_serial(nav0, D, lay.as_array(), navs0, sensors, scr)
    navs0[N] = nav0
    out = {}
    old = numba.get_num_threads()
    for label, mech, step, threads in (("serial", PK.pf_mechanize_serial, PK.pf_step_serial, old),
                                       ("parallel_1_thread", PK.pf_mechanize, PK.pf_step, 1),
                                       ("parallel_2_threads", PK.pf_mechanize, PK.pf_step, min(2, old))):
        numba.set_num_threads(threads)
        PK.merge_block_into(dth, dv, dt, 1, g[:, 0:3], g[:, 3:6], g[:, 6])

        def one_step():
            rng.standard_normal(out=Z)
            step(nav0, np.zeros(6), np.zeros(12), D, SQT, Z, dth, dv, dt, 1, la, tau, 0.01, navs, prevs, sensors,
                 scr, g[:, 0:3], g[:, 3:6], g[:, 6], np.empty(4), Dn)

        one_step()
        tm, ts, cm, cs = [], [], [], []
        for _ in range(repeats):
            navs[:] = navs0
            prevs[:] = 0.0
            sensors[:] = 0.0
            c0 = time.process_time()
            t0 = time.perf_counter()
            mech(navs, prevs, sensors, scr, g[:, 0:3], g[:, 3:6], g[:, 6], 1)
            t1 = time.perf_counter()
            c1 = time.process_time()
            one_step()
            t2 = time.perf_counter()
            c2 = time.process_time()
            tm.append(t1 - t0)
            ts.append(t2 - t1)
            cm.append(c1 - c0)
            cs.append(c2 - c1)
        out[label] = {"mechanize_substep_us_median": float(np.median(tm)) * 1e6,
                      "mechanize_substep_us_best": float(np.min(tm)) * 1e6,
                      "propagate_one_increment_us_median": float(np.median(ts)) * 1e6,
                      "propagate_one_increment_us_best": float(np.min(ts)) * 1e6,
                      "mechanize_substep_cpu_us_median": float(np.median(cm)) * 1e6,
                      "propagate_one_increment_cpu_us_median": float(np.median(cs)) * 1e6}
    numba.set_num_threads(old)
    return out


def update_split(sim, lever, N=5000, n_epochs=12, seconds=360.0, repeats=15):
    """One GNSS update of N particles on captured loose-demo epochs, with and without a
    resampling and with and without the Liu-West jitter, fused and generic, on the same
    inputs: the estimator's state (particles, weights) is captured before ``n_epochs``
    epochs spread over the first ``seconds`` of a default run, restored before each timed
    ``update`` call; the resampling is forced (threshold 1) or kept off (threshold
    1e-9). Medians over epochs x ``repeats`` [us]: wall, wall best, process CPU. Then
    the stages of the fused update timed alone on the same epochs (kernel, systematic
    resampling, Cholesky, the normals, the jitter product, and the moments of the
    resampled cloud, which the engine's recording recomputed until stop 31)."""
    from mixnav.linalg import cholesky_lower
    lay = get_layout(15)
    f = ParticleFilter(lay, sim.imu_model, particles=N)
    eng = f.engine([LooseGnss(sim.fixes, lever, lay)], rng=0)
    eng.start(sim.imu, sim.init)
    est = f.estimator
    every = seconds / n_epochs
    caps, orig = [], est.update

    def capture(epoch):
        if epoch.time >= sim.init.time + every * (len(caps) + 1) and len(caps) < n_epochs:
            frozen = Epoch(epoch.time, epoch.index, epoch.model, epoch.nav.copy(), np.array(epoch.w_b, dtype=float),
                           np.array(epoch.clock, dtype=float), epoch.memory, epoch.aux)   # the engine's arrays move on
            caps.append((frozen, est.D.copy(), est.logw.copy(), est.w.copy()))
        return orig(epoch)
    est.update = capture
    while len(caps) < n_epochs and eng.step():
        pass
    est.update = orig

    def restore(c):
        est.D[:] = c[1]
        est.logw[:] = c[2]
        est.w[:] = c[3]

    out = {}
    for fused in (True, False):
        for resample in (False, True):
            for h in (0.9, 0.0):
                est.fused, est.roughening = fused, h
                est.resample_threshold = 1.0 if resample else 1e-9
                wall, cpu = [], []
                for c in caps:
                    for _ in range(repeats):
                        restore(c)
                        c0, t0 = time.process_time(), time.perf_counter()
                        orig(c[0])
                        wall.append(time.perf_counter() - t0)
                        cpu.append(time.process_time() - c0)
                key = f"{'fused' if fused else 'generic'}_{'resampled' if resample else 'not_resampled'}_h{h:g}"
                out[key] = {"wall_us_median": float(np.median(wall)) * 1e6, "wall_us_best": float(np.min(wall)) * 1e6,
                            "cpu_us_median": float(np.median(cpu)) * 1e6}
    est.fused, est.roughening, est.resample_threshold = True, 0.9, 0.5
    n = lay.n
    la = lay.as_array()
    ym, Pyy, YT, work = np.empty(6), np.empty((6, 6)), np.empty((6, N)), np.empty((n + 1, N))
    x, P, L, ZT, Dn = np.empty(n), np.empty((n, n)), np.empty((n, n)), np.empty((n, N)), np.empty((N, n))
    yp, pa, part = np.empty((K.CHUNKS, 44)), np.empty((K.CHUNKS, 2 + n)), np.empty((K.CHUNKS, n + n * n))
    logw, w, idx = np.empty(N), np.empty(N), np.empty(N, dtype=np.int64)
    rng = np.random.default_rng(0)
    stages = {k: [] for k in ("kernel", "systematic", "cholesky", "normals", "jitter_product", "copy_without_jitter",
                              "cloud_moments_not_recomputed", "jitter_with_its_normals")}
    for c in caps:
        ep = c[0]
        wb = np.asarray(ep.w_b, dtype=float)
        if hasattr(ep.model, "member_update"):     # issue 33: the model's fused update, through the seam
            u = ep.model.member_update(ep.index, lay)
            kernel = (lambda c=c, ep=ep, wb=wb, u=u: u.kernel(c[1], ep.nav, wb, c[2], c[3], 1e30, YT, logw, w, ym, Pyy,
                                                              x, P, yp, pa, part, work, *u.constants))
        else:                                       # before: the motion model's kernel, the model's fix row
            fix, lev = ep.model.batch_fix(ep.index)
            kernel = (lambda c=c, ep=ep, wb=wb, fix=fix, lev=lev: PK.pf_loose_update_serial(
                c[1], la, ep.nav, wb, lev, fix, c[2], c[3], 1e30, YT, logw, w, ym, Pyy, x, P, yp, pa, part, work))
        calls = {"kernel": kernel,
                 "systematic": lambda: K.pf_systematic(w, 0.5, idx),
                 "cholesky": lambda: cholesky_lower(P, L),
                 "normals": lambda: rng.standard_normal(out=ZT),
                 "jitter_product": lambda: K.pf_jitter_serial(c[1], idx, 0.43, 0.9, x, L, ZT, Dn),
                 "copy_without_jitter": lambda: K.pf_jitter_serial(c[1], idx, 1.0, 0.0, x, L, ZT, Dn),
                 "cloud_moments_not_recomputed": lambda: K.pf_moments_serial(Dn, w, x, P, part)}
        if hasattr(K, "pf_jitter_drawn_serial"):     # issue 33: the normals drawn in the jitter kernel
            seeds = rng.integers(0, 2 ** 64, size=K.CHUNKS, dtype=np.uint64)
            calls["jitter_with_its_normals"] = lambda: K.pf_jitter_drawn_serial(c[1], idx, 0.43, 0.9, x, L, seeds,
                                                                                 ZT, Dn)
        for k, fn in calls.items():
            for _ in range(repeats):
                t0 = time.perf_counter()
                fn()
                stages[k].append(time.perf_counter() - t0)
    out["stages"] = {k: {"wall_us_median": float(np.median(v)) * 1e6, "wall_us_best": float(np.min(v)) * 1e6}
                     for k, v in stages.items() if v}
    out["epochs"] = len(caps)
    out["median_ess_fraction"] = float(np.median([1.0 / np.dot(c[3], c[3]) for c in caps])) / N
    return out


def peak_memory(sim, lever, N=5000, seconds=120.0):
    """Peak traced allocation [MiB] over a run of the first ``seconds`` of loose-demo with
    N particles (engine, estimator, result), the particle state's own size, max RSS."""
    lay = get_layout(15)
    f = ParticleFilter(lay, sim.imu_model, particles=N)
    tracemalloc.start()
    eng = f.engine([LooseGnss(sim.fixes, lever, lay)], rng=0)
    eng.start(sim.imu, sim.init)
    t_end = sim.init.time + seconds
    while eng._ti < eng._n_events and eng._times[eng._ti] <= t_end:
        eng.step()
    cur, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    est = f.estimator
    state = (est.D.nbytes + est.logw.nbytes + est.w.nbytes) / 2 ** 20
    arrays = sum(a.nbytes for a in vars(est).values() if isinstance(a, np.ndarray)) / 2 ** 20
    return {"particles": N, "states": lay.n, "traced_peak_mib": peak / 2 ** 20, "traced_current_mib": cur / 2 ** 20,
            "particle_state_mib": state, "estimator_arrays_mib": arrays,
            "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    lay = get_layout(15)
    out = {}
    ekf = ErrorStateEkf(lay, sim.imu_model)
    ekf.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, lay)])      # warm
    out["ekf_us_per_epoch"], _ = engine_epoch_us(ekf, sim, lever)
    ukf = UnscentedKalmanFilter(lay, sim.imu_model)
    ukf.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, lay)])
    out["ukf_us_per_epoch"], _ = engine_epoch_us(ukf, sim, lever)
    out["load_average_1min_start"] = os.getloadavg()[0]
    out["numba_threads"] = numba.get_num_threads()
    for N in (500, 2000, 5000):
        pf = ParticleFilter(lay, sim.imu_model, particles=N)
        t, parts = engine_epoch_us(pf, sim, lever)
        out[f"pf{N}_us_per_epoch"] = t
        for k, v in parts.items():
            out[f"pf{N}_{k}" + ("" if k == "resampled_fraction" else "_us")] = v
        out[f"pf{N}_over_ekf"] = t / out["ekf_us_per_epoch"]
        out[f"pf{N}_over_ukf"] = t / out["ukf_us_per_epoch"]
    pf = ParticleFilter(lay, sim.imu_model, particles=5000)
    t, parts = engine_epoch_us(pf, sim, lever, fused=False)
    out["pf5000_generic_us_per_epoch"] = t
    for k, v in parts.items():
        out["pf5000_generic_" + k + ("" if k == "resampled_fraction" else "_us")] = v
    out["update_split_5000"] = update_split(sim, lever)
    out["memory"] = peak_memory(sim, lever)
    # the parallel kernels last: their worker threads must not slow the serial timings
    pf = ParticleFilter(lay, sim.imu_model, particles=5000, parallel=True)
    pf.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, lay)])     # compile / load
    for threads in (1, 2):
        numba.set_num_threads(threads)
        t, parts = engine_epoch_us(pf, sim, lever)
        out[f"pf5000_parallel_{threads}thr_us_per_epoch"] = t
        out[f"pf5000_parallel_{threads}thr_predict_us"] = parts["predict"]
        out[f"pf5000_parallel_{threads}thr_update_us"] = parts["update"]
    numba.set_num_threads(out["numba_threads"])
    out["imu_step_5000"] = imu_step_us()
    out["load_average_1min_end"] = os.getloadavg()[0]

    def accuracy(filt, seed=0):
        r = filt.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, lay)], rng=seed)
        try:
            tab = solution_table(r, sim.truth)
        except np.linalg.LinAlgError:   # a collapsed cloud: singular position covariance
            r.pv_cov[:] += np.eye(6) * 1e-12
            tab = solution_table(r, sim.truth)
        pe = tab[["err_n_m", "err_e_m", "err_d_m"]].to_numpy()
        return float(np.sqrt((pe ** 2).sum(axis=1).mean())), float(tab["nees_pos"].mean())

    e_rms, e_nees = accuracy(ErrorStateEkf(lay, sim.imu_model))
    out["ekf_pos_rms_m"], out["ekf_nees_pos"] = e_rms, e_nees
    rows = []
    for N in (500, 1000, 2000, 5000):
        for seed in (0, 1, 2):
            pf = ParticleFilter(lay, sim.imu_model, particles=N)
            rms, nees = accuracy(pf, seed)
            c = pf.estimator.counts
            rows.append(dict(particles=N, seed=seed, pos_rms_m=rms, over_ekf=rms / e_rms, nees_pos=nees,
                             resampled=c["pf_resampled"], degenerate=c["pf_degenerate"],
                             median_ess=float(np.median(pf.estimator.ess_history))))
    out["accuracy"] = rows
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "pf.json").write_text(json.dumps(out, indent=1))
    md = ["# Particle filter: time per GNSS epoch and accuracy (bench_pf.py)", "",
          "loose-demo, 15 states, one epoch = 100 IMU increments + 6 loose rows + feedback; mean over the "
          "run's GNSS epochs, best of 2 runs; same process. Serial kernels unless named parallel. "
          f"1-min load average {out['load_average_1min_start']:.1f} at the start, "
          f"{out['load_average_1min_end']:.1f} at the end (2 cores shared with other jobs: wall times "
          "are inflated by the time spent waiting for a core).", "", "| what | value |", "|---|---|"]
    for k, v in out.items():
        if not isinstance(v, (dict, list)):
            md.append(f"| {k} | {v:.4g} |")
    im, us = out["imu_step_5000"], out["update_split_5000"]
    md += ["", "Against issue 19's targets (5000 particles x 15 states; wall medians, us):", "",
           "| target | measured |", "|---|---|",
           f"| one IMU step <= 2000 (one mechanization sub-interval of the array) | serial "
           f"{im['serial']['mechanize_substep_us_median']:.0f}, 2 threads "
           f"{im['parallel_2_threads']['mechanize_substep_us_median']:.0f} |",
           f"| one GNSS update <= 1000 (weights, ESS, NIS, mean, covariance) | "
           f"{us['fused_not_resampled_h0.9']['wall_us_median']:.0f} |",
           f"| the same epoch with a resampling and the Liu-West jitter (the ESS asks for it at "
           f"{out['pf5000_resampled_fraction']:.0%} of loose-demo's epochs) | "
           f"{us['fused_resampled_h0.9']['wall_us_median']:.0f}"
           + (f", of which the jitter with its 75000 normals drawn in the kernel "
              f"{us['stages']['jitter_with_its_normals']['wall_us_median']:.0f} (numpy would take "
              f"{us['stages']['normals']['wall_us_median']:.0f} for the normals alone) |"
              if "jitter_with_its_normals" in us["stages"] else
              f", of which drawing the 75000 normals {us['stages']['normals']['wall_us_median']:.0f} |"),
           f"| mean per GNSS epoch in the engine run, resamplings included (wall / process CPU) | "
           f"{out['pf5000_update_us']:.0f} / {out['pf5000_update_cpu_us']:.0f} |"]
    md += ["", "IMU step, 5000 particles x 15 states (us; wall median / wall best of 40 / process CPU median, "
           "the CPU time of all the process's threads):", "",
           "| kernels | one mechanization sub-interval (5001 states) | propagation over one increment "
           "(feedback, mechanization, difference, noise incl. drawing 75000 normals) |", "|---|---|---|"]
    for label, r in out["imu_step_5000"].items():
        md.append(f"| {label} | {r['mechanize_substep_us_median']:.0f} / {r['mechanize_substep_us_best']:.0f} / "
                  f"{r['mechanize_substep_cpu_us_median']:.0f} | {r['propagate_one_increment_us_median']:.0f} / "
                  f"{r['propagate_one_increment_us_best']:.0f} / {r['propagate_one_increment_cpu_us_median']:.0f} |")
    us = out["update_split_5000"]
    md += ["", f"One GNSS update of 5000 particles x 15 states, the same inputs for every variant: the "
           f"estimator's state captured before {us['epochs']} loose-demo epochs (6 rows; median ESS "
           f"{us['median_ess_fraction']:.2f} N before them), restored before each call; resampling forced "
           "(threshold 1) or off (threshold 1e-9); h the Liu-West jitter (0.9 the default, 0 none). Serial "
           "kernels. us: wall median / wall best / process CPU median.", "",
           "| epoch | h | fused (pf_loose_update) | generic (member states + predict_batch) |", "|---|---|---|---|"]
    for res in ("not_resampled", "resampled"):
        for h in ("0.9", "0"):
            a, b = us[f"fused_{res}_h{h}"], us[f"generic_{res}_h{h}"]
            md.append(f"| {res.replace('_', ' ')} | {h} | {a['wall_us_median']:.0f} / {a['wall_us_best']:.0f} / "
                      f"{a['cpu_us_median']:.0f} | {b['wall_us_median']:.0f} / {b['wall_us_best']:.0f} / "
                      f"{b['cpu_us_median']:.0f} |")
    md += ["", "Stages of the fused update, each timed alone on the same epochs (us, wall median / best):", "",
           "| stage | us |", "|---|---|"]
    for k, v in us["stages"].items():
        md.append(f"| {k} | {v['wall_us_median']:.0f} / {v['wall_us_best']:.0f} |")
    mem = out["memory"]
    md += ["", f"Memory, {mem['particles']} particles x {mem['states']} states, loose-demo first 120 s: particle "
           f"state (D, log-weights, weights) {mem['particle_state_mib']:.2f} MiB, all the estimator's arrays "
           f"{mem['estimator_arrays_mib']:.2f} MiB, peak of traced allocations during the run "
           f"{mem['traced_peak_mib']:.1f} MiB (engine, estimator, recorded result), process max RSS "
           f"{mem['max_rss_mib']:.0f} MiB (Python, numpy, numba/LLVM, the simulated data)."]
    md += ["", f"EKF: position RMS {e_rms:.3f} m, mean position NEES {e_nees:.2f}.", "",
           "| particles | seed | pos RMS [m] | / EKF | NEES pos | resampled (of 600) | degenerate | median ESS |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['particles']} | {r['seed']} | {r['pos_rms_m']:.3f} | {r['over_ekf']:.2f} | "
                  f"{r['nees_pos']:.3g} | {r['resampled']} | {r['degenerate']} | {r['median_ess']:.0f} |")
    md += ["", f"Machine: {platform.machine()}, Python {platform.python_version()}, mixnav {__version__}.", ""]
    (RESULTS / "pf.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
