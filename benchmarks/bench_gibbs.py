"""Benchmark the Gibbs learner: compiled kernel vs the numpy reference sweep, with VB beside.

Run:  PYTHONPATH=src python benchmarks/bench_gibbs.py [--out benchmarks/results/gibbs]   (-> .md and .json)

The P1 training problem: 1-D standardised residuals, n = 2000 per mixture, K = 4,
the priors of ``mixnav.filters.gmekf.learn_mixture`` (alpha0 = 1, beta0 = 1,
nu0 = 1, W0 = 2).  Three training sets like the ones a P1-sim1 run learns from
(every learned filter fits all three per run):

* pseudorange: 0.1 N(0, 1) + 0.9 N(0, 1/3) (P1: R_1 = 3 R_2 = R), plus a +-8.33 gross error (2.5 m / 0.3 m)
  on every 20th sample (P1's "every 20 epochs");
* tdcp: the difference of two such mixture draws (no gross errors);
* process: 0.1 N(0, 3) + 0.9 N(0, 1) (P1-sim2's IMU white noise).

Timed, all in one process, side by side: MCMC with 1000 and 5000 kept samples
(burn-in the default, 500 / 2500 sweeps), numpy backend (best of 3) and numba
backend (best of 5), and VB as ``learn_mixture`` runs it (best of 3 per seed,
median over 3 seeds: its iteration count depends on the initial partition).
The first compiled fit (cache load or compilation) is timed separately.
The mixtures each learner gives (``learn_mixture``, seed 0, after pruning at
1 %) are listed below the table: cost is only half of the comparison.  Times are
CPU times of the process (see :func:`best_of`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import warnings

import numba
import numpy as np

from _timing import best_time
from mixnav.filters.gmekf import learn_mixture
from mixnav.noise.learn import GibbsGaussianMixture
from mixnav.noise.mixture import GaussianMixture

N = 2000
K = 4


def training_sets(rng):
    """The three 1-D training sets (n = 2000 each) described in the module docstring."""
    meas = GaussianMixture([0.1, 0.9], [[0.0], [0.0]], [[[1.0]], [[1.0 / 3]]])
    pr = meas.sample(N, rng)[:, 0]
    pr[::20] += 2.5 / 0.3 * rng.choice([-1.0, 1.0], size=pr[::20].shape)
    tdcp = meas.sample(N, rng)[:, 0] - meas.sample(N, rng)[:, 0]
    proc = GaussianMixture([0.1, 0.9], [[0.0], [0.0]], [[[3.0]], [[1.0]]]).sample(N, rng)[:, 0]
    return {"pseudorange": pr, "tdcp": tdcp, "process": proc}


def gibbs(x, samples, backend, seed=0):
    # learn_mixture's settings (mixnav.filters.gmekf), with the backend chosen
    return GibbsGaussianMixture(n_components=K, n_samples=samples, alpha0=1.0, beta0=1.0, nu0=1.0,
                                W0=np.array([[2.0]]), prune_threshold=0.01, random_state=seed,
                                backend=backend).fit(x[:, None])


def cpu_best(fn, repeats):
    """Smallest CPU time of the process (``time.process_time``) over ``repeats`` calls.

    CPU time, not wall time: on the shared 2-core machine a wall clock also counts the
    time the process waits for a core (every learner here runs on one thread).
    """
    return best_time(fn, repeats, clock=time.process_time)


def main(out=None):
    warnings.simplefilter("ignore")
    data = training_sets(np.random.default_rng(0))
    t = time.perf_counter()
    gibbs(data["tdcp"][:100], 10, "numba")
    t_first = time.perf_counter() - t               # wall time: includes reading the cache
    learn_mixture(data["tdcp"], "vb")                    # VB kernel: compile / cache load
    load0 = os.getloadavg()
    rows = []
    for name, x in data.items():
        r = {"data": name}
        for S in (1000, 5000):
            r[f"numpy_{S}"] = cpu_best(lambda: gibbs(x, S, "numpy"), 3)
            r[f"numba_{S}"] = cpu_best(lambda: gibbs(x, S, "numba"), 5)
        r["vb"] = float(np.median([cpu_best(lambda: learn_mixture(x, "vb", seed=s), 3) for s in range(3)]))
        rows.append(r)
        print(r, flush=True)
    load1 = os.getloadavg()
    tot = {k: sum(r[k] for r in rows) for k in rows[0] if k != "data"}
    rows.append({"data": "total (one learned filter's training in a P1 run)", **tot})

    def ms(v):
        return f"{1e3 * v:.0f}" if v >= 0.1 else f"{1e3 * v:.1f}"

    lines = ["# Gibbs learner: compiled kernel vs numpy reference, VB beside", "",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores "
             f"(numba threads {numba.get_num_threads()}; every learner here is single-threaded), Python "
             f"{platform.python_version()}, numpy {np.__version__}.  Produced by `benchmarks/bench_gibbs.py`, "
             f"all in one process.  Load average (1 min) {load0[0]:.1f} at the start, {load1[0]:.1f} at the end "
             f"(the machine is shared; times are CPU times of the process, which exclude waiting for a core, "
             f"and the ratios side by side are the result).", "",
             f"P1 training problem: 1-D, n = {N}, K = {K}, learn_mixture's priors; MCMC-S keeps S draws after "
             f"the default burn-in of S/2 sweeps; numpy best of 3, numba best of 5; VB median over 3 seeds of "
             f"the best of 3.  First compiled fit in the process (cache load): {t_first:.2f} s.", "",
             "| training set | MCMC-1000 numpy [ms] | MCMC-1000 numba [ms] | speed-up | MCMC-5000 numpy [ms] "
             "| MCMC-5000 numba [ms] | speed-up | VB [ms] | MCMC-5000 numba / VB |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['data']} | {ms(r['numpy_1000'])} | {ms(r['numba_1000'])} | "
                     f"{r['numpy_1000'] / r['numba_1000']:.1f}x | {ms(r['numpy_5000'])} | {ms(r['numba_5000'])} | "
                     f"{r['numpy_5000'] / r['numba_5000']:.1f}x | {ms(r['vb'])} | "
                     f"{r['numba_5000'] / r['vb']:.1f}x |")
    per_sweep = {k: tot[f"numba_{k}"] / (3 * 1.5 * k) for k in (1000, 5000)}
    lines += ["", f"Per sweep (n = {N}, K = {K}), compiled: {1e6 * per_sweep[5000]:.0f} us "
              f"(numpy: {1e6 * tot['numpy_5000'] / (3 * 7500):.0f} us).", ""]
    truth = {"pseudorange": "0.1 N(0, 1) + 0.9 N(0, 0.333), gross +-8.33 on 5 %",
             "tdcp": "0.01 N(0, 2) + 0.18 N(0, 1.33) + 0.81 N(0, 0.667)", "process": "0.1 N(0, 3) + 0.9 N(0, 1)"}
    lines += ["Learned mixtures (`learn_mixture`, seed 0, numba backend; weight / mean / variance per "
              "component, components below 1 % pruned):", "",
              "| training set (truth) | VB | MCMC-1000 | MCMC-5000 |", "|---|---|---|---|"]
    learned = {}
    for name, x in data.items():
        cells = []
        for method, S in (("vb", 1000), ("gibbs", 1000), ("gibbs", 5000)):
            sm = learn_mixture(x, method, K, S, 0.01, 0)
            cells.append("; ".join(f"{w:.3f} / {m:+.2f} / {v:.3g}" for w, m, v in zip(sm.weights, sm.means, sm.scales)))
            learned[f"{name}:{method}-{S}"] = [list(map(float, a)) for a in (sm.weights, sm.means, sm.scales)]
        lines.append(f"| {name} ({truth[name]}) | " + " | ".join(cells) + " |")
    lines += ["", "The Gibbs posterior means are averages of draws relabelled by the component mean; with "
              "several zero-mean components (every P1 noise) the labels of those components switch "
              "between draws, so their averages blend the narrow and the wide component, and components "
              "that the data leave nearly empty average heavy-tailed prior draws (nu0 = 1), which grow "
              "with the chain length.", ""]
    text = "\n".join(lines)
    print(text)
    if out:
        with open(out + ".md", "w") as f:
            f.write(text)
        with open(out + ".json", "w") as f:
            json.dump({"rows": rows, "first_fit_s": t_first, "load": [load0[0], load1[0]],
                       "n": N, "K": K, "learned": learned}, f, indent=1)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None, help="path without extension: writes .md and .json")
    main(ap.parse_args().out)
