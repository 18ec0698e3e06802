"""Compute tests/data/reference_metrics.json with the mixnav on the path.

    PYTHONPATH=<old checkout>/src python tests/reference/make_reference.py [--data DIR]

Run once on the code before the engine redesign (commit 15ef457); each case is
computed twice and stored only if the two runs agree bitwise.
"""

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import CASES, compute  # noqa: E402

data = sys.argv[sys.argv.index("--data") + 1] if "--data" in sys.argv else None
out, seconds = {}, {}
for case in CASES:
    t = time.perf_counter()
    try:
        a = compute(case, data)
    except Exception as exc:  # e.g. no shared data here
        print(f"{case[0]}: skipped ({exc})", flush=True)
        continue
    seconds[case[0]] = time.perf_counter() - t
    b = compute(case, data)
    if json.dumps(a, sort_keys=True) != json.dumps(b, sort_keys=True):
        raise SystemExit(f"{case[0]} is not reproducible between two runs")
    out[case[0]] = a
    print(f"{case[0]}: {seconds[case[0]]:.1f} s", flush=True)
path = Path(__file__).resolve().parents[1] / "data" / "reference_metrics.json"
path.write_text(json.dumps({"cases": out, "seconds": seconds}, indent=1, sort_keys=True))
print("wrote", path)
