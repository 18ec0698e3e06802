"""Filter cost per GNSS epoch before and after the engine redesign, side by side.

    python benchmarks/bench_engine_redesign.py            # drives both, writes results/engine_redesign.{md,json}
    python benchmarks/bench_engine_redesign.py --one      # times the mixnav on the path, prints JSON

The driver runs ``--one`` alternately with the old code (``OLD_SRC``: the src of a
checkout of commit 15ef457, e.g. ``git worktree add ../wt-ref 15ef457``, the
default ../wt-ref/src) and the new one, ROUNDS times, and
takes each filter's best time per epoch over the rounds of each code (the
machine is shared: the minimum is the steady-state cost, the alternation
cancels drift). Every filter runs the same simulated data (same seed) in both.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

#: (scenario, methods to time) — the EKF epoch, the bank of 16 (P1's TDCP/SINS,
#: MCMC-learned mixtures), M6 on P2-s2, the tight EKF
CASES = [("loose-demo", ["ekf"]), ("tight-demo", ["tight"]), ("P1-sim1", ["ekf", "robust", "gm-true", "vb"]),
         ("P2-s2", ["gmekf", "m6"])]
ROUNDS = 3
REPEAT = 5


def one() -> dict:
    from mixnav.config import load_scenario
    from mixnav.experiment.run import _training
    from mixnav.sim.scenario import simulate
    from _timing import best_of
    try:
        from mixnav.experiment.methods import build
    except ImportError:  # before the redesign
        from mixnav.filters.registry import build
    out = {}
    for name, wanted in CASES:
        sc, src, _ = load_scenario(name)
        sim = simulate(sc, 3, src)
        clock = None
        if sc.gnss.satellites is not None:
            from mixnav.ins.error_model import ClockModel
            s = sc.gnss.satellites
            clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
        training = _training(sc, 3, src)
        for i, m in enumerate(sc.methods):
            if m.name not in wanted:
                continue
            filt, meas = build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, i,
                               observations=sim.observations, clock=clock, training=training, seed=3)
            # warm-up: compilation, caches
            best, res = best_of(lambda: filt.run(sim.imu, sim.init, meas), REPEAT, warmup=True)
            n = res.timing["measurement_epochs"]
            out[f"{name}:{m.name}"] = {"us_per_epoch": best / n * 1e6, "epochs": n}
    return out


def drive():
    here = Path(__file__).resolve().parent
    old_src = os.environ.get("OLD_SRC", str(here.parents[1] / "wt-ref" / "src"))
    new_src = str(here.parent / "src")
    runs = {"old": [], "new": []}
    for _ in range(ROUNDS):
        for label, src in (("old", old_src), ("new", new_src)):
            env = dict(os.environ, PYTHONPATH=src)
            p = subprocess.run([sys.executable, __file__, "--one"], env=env, capture_output=True, text=True,
                               check=True)
            runs[label].append(json.loads(p.stdout.strip().splitlines()[-1]))
    load = open("/proc/loadavg").read().split()[:3]
    rows = []
    for key in runs["new"][0]:
        o = min(r[key]["us_per_epoch"] for r in runs["old"])
        n = min(r[key]["us_per_epoch"] for r in runs["new"])
        rows.append((key, o, n, n / o))
    res = {"rows": [{"filter": k, "old_us": o, "new_us": n, "new_over_old": r} for k, o, n, r in rows],
           "rounds": ROUNDS, "repeat": REPEAT, "load_average": load}
    (here / "results" / "engine_redesign.json").write_text(json.dumps(res, indent=1))
    lines = ["# Engine redesign: cost per GNSS epoch, old (15ef457) and new code side by side", "",
             f"`benchmarks/bench_engine_redesign.py`: each filter's whole run (mechanization, covariance "
             f"propagation, measurement model, update, feedback, recording) divided by its GNSS epochs; best of "
             f"{REPEAT} runs per round, {ROUNDS} rounds alternating old and new processes; load average at the end "
             f"{' '.join(load)} (2 cores, shared).", "",
             "| filter | old [us/epoch] | new [us/epoch] | new / old |", "|---|---|---|---|"]
    lines += [f"| {k} | {o:.1f} | {n:.1f} | {r:.3f} |" for k, o, n, r in rows]
    (here / "results" / "engine_redesign.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    if "--one" in sys.argv:
        print(json.dumps(one()))
    else:
        drive()
