"""The SIR particle filter against the EKF and the UKF on loose-demo: time per GNSS epoch
and accuracy, in one run.

    python benchmarks/bench_pf.py            # writes benchmarks/results/pf.{json,md}

One epoch = one 1 s propagation step (100 IMU increments) ending in a 6-row loose
update (position + velocity) and the feedback; 15 states; mean over the run's GNSS
epochs, best of 2 runs, with the engine's step API (as bench_ukf.py). For the PF the
propagation (all particles mechanized in one compiled call, 4 merged sub-intervals,
process noise) and the update (particles as full states, predict_batch, weights,
resampling, moments) are also timed apart.

Accuracy: position RMS over the run against the EKF's, mean position NEES, resamplings
and degeneracies, for 500, 1000 and 2000 particles (roughening 0.9, threshold 0.5),
filter seeds 0-2 on the one simulated run (simulation seed 3, as tests/test_particle.py).
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
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.filters.particle import ParticleEstimator, ParticleFilter
from mixnav.filters.ukf import UnscentedKalmanFilter
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate

RESULTS = Path(__file__).resolve().parent / "results"


def engine_epoch_us(filt, sim, lever, repeats=2):
    best, parts = np.inf, None
    for _ in range(repeats):
        eng = filt.engine([LooseGnss(sim.fixes, lever, filt.layout)])
        eng.start(sim.imu, sim.init)
        est = eng.estimator if hasattr(eng, "estimator") else filt.estimator
        split = {"predict": [], "update": []}
        if isinstance(est, ParticleEstimator):
            for name in ("predict", "update"):
                f = getattr(est, name)

                def timed(*a, _f=f, _k=name):
                    t0 = time.perf_counter()
                    out = _f(*a)
                    split[_k].append(time.perf_counter() - t0)
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
            parts = {k: float(np.mean(v)) * 1e6 for k, v in split.items() if v}
    return best, parts


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
    for N in (500, 2000):
        pf = ParticleFilter(lay, sim.imu_model, particles=N)
        t, parts = engine_epoch_us(pf, sim, lever)
        out[f"pf{N}_us_per_epoch"] = t
        out[f"pf{N}_predict_us"] = parts["predict"]
        out[f"pf{N}_update_us"] = parts["update"]
        out[f"pf{N}_over_ekf"] = t / out["ekf_us_per_epoch"]
        out[f"pf{N}_over_ukf"] = t / out["ukf_us_per_epoch"]

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
    for N in (500, 1000, 2000):
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
          "run's GNSS epochs, best of 2 runs; same process.", "", "| what | value |", "|---|---|"]
    for k, v in out.items():
        if k != "accuracy":
            md.append(f"| {k} | {v:.4g} |")
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
