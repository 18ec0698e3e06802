"""The ensemble filters on the dead-reckoning and constant-velocity models, on real data, beside the EKF.

Run:  PYTHONPATH=src python benchmarks/bench_ensemble_motion.py [--data ../shared/data] [--particles 1000]
      [--repeat 2] [--out benchmarks/results]

Datasets: ``smartloc-berlin`` (dead reckoning from wheel speed and yaw rate, GPS + GLONASS
pseudoranges; causal start from the 20 s track alignment) and ``android-static-filters``
(GNSS-only constant velocity, GPS pseudoranges corrected by the SPP's atmosphere; start at
the first SPP fix). Each estimator runs through the dataset's own pipeline
(``mixnav.experiment.vehicle_process`` / ``spp_process``): the shipped config's ``ekf``
method alone, with :func:`mixnav.experiment.methods.estimator_for` (what
:func:`mixnav.experiment.methods.run_methods` asks) answering with the
estimator under test. So the motion model, its noise, the pseudorange model, the initial
state, the engine, the output epochs and the scoring are the EKF method's, and only the
estimator differs. The estimators take their defaults; the particle counts (``--particles``,
both PF and GMPF) are chosen for run time only. Nothing is tuned against the reference.

Accuracy: 2-D error, estimate minus reference (smartLoc: the ground-truth track at its
epochs; android: the surveyed point) over the same epochs and the same start as the EKF.
Cost per epoch: the engine's wall time of the run divided by its measurement epochs (the
propagation between epochs included); the smallest of ``--repeat`` runs (a shared machine).
Writes ``ensemble_motion_models.md`` and ``.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np

from mixnav.config.loader import load_dataset
from mixnav.experiment import methods

ROOT = Path(__file__).resolve().parents[1]


def estimators(particles: int) -> dict:
    """name -> a factory of a fresh estimator (None: the pipeline's own EKF)."""
    from mixnav.filters.dd2 import Dd2Estimator
    from mixnav.filters.gmpf import GmpfEstimator
    from mixnav.filters.particle import ParticleEstimator
    from mixnav.filters.ukf import UnscentedEstimator
    from mixnav.filters.vb_akf import ChannelNoise
    return {"ekf": None,
            "ukf": UnscentedEstimator,
            "vb-aukf": lambda: UnscentedEstimator(noise=ChannelNoise()),
            "dd2": Dd2Estimator,
            "pf": lambda: ParticleEstimator(particles=particles),
            "gmpf": lambda: GmpfEstimator(particles=particles)}


def ekf_only(ds):
    """The dataset with its ``ekf`` method alone (no smoother: scored as a filter)."""
    ekf = [m for m in ds.methods if m.name == "ekf"]
    assert len(ekf) == 1, "the shipped config has one method named ekf"
    return ds.model_copy(update={"methods": [ekf[0].model_copy(update={"smooth": False})]})


def run_with(ds, source, data, factory, seed=0):
    """The pipeline with the ekf method's estimator replaced by ``factory()``."""
    original = methods.estimator_for

    def swapped(method, *args, **kwargs):
        return original(method, *args, **kwargs) if factory is None else factory()
    methods.estimator_for = swapped
    try:
        if ds.dataset.kind == "odometry-gnss":
            from mixnav.experiment.vehicle_process import process_vehicle, vehicle_tables
            out = process_vehicle(ds, source, data, seed)
            table = vehicle_tables(out)["ekf"]
            err = table[["err_n_m", "err_e_m"]].to_numpy(dtype=float)
            time = table["time_s"].to_numpy()
        else:
            from mixnav.experiment.spp_process import filter_table, process_raw
            from mixnav.experiment.data_folder import find_data_dir
            out = process_raw(ds, source, find_data_dir(ds, data, source), seed)
            table = filter_table(out, out.results["ekf"])
            ok = (table["status"] == "ok").to_numpy()
            err = table.loc[ok, ["err_n_m", "err_e_m"]].to_numpy(dtype=float)
            time = table.loc[ok, "time_s"].to_numpy()
    finally:
        methods.estimator_for = original
    return out.results["ekf"], err, time


def score(res, err, time) -> dict:
    h = np.hypot(err[:, 0], err[:, 1])
    good = np.isfinite(h)
    h = h[good]
    return {"rmse_m": float(np.sqrt(np.mean(h ** 2))), "p95_m": float(np.percentile(h, 95)),
            "max_m": float(h.max()), "epochs": int(h.size), "from_s": float(time[good][0]),
            "to_s": float(time[good][-1]), "epoch_time_us": float(res.timing["epoch_time_mean_us"]),
            "measurement_epochs": int(res.timing["measurement_epochs"]),
            "recoveries": {k: int(v) for k, v in res.recoveries.items() if v}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--particles", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--datasets", nargs="+", default=["smartloc-berlin", "android-static-filters"])
    ap.add_argument("--only", nargs="+", default=None, help="estimator names (default: all)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    a = ap.parse_args(argv)
    facs = estimators(a.particles)
    names = a.only or list(facs)
    results = {}
    for dname in a.datasets:
        ds, source, _ = load_dataset(dname)
        ds = ekf_only(ds)
        results[dname] = {}
        for name in names:
            best = None
            for _ in range(a.repeat):
                res, err, time = run_with(ds, source, a.data, facs[name])
                s = score(res, err, time)
                if best is not None:    # the same numbers every run (seeded): keep the fastest
                    assert s["rmse_m"] == best["rmse_m"], (dname, name)
                if best is None or s["epoch_time_us"] < best["epoch_time_us"]:
                    best = s
            results[dname][name] = best
            print(dname, name, {k: (round(v, 3) if isinstance(v, float) else v) for k, v in best.items()},
                  flush=True)
    out = Path(a.out)
    meta = {"particles": a.particles, "repeat": a.repeat, "python": platform.python_version(),
            "machine": platform.machine(), "processor": platform.processor()}
    (out / "ensemble_motion_models.json").write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    lines = []
    for dname, rows in results.items():
        ekf = rows.get("ekf")
        lines += [f"### {dname}", "",
                  "| estimator | RMSE [m] | p95 [m] | max [m] | epochs scored | cost / epoch [us] | x EKF | recoveries |",
                  "|---|---|---|---|---|---|---|---|"]
        for name, s in rows.items():
            rel = f"{s['epoch_time_us'] / ekf['epoch_time_us']:.1f}" if ekf else ""
            rec = ", ".join(f"{k} {v}" for k, v in s["recoveries"].items()) or "-"
            lines.append(f"| {name} | {s['rmse_m']:.2f} | {s['p95_m']:.2f} | {s['max_m']:.2f} | {s['epochs']} "
                         f"({s['from_s']:.1f}-{s['to_s']:.1f} s) | {s['epoch_time_us']:.0f} | {rel} | {rec} |")
        lines.append("")
    print("\n".join(lines))
    return results, lines


if __name__ == "__main__":
    main()
