"""Pin the sweep summaries that tests/test_sweep_pins.py guards (tests/data/sweep_pins.json).

    python tests/reference/make_sweep_pins.py [--data ../shared/data]

The drive-0708-aided outage sweep (30 s windows every 20 s across the drive) and the
smartloc-berlin start sweep (every 30 s from 0 to 150 s), the same calls as the test.
Re-pin only after a change that is meant to move these numbers, and say so in the commit.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sweep_cases import SWEEP_CASES, compute  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "data" / "sweep_pins.json"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[3] / "shared" / "data"))
    a = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).parent).stdout.strip()
    doc = {"commit": commit, "cases": {name: compute(name, a.data) for name in SWEEP_CASES}}
    OUT.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    print(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
