"""The GMPF (paper P3) against the SIR particle filter, the DD2 filter and the EKF on loose-demo:
time per GNSS epoch and accuracy, from the same runs.

    python benchmarks/bench_gmpf.py            # writes benchmarks/results/gmpf_pf.{json,md}

One epoch = one 1 s propagation step (100 IMU increments) ending in a 6-row loose update
(position + velocity) and the feedback; 15 states; loose-demo, simulation seed 3 (as
tests/test_particle.py and tests/test_gmpf.py). Each filter runs the whole 600 s once
through the engine's step API; the wall time of every step that ends in a measurement
epoch is kept (mean and median reported: the machine is shared). The estimators'
``predict`` and ``update`` are timed apart, and for the GMPF the weighted-EM refit
(``fit_weighted_mixture``) inside the update. Accuracy: position RMS and mean position
NEES of the same run; the GMPF with 2000 particles also for filter seeds 1-2.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from mixnav import __version__
from mixnav.config import load_scenario
from mixnav.experiment.run import solution_table
from mixnav.filters import gmpf as gmpf_module
from mixnav.filters.dd2 import Dd2Filter
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.filters.gmpf import GaussianMixtureParticleFilter
from mixnav.filters.particle import ParticleFilter
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate

RESULTS = Path(__file__).resolve().parent / "results"


def timed_run(filt, sim, lever, seed=0):
    """One run through the step API: ``(result, per-epoch times [s], split {name: times})``."""
    eng = filt.engine([LooseGnss(sim.fixes, lever, filt.layout)], rng=seed)
    eng.start(sim.imu, sim.init)
    est = filt.estimator
    split = {"predict": [], "update": [], "em": []}
    for name in ("predict", "update"):
        f = getattr(est, name)

        def wrapped(*a, _f=f, _k=name):
            t0 = time.perf_counter()
            out = _f(*a)
            split[_k].append(time.perf_counter() - t0)
            return out
        setattr(est, name, wrapped)
    fit = gmpf_module.fit_weighted_mixture

    def fit_timed(*a, **k):
        t0 = time.perf_counter()
        out = fit(*a, **k)
        split["em"].append(time.perf_counter() - t0)
        return out
    gmpf_module.fit_weighted_mixture = fit_timed
    times = []
    try:
        while True:
            measured = eng._ti in eng._events
            t0 = time.perf_counter()
            if not eng.step():
                break
            if measured:
                times.append(time.perf_counter() - t0)
    finally:
        gmpf_module.fit_weighted_mixture = fit
    return eng.result(), np.array(times), split


def accuracy(result, truth):
    tab = solution_table(result, truth)
    pe = tab[["err_n_m", "err_e_m", "err_d_m"]].to_numpy()
    return float(np.sqrt((pe ** 2).sum(axis=1).mean())), float(tab["nees_pos"].mean())


def main():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    lay = get_layout(15)
    # warm every kernel (numba cache) on a short run first
    for f in (ErrorStateEkf(lay, sim.imu_model), Dd2Filter(lay, sim.imu_model),
              ParticleFilter(lay, sim.imu_model, particles=50),
              GaussianMixtureParticleFilter(lay, sim.imu_model, particles=50, components=2)):
        f.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, lay)], rng=0)
    configs = [("EKF", lambda: ErrorStateEkf(lay, sim.imu_model)),
               ("DD2", lambda: Dd2Filter(lay, sim.imu_model)),
               ("PF 2000", lambda: ParticleFilter(lay, sim.imu_model, particles=2000)),
               ("GMPF 2000 K=3", lambda: GaussianMixtureParticleFilter(lay, sim.imu_model, particles=2000,
                                                                       components=3)),
               ("GMPF 2000 K=3 em=3", lambda: GaussianMixtureParticleFilter(lay, sim.imu_model, particles=2000,
                                                                            components=3, em_iterations=3)),
               ("GMPF 2000 K=1", lambda: GaussianMixtureParticleFilter(lay, sim.imu_model, particles=2000,
                                                                       components=1)),
               ("GMPF 2000 K=3 iid", lambda: GaussianMixtureParticleFilter(lay, sim.imu_model, particles=2000,
                                                                           components=3, sampling="iid")),
               ("GMPF 300 K=3", lambda: GaussianMixtureParticleFilter(lay, sim.imu_model, particles=300,
                                                                      components=3))]
    rows = []
    for name, make in configs:
        f = make()
        r, t, split = timed_run(f, sim, lever)
        rms, nees = accuracy(r, sim.truth)
        c = f.estimator.counts
        row = dict(filter=name, seed=0, epoch_ms_mean=1e3 * float(t.mean()), epoch_ms_median=1e3 * float(np.median(t)),
                   predict_ms=1e3 * float(np.mean(split["predict"])),
                   update_ms=1e3 * float(np.mean(split["update"])) if split["update"] else 0.0,
                   em_ms=1e3 * float(np.mean(split["em"])) if split["em"] else 0.0,
                   pos_rms_m=rms, nees_pos=nees,
                   recoveries={k: v for k, v in c.items() if v})
        ess = getattr(f.estimator, "ess_history", None)
        row["median_ess"] = float(np.median(ess)) if ess else None
        rows.append(row)
        print(row, flush=True)
    seeds = []
    for seed in (1, 2):
        f = GaussianMixtureParticleFilter(lay, sim.imu_model, particles=2000, components=3)
        r = f.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, lay)], rng=seed)
        rms, nees = accuracy(r, sim.truth)
        seeds.append(dict(filter="GMPF 2000 K=3", seed=seed, pos_rms_m=rms, nees_pos=nees))
        print(seeds[-1], flush=True)
    out = {"rows": rows, "seeds": seeds, "machine": platform.machine(), "python": platform.python_version(),
           "mixnav": __version__}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "gmpf_pf.json").write_text(json.dumps(out, indent=1))
    ekf = rows[0]
    md = ["# GMPF vs PF vs DD2 vs EKF on loose-demo: time per GNSS epoch and accuracy (bench_gmpf.py)", "",
          "15 states; one epoch = a 1 s step (100 IMU increments) + 6 loose rows + feedback; one whole run "
          "(600 epochs) per filter through the step API, filter seed 0; the machine is shared (2 cores, other "
          "jobs), so the median is the steadier number. EM = the weighted-EM refit inside the GMPF update.", "",
          "| filter | epoch mean [ms] | median [ms] | / EKF (median) | predict [ms] | update [ms] | EM [ms] | "
          "pos RMS [m] | NEES pos | median ESS | recoveries |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ess = "" if r["median_ess"] is None else f"{r['median_ess']:.0f}"
        md.append(f"| {r['filter']} | {r['epoch_ms_mean']:.3g} | {r['epoch_ms_median']:.3g} | "
                  f"{r['epoch_ms_median'] / ekf['epoch_ms_median']:.3g} | {r['predict_ms']:.3g} | "
                  f"{r['update_ms']:.3g} | {r['em_ms']:.3g} | {r['pos_rms_m']:.3f} | {r['nees_pos']:.3g} | {ess} | "
                  f"{r['recoveries'] or ''} |")
    md += ["", "GMPF 2000 K=3 (matched draws), other filter seeds:", "", "| seed | pos RMS [m] | NEES pos |",
           "|---|---|---|"]
    for s in seeds:
        md.append(f"| {s['seed']} | {s['pos_rms_m']:.3f} | {s['nees_pos']:.3g} |")
    md += ["", f"Machine: {platform.machine()}, Python {platform.python_version()}, mixnav {__version__}.", ""]
    (RESULTS / "gmpf_pf.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
