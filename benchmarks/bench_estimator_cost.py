"""Every estimator's cost per GNSS epoch, two versions of mixnav side by side in one run.

    python benchmarks/bench_estimator_cost.py --old DIR/src [--rounds 3]   # drives both, writes results
    python benchmarks/bench_estimator_cost.py --one                       # times the mixnav on the path
    python benchmarks/bench_estimator_cost.py --old DIR/src --only drive-0708-multipath smartloc-berlin
                                                  # only these cases (names as in CASES), results under
                                                  # estimator_cost_subset.md/.json (or --out STEM)

Made for issue 33 (the registry, pipelines and motion-seam redesign must keep every
estimator's cost within 5 %). Only the public API is called (``mixnav.run_scenario``,
``mixnav.process_dataset``), so any two versions can be compared: ``--old`` is the
``src`` of a checkout of the version before (``git worktree add /tmp/before <commit>``).
The driver runs ``--one`` alternately with the old and the new code, ROUNDS times;
each ``--one`` runs every case once to compile and warm the caches, then REPEAT times timed,
and reports the filters' own ``epoch_time_mean_us`` (filter wall time per GNSS
epoch, mechanization included; metrics.json). Each method's best over the rounds of
each code is compared: the machine is shared, the minimum is the steady-state cost,
and the alternation cancels drift.

The cases cover every registered estimator with the shortest shipped case that runs
it; the ensemble filters (UKF, DD2, PF, GMPF) on ``configs/ensemble-cost.toml``
(loose-demo's drive; 2000 and 500 particles for run time).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: (kind, name or path): scenarios and datasets, each estimator in at least one
CASES = [
    ("scenario", "loose-demo"),                          # ekf (loose)
    ("scenario", "tight-demo"),                          # ekf (pseudorange + Doppler)
    ("scenario", "tdcp-demo"),                           # ekf (TDCP clones)
    ("scenario", "P1-sim1"),                             # robust-adaptive, gaussian-mixture (M3-M5)
    ("scenario", "P2-s2"),                               # gaussian-mixture with [mixture.colored] (M6)
    ("scenario", "P5-aircraft"),                         # ukf, vb-aukf, vb-akf, sage-husa
    ("scenario", str(HERE / "configs" / "ensemble-cost.toml")),   # ukf, dd2, pf, gmpf
    ("dataset", "drive-0708-aided"),                     # ekf with NHC/ZUPT/ZARU, smoother
    ("dataset", "drive-0708-multipath"),                 # imm, em-bias
    ("dataset", "smartloc-berlin"),                      # dead reckoning: epoch-mixture, sage-husa, vb-akf ...
    ("dataset", "android-static-filters"),               # constant velocity
]
ROUNDS = 3
#: timed runs of each case per process (after the warm-up); the best counts
REPEAT = 3


def _cases(only=None):
    return [(k, n) for k, n in CASES if not only or Path(n).stem in only]


def one(only=None) -> dict:
    import mixnav
    out = {}
    for kind, name in _cases(only):
        run = (lambda: mixnav.run_scenario(name, seed=1)) if kind == "scenario" else \
            (lambda: mixnav.process_dataset(name))
        run()                                             # compile, caches
        label = Path(name).stem
        for _ in range(REPEAT):
            for method, row in run().metrics.iterrows():
                t = row.get("epoch_time_mean_us")
                if t is not None and t == t and t > 0:   # a smoother's row has no filter time (0)
                    key = f"{label}:{method}"
                    out[key] = min(out.get(key, math.inf), float(t))
    return out


def _run_one(src: str | None, only=()) -> dict:
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = src
    done = subprocess.run([sys.executable, __file__, "--one", *(["--only", *only] if only else [])], env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv) -> None:
    only = []
    if "--only" in argv:   # the names after --only, up to the next option
        for a in argv[argv.index("--only") + 1:]:
            if a.startswith("--"):
                break
            only.append(a)
    if only and not _cases(only):
        raise SystemExit(f"--only: no case named {only}; the cases: {[Path(n).stem for _, n in CASES]}")
    if "--one" in argv:
        print(json.dumps(one(only)))
        return
    old = argv[argv.index("--old") + 1]
    new = str(HERE.parent / "src")
    rounds = int(argv[argv.index("--rounds") + 1]) if "--rounds" in argv else ROUNDS
    runs = {"old": [], "new": []}
    for r in range(rounds):
        for which, src in (("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old)):
            runs[which].append(_run_one(src, only))
            print(f"round {r + 1}: {which} done", flush=True)
    best = {w: {k: min(d[k] for d in ds if k in d) for k in set().union(*ds)} for w, ds in runs.items()}
    keys = sorted(set(best["old"]) & set(best["new"]))
    rows = [(k, best["old"][k], best["new"][k], best["new"][k] / best["old"][k]) for k in keys]
    load = os.getloadavg()
    lines = ["# Estimator cost per GNSS epoch: before and after, side by side",
             "",
             f"`benchmarks/bench_estimator_cost.py --old {old} --rounds {rounds}`: each method's "
             f"`epoch_time_mean_us` (filter wall time per GNSS epoch, mechanization included), best of "
             f"{rounds} rounds alternating old and new processes, {REPEAT} timed runs each after a warm-up run; "
             f"load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (2 cores, shared).",
             "", "| case:method | old [us/epoch] | new [us/epoch] | new / old |", "|---|---|---|---|"]
    lines += [f"| {k} | {a:.1f} | {b:.1f} | {q:.3f} |" for k, a, b, q in rows]
    one_side = sorted(set(best["old"]) ^ set(best["new"]))
    if one_side:
        lines += ["", "In one version only: " + ", ".join(one_side)]
    if only:
        lines[2] = lines[2].replace("--rounds", "--only " + " ".join(only) + " --rounds")
    stem = argv[argv.index("--out") + 1] if "--out" in argv else "estimator_cost" + ("_subset" if only else "")
    (HERE / "results" / f"{stem}.md").write_text("\n".join(lines) + "\n")
    (HERE / "results" / f"{stem}.json").write_text(json.dumps({"old": runs["old"], "new": runs["new"],
                                                                      "old_src": old}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
