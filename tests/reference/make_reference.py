"""Compute tests/data/reference_metrics.json with the mixnav on the path.

    python tests/reference/make_reference.py [--data DIR] [--only CASE ...]

Each case is computed twice and stored only if the two runs agree bitwise.
The stored file records the commit and machine it was made on: the bitwise
check (``MIXNAV_BITWISE=1``) holds on that machine only.
"""

import json
import platform
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import CASES, _diffs, _without_digests, compute  # noqa: E402
from mixnav.errors import DataError  # noqa: E402


argv = sys.argv[1:]
data = argv[argv.index("--data") + 1] if "--data" in argv else None
only = set(argv[argv.index("--only") + 1:]) if "--only" in argv else None
path = Path(__file__).resolve().parents[1] / "data" / "reference_metrics.json"
stored = json.loads(path.read_text()) if only and path.exists() else {"cases": {}, "seconds": {}}
out, seconds = stored["cases"], stored["seconds"]
not_bitwise = set(stored.get("not_bitwise", ()))
for case in CASES:
    if only and case[0] not in only:
        continue
    t = time.perf_counter()
    try:
        a = compute(case, data)
    except DataError as exc:  # e.g. no shared data here
        print(f"{case[0]}: skipped ({exc})", flush=True)
        continue
    seconds[case[0]] = round(time.perf_counter() - t, 1)
    b = compute(case, data)
    a, b = json.loads(json.dumps(a)), json.loads(json.dumps(b))
    if json.dumps(a, sort_keys=True) != json.dumps(b, sort_keys=True):
        # Not bitwise reproducible inside one process (the MCMC learner's draws
        # meet threaded BLAS reductions): stored, but compared within the
        # tolerance only, if the two runs agree within it.
        diffs = _diffs(_without_digests(a), _without_digests(b))
        if diffs:
            raise SystemExit(f"{case[0]} is not reproducible between two runs:\n" + "\n".join(diffs[:20]))
        not_bitwise.add(case[0])
        print(f"{case[0]}: reproducible within the tolerance only, not bitwise", flush=True)
    out[case[0]] = a
    print(f"{case[0]}: {seconds[case[0]]:.1f} s", flush=True)
commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                        cwd=path.parent).stdout.strip()
path.write_text(json.dumps({"cases": out, "seconds": seconds, "commit": commit,
                            "not_bitwise": sorted(not_bitwise),
                            "machine": f"{platform.machine()} {platform.processor()} {platform.node()}"},
                           indent=1, sort_keys=True))
print("wrote", path)
