"""The particle filter's GNSS epoch with and without a resampling, two source trees side by
side in one run (issue 33: the resampling epoch with the Liu-West jitter <= 1.5 ms).

    python benchmarks/bench_pf_resample.py --old /work/main/src --new src [--rounds 3]

Each round runs one child process per tree (alternating, so both see the same machine
load); a child measures, on loose-demo with 5000 particles x 15 states (serial kernels):

- ``update_fused_resampled_h0.9`` / ``..._not_resampled_h0.9`` / ...: one GNSS update on
  the estimator's state captured before 12 loose-demo epochs and restored before each
  call, the resampling forced (threshold 1) or off (bench_pf.update_split, its medians),
  and its stages timed alone (``stage_*``);
- ``engine_update_resampled`` / ``engine_update_not_resampled`` / ``engine_predict`` /
  ``engine_us_per_epoch``: the means over one whole engine run (bench_pf.engine_epoch_us).

Medians over the rounds (the machine is shared: the children's load average is recorded).
Writes results/pf_resample.json and .md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"


def child(repeats: int) -> dict:
    sys.path.insert(0, str(HERE))
    from bench_pf import engine_epoch_us, update_split

    import mixnav
    from mixnav.config import load_scenario
    from mixnav.filters.particle import ParticleFilter
    from mixnav.ins.error_model import get_layout
    from mixnav.sim.scenario import simulate

    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    lay = get_layout(15)
    N = 5000
    out = {"load_average_1min_start": os.getloadavg()[0], "source": str(Path(mixnav.__file__).parent)}
    us = update_split(sim, lever, N=N, repeats=repeats)
    for k in ("fused_resampled_h0.9", "fused_not_resampled_h0.9", "fused_resampled_h0", "generic_resampled_h0.9"):
        out[f"update_{k}_us"] = us[k]["wall_us_median"]
    for k, v in us["stages"].items():
        out[f"stage_{k}_us"] = v["wall_us_median"]
    t, parts = engine_epoch_us(ParticleFilter(lay, sim.imu_model, particles=N), sim, lever, repeats=1)
    out["engine_us_per_epoch"] = t
    for k in ("predict", "update_resampled", "update_not_resampled", "resampled_fraction"):
        out[f"engine_{k}" + ("" if k == "resampled_fraction" else "_us")] = parts[k]
    out["load_average_1min_end"] = os.getloadavg()[0]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", type=Path)
    ap.add_argument("--new", type=Path)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--child", action="store_true")
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.repeats)))
        return 0
    runs = {"old": [], "new": []}
    for _ in range(args.rounds):
        for label, src in (("old", args.old), ("new", args.new)):
            env = dict(os.environ, PYTHONPATH=str(src.resolve()))
            res = subprocess.run([sys.executable, __file__, "--child", "--repeats", str(args.repeats)], env=env,
                                 capture_output=True, text=True, check=True)
            runs[label].append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(label, runs[label][-1], flush=True)
    keys = [k for k in {**runs["old"][0], **runs["new"][0]} if k != "source"]   # a stage may exist in one tree only
    med = {lab: {k: float(np.median([r.get(k, np.nan) for r in rs])) for k in keys} for lab, rs in runs.items()}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "pf_resample.json").write_text(json.dumps({"median": med, "runs": runs}, indent=1))
    lines = ["# PF GNSS epoch, resampled or not, before and after (bench_pf_resample.py)", "",
             f"loose-demo, 5000 particles x 15 states, serial kernels; {args.rounds} rounds, each one child "
             f"process per source tree, alternating (old: {runs['old'][0]['source']}, new: "
             f"{runs['new'][0]['source']}); medians over the rounds [us]. The machine is shared (2 cores, other "
             "jobs running): load averages in the last rows.", "",
             "| what | old | new | new / old |", "|---|---|---|---|"]
    for k in keys:
        o, w = med["old"][k], med["new"][k]
        ratio = f"{w / o:.3f}" if o and np.isfinite(o) and np.isfinite(w) else ""
        lines.append(f"| {k} | {o:.4g} | {w:.4g} | {ratio} |")
    (RESULTS / "pf_resample.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
