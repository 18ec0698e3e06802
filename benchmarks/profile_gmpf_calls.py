"""The GMPF's work per run, two versions side by side: Python function calls by cProfile.

    python benchmarks/profile_gmpf_calls.py --old DIR/src    # writes results/gmpf_profile.md/.json

Wall times on this VM move 10-30 % per process (estimator_cost_like_for_like_pooled.md), more
than the 5 % the redesign must stay within; the GMPF's cost is mostly Python-level (its EM
refits per epoch), so the count of function calls per run, which does not depend on the
machine's load, says whether the new code does more work. Each version: ensemble-cost's drive
with the GMPF alone (500 particles), one warm-up run, then one profiled run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

_CHILD = """
import cProfile, json, pstats, sys
from pathlib import Path
import mixnav
go = lambda: mixnav.run_scenario(sys.argv[1], seed=1)
go()
pr = cProfile.Profile(); pr.enable(); go(); pr.disable()
st = pstats.Stats(pr)
top = sorted(st.stats.items(), key=lambda kv: -kv[1][2])[:12]
print(json.dumps({"calls": st.total_calls, "primitive": st.prim_calls,
                  "top": [[f"{Path(f).name}:{ln}({fn})", cc, nc, tt] for (f, ln, fn), (cc, nc, tt, ct, _) in top]}))
"""


def _gmpf_only() -> str:
    text = (HERE / "configs" / "ensemble-cost.toml").read_text()
    head, *methods = text.split("[[methods]]")
    path = Path(tempfile.mkdtemp()) / "ensemble-gmpf.toml"
    path.write_text(head + "[[methods]]" + next(m for m in methods if 'estimator = "gmpf"' in m))
    return str(path)


def run(src: str | None, cfg: str) -> dict:
    env = {"PYTHONPATH": src} if src else {}
    out = subprocess.run([sys.executable, "-c", _CHILD, cfg], env={**os.environ, **env}, capture_output=True,
                         text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv) -> None:
    old = argv[argv.index("--old") + 1]
    cfg = _gmpf_only()
    res = {"old": run(old, cfg), "new": run(str(HERE.parent / "src"), cfg), "old_src": old}
    epochs = 540   # GNSS epochs of the drive (600 s at 1 Hz less the 60 s outage)
    lines = ["# The GMPF's work per run, old and new (cProfile function calls)", "",
             f"`benchmarks/profile_gmpf_calls.py --old {old}`: ensemble-cost's drive, the GMPF alone (500 "
             "particles), one profiled run after a warm-up in each version.", "",
             "| version | function calls | primitive calls | per GNSS epoch |", "|---|---|---|---|"]
    for w in ("old", "new"):
        lines.append(f"| {w} | {res[w]['calls']} | {res[w]['primitive']} | {res[w]['calls'] / epochs:.0f} |")
    lines += ["", f"New - old: {res['new']['calls'] - res['old']['calls']:+d} calls "
              f"({(res['new']['calls'] / res['old']['calls'] - 1) * 100:+.2f} %).", ""]
    for w in ("old", "new"):
        lines += [f"## {w}: the 12 functions of most own time", "", "| function | calls | own time [s] |",
                  "|---|---|---|"]
        lines += [f"| {name} | {nc} | {tt:.3f} |" for name, cc, nc, tt in res[w]["top"]]
        lines.append("")
    (HERE / "results" / "gmpf_profile.md").write_text("\n".join(lines))
    (HERE / "results" / "gmpf_profile.json").write_text(json.dumps(res, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
