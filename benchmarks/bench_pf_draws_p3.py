"""The particle filter's Monte Carlo statistics on P3-flight, before and after a change of
its random draws (issue 33: the Liu-West jitter's normals drawn in the kernel).

    PYTHONPATH=<old src> python benchmarks/bench_pf_draws_p3.py run --runs 20 --out DIR/old
    PYTHONPATH=<new src> python benchmarks/bench_pf_draws_p3.py run --runs 20 --out DIR/new
    python benchmarks/bench_pf_draws_p3.py compare DIR/old DIR/new [--md FILE]

``run``: the shipped P3-flight scenario with only its particle filter (2000 particles),
in make_p3.py's ``fix-init`` variant (the filter's initial position error with the
fix's sigma: the variant where the PF converges; with P3's 370 m spread it is lost in
every run, before and after, and its statistics say nothing), for seeds 1..runs through
the Monte Carlo layer. Every seed simulates the same data in both runs; only the
filter's draws differ. ``compare``: per score the mean and 95 % confidence interval
(t distribution) of each, and the paired difference new - old with its interval.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

SCORES = ["pitch_rmse_deg", "yaw_rmse_deg", "velocity_rmse_mps", "horizontal_rmse_m", "vertical_rmse_m",
          "nees_pos_mean"]


def scenario_text() -> str:
    from mixnav.config.loader import resolve
    text, _ = resolve("P3-flight", "scenarios", "scenario")
    head, *blocks = re.split(r"(?m)^\[\[methods\]\]\n", text)
    pf = [b for b in blocks if re.search(r'(?m)^name = "pf"$', b)]
    if len(pf) != 1:
        raise SystemExit("P3-flight has no single method named pf: update bench_pf_draws_p3.py")
    old = 'position_sigma = ["369.8 m", "307.2 m", "50 m"]'
    if old not in head:
        raise SystemExit(f"P3-flight no longer has {old!r}: update bench_pf_draws_p3.py")
    head = head.replace(old, 'position_sigma = ["3.7 m", "3.7 m", "5 m"]')
    return head + "[[methods]]\n" + pf[0]


def run(runs: int, out: Path, workers: int) -> None:
    import mixnav
    from mixnav.experiment.montecarlo import run_experiment
    out.mkdir(parents=True, exist_ok=True)
    path = out / "P3-flight-pf.toml"
    path.write_text(scenario_text())
    res = run_experiment(str(path), runs, out / "experiment", workers=workers, resume=False, seeds_from=1,
                         overwrite=True)
    res = res[res.method == "pf"].sort_values("seed")
    rows = {k: res[k].astype(float).tolist() for k in SCORES}
    rows["seed"] = res.seed.astype(int).tolist()
    rows["source"] = str(Path(mixnav.__file__).parent)
    (out / "scores.json").write_text(json.dumps(rows, indent=1))


def _ci(x):
    from scipy import stats
    x = np.asarray(x, float)
    h = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
    return x.mean(), h


def compare(old: Path, new: Path, md: Path | None) -> str:
    a, b = (json.loads((p / "scores.json").read_text()) for p in (old, new))
    if a["seed"] != b["seed"]:
        raise SystemExit("the two runs have different seeds")
    lines = [f"P3-flight (fix-init), the particle filter alone (2000 particles), seeds "
             f"{a['seed'][0]}-{a['seed'][-1]} ({len(a['seed'])} runs): old draws ({a['source']}) against new "
             f"({b['source']}); mean ± half width of the 95 % CI (t), and the paired difference new - old.", "",
             "| score | old | new | new - old [95 % CI] | CI holds 0 |", "|---|---|---|---|---|"]
    for k in SCORES:
        (ma, ha), (mb, hb) = _ci(a[k]), _ci(b[k])
        md_, hd = _ci(np.asarray(b[k]) - np.asarray(a[k]))
        lines.append(f"| {k} | {ma:.4g} ± {ha:.2g} | {mb:.4g} ± {hb:.2g} | {md_:.3g} [{md_ - hd:.3g}, "
                     f"{md_ + hd:.3g}] | {'yes' if abs(md_) <= hd else 'NO'} |")
    text = "\n".join(lines) + "\n"
    if md is not None:
        md.write_text(text)
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--runs", type=int, default=20)
    r.add_argument("--workers", type=int, default=1)
    r.add_argument("--out", type=Path, required=True)
    c = sub.add_parser("compare")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    c.add_argument("--md", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "run":
        run(args.runs, args.out, args.workers)
    else:
        print(compare(args.old, args.new, args.md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
