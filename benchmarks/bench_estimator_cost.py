"""Every estimator's cost per GNSS epoch, two versions of mixnav side by side in one run.

    python benchmarks/bench_estimator_cost.py --old DIR/src [--rounds 3]   # drives both, writes results
    python benchmarks/bench_estimator_cost.py --one                       # times the mixnav on the path
    python benchmarks/bench_estimator_cost.py --old DIR/src --only drive-0708-multipath smartloc-berlin
                                                  # only these cases (names as in CASES), results under
                                                  # estimator_cost_subset.md/.json (or --out STEM)
    python benchmarks/bench_estimator_cost.py --old DIR/src --as-of 2f27095 ...
                                                  # the datasets as configured at that commit, for both
    python benchmarks/bench_estimator_cost.py --pool A B --out STEM
                                                  # the rounds of runs A and B (results/A.json ...)
                                                  # pooled: best and median of every round, per side

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

Like for like (``--as-of COMMIT``): a dataset whose shipped file changed on purpose
since the old version (new settings, new keys with defaults that change behaviour) does
other work per epoch in each version, so its cost is not comparable. With ``--as-of``
both versions run the dataset files as they were at COMMIT (``git show``; ``data_dir``
made absolute), and the new one with the keys added since then set to what the old code
did (``OFF_SINCE``: the stillness detector's level test off). Each method's horizontal
RMSE is recorded with its time, and the table says whether the two versions computed
the same numbers: only then are the two costs the cost of the same work.

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
#: (table header, line added under it) for the new version's copy of an --as-of file: behaviour
#: added after 2f27095 and on by default, switched off where the old file had no such key
OFF_SINCE = [("[aiding.zupt]", 'accel_drift = "1e6 m/s^2"   # the level test off (stop 38 added it)')]
#: timed runs of each case per process (after the warm-up); the best counts
REPEAT = 3


def _cases(only=None):
    return [(k, n) for k, n in CASES if not only or Path(n).stem in only]


def one(only=None, files=None) -> dict:
    import mixnav
    out = {}
    for kind, name in _cases(only):
        if kind == "dataset" and files and (Path(files) / f"{name}.toml").exists():
            name = str(Path(files) / f"{name}.toml")
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
                    out["rmse:" + key] = float(row.get("horizontal_rmse_m", math.nan))
    return out


def as_of_files(commit: str, cases, root: Path) -> dict:
    """Write every dataset case's file as it was at ``commit`` into ``root/old`` and
    ``root/new`` (the new copy with OFF_SINCE); returns {"old": dir, "new": dir}."""
    data = Path(os.environ.get("MIXNAV_DATA", HERE.parent.parent / "shared" / "data")).resolve()
    for side in ("old", "new"):
        (root / side).mkdir(parents=True, exist_ok=True)
    for kind, name in cases:
        if kind != "dataset":
            continue
        text = subprocess.run(["git", "-C", str(HERE.parent), "show",
                               f"{commit}:src/mixnav/config/datasets/{name}.toml"],
                              capture_output=True, text=True, check=True).stdout
        text = text.replace('data_dir = "../shared/data/', f'data_dir = "{data}/')
        (root / "old" / f"{name}.toml").write_text(text)
        for header, line in OFF_SINCE:
            if header in text and line.split("=")[0] not in text.split(header, 1)[1].split("\n[", 1)[0]:
                text = text.replace(header + "\n", f"{header}\n{line}\n", 1)
        (root / "new" / f"{name}.toml").write_text(text)
    return {"old": str(root / "old"), "new": str(root / "new")}


def _run_one(src: str | None, only=(), files=None) -> dict:
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = src
    done = subprocess.run([sys.executable, __file__, "--one", *(["--only", *only] if only else []),
                           *(["--files", files] if files else [])], env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def pool(stems, out: str) -> None:
    """Pool the rounds of several runs of this script (results/STEM.json, the same protocol:
    old and new processes alternating) and write results/OUT.md/.json: per method the number
    of rounds, the best and the median of each side and their ratios. Both statistics are
    given because on a shared VM one process's times are off by 10-30 % as a whole: the best
    of the rounds is the steady cost when the slow processes are the outliers, the median
    when a lucky fast one is."""
    import statistics
    runs = [json.loads((HERE / "results" / f"{s}.json").read_text()) for s in stems]
    sides = {w: [r for run in runs for r in run[w]] for w in ("old", "new")}
    keys = sorted({k for r in sides["old"] for k in r if not k.startswith("rmse:")}
                  & {k for r in sides["new"] for k in r if not k.startswith("rmse:")})
    rows = []
    for k in keys:
        o = [r[k] for r in sides["old"] if k in r]
        n = [r[k] for r in sides["new"] if k in r]
        rows.append({"method": k, "rounds": min(len(o), len(n)), "old_best": min(o), "new_best": min(n),
                     "best_ratio": min(n) / min(o), "old_median": statistics.median(o),
                     "new_median": statistics.median(n),
                     "median_ratio": statistics.median(n) / statistics.median(o)})
    lines = ["# Estimator cost per GNSS epoch: the rounds of several runs pooled", "",
             f"`benchmarks/bench_estimator_cost.py --pool {' '.join(stems)} --out {out}`: the rounds of "
             + ", ".join(f"`{s}`" for s in stems) + " (each: old and new processes alternating, 3 timed runs "
             "per process after a warm-up, the best of them per process) pooled per method: the best and the "
             "median over the rounds of each side [us per GNSS epoch].", "",
             "| case:method | rounds | old best | new best | best new / old | old median | new median | "
             "median new / old |", "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['method']} | {r['rounds']} | {r['old_best']:.1f} | {r['new_best']:.1f} | {r['best_ratio']:.3f} | "
              f"{r['old_median']:.1f} | {r['new_median']:.1f} | {r['median_ratio']:.3f} |" for r in rows]
    (HERE / "results" / f"{out}.md").write_text("\n".join(lines) + "\n")
    (HERE / "results" / f"{out}.json").write_text(json.dumps({"pooled": list(stems), "rows": rows}, indent=1))
    print("\n".join(lines))


def _names_after(argv, flag: str) -> list[str]:
    """The arguments after ``flag``, up to the next option (none when ``flag`` is absent)."""
    names = []
    for a in argv[argv.index(flag) + 1:] if flag in argv else ():
        if a.startswith("--"):
            break
        names.append(a)
    return names


def main(argv) -> None:
    if "--pool" in argv:
        pool(_names_after(argv, "--pool"), argv[argv.index("--out") + 1])
        return
    only = _names_after(argv, "--only")
    if only and not _cases(only):
        raise SystemExit(f"--only: no case named {only}; the cases: {[Path(n).stem for _, n in CASES]}")
    if "--one" in argv:
        print(json.dumps(one(only, argv[argv.index("--files") + 1] if "--files" in argv else None)))
        return
    old = argv[argv.index("--old") + 1]
    new = str(HERE.parent / "src")
    rounds = int(argv[argv.index("--rounds") + 1]) if "--rounds" in argv else ROUNDS
    as_of = argv[argv.index("--as-of") + 1] if "--as-of" in argv else None
    files = {"old": None, "new": None}
    if as_of:
        import tempfile
        files = as_of_files(as_of, _cases(only), Path(tempfile.mkdtemp(prefix="cost-as-of-")))
    runs = {"old": [], "new": []}
    for r in range(rounds):
        for which, src in (("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old)):
            runs[which].append(_run_one(src, only, files[which]))
            print(f"round {r + 1}: {which} done", flush=True)
    best = {w: {k: min(d[k] for d in ds if k in d) for k in set().union(*ds) if not k.startswith("rmse:")}
            for w, ds in runs.items()}
    rmse = {w: ds[0] for w, ds in runs.items()}
    keys = sorted(set(best["old"]) & set(best["new"]))

    def same(k):   # the two versions' RMSE of this method, equal to 1e-9 relative: the same work
        a, b = rmse["old"].get("rmse:" + k, math.nan), rmse["new"].get("rmse:" + k, math.nan)
        return "n/a" if a != a or b != b else ("yes" if abs(a - b) <= 1e-9 * max(abs(a), 1e-9)
                                               else f"no ({a:.3f} / {b:.3f} m)")
    rows = [(k, best["old"][k], best["new"][k], best["new"][k] / best["old"][k], same(k)) for k in keys]
    load = os.getloadavg()
    lines = ["# Estimator cost per GNSS epoch: before and after, side by side",
             "",
             f"`benchmarks/bench_estimator_cost.py --old {old} --rounds {rounds}`: each method's "
             f"`epoch_time_mean_us` (filter wall time per GNSS epoch, mechanization included), best of "
             f"{rounds} rounds alternating old and new processes, {REPEAT} timed runs each after a warm-up run; "
             f"load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (2 cores, shared).",
             "", "| case:method | old [us/epoch] | new [us/epoch] | new / old | same RMSE |",
             "|---|---|---|---|---|"]
    lines += [f"| {k} | {a:.1f} | {b:.1f} | {q:.3f} | {e} |" for k, a, b, q, e in rows]
    one_side = sorted(set(best["old"]) ^ set(best["new"]))
    if one_side:
        lines += ["", "In one version only: " + ", ".join(one_side)]
    if only:
        lines[2] = lines[2].replace("--rounds", "--only " + " ".join(only) + " --rounds")
    if as_of:
        lines[2] = lines[2].replace("--rounds", f"--as-of {as_of} --rounds")
        lines[2] += (f" The datasets run their files as they were at {as_of}, in both versions; the new one "
                     "with " + "; ".join(f"`{h} {ln.split('#')[0].strip()}`" for h, ln in OFF_SINCE)
                     + " (behaviour added since, switched off).")
    stem = argv[argv.index("--out") + 1] if "--out" in argv else "estimator_cost" + ("_subset" if only else "")
    (HERE / "results" / f"{stem}.md").write_text("\n".join(lines) + "\n")
    (HERE / "results" / f"{stem}.json").write_text(json.dumps({"old": runs["old"], "new": runs["new"],
                                                                      "old_src": old, "as_of": as_of}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
