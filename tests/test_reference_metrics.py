"""Every shipped scenario and dataset gives the numbers it gave before the engine
redesign (stored in tests/data/reference_metrics.json by tests/reference/make_reference.py,
run on commit 15ef457).

The redesign kept every operation of every filter in its order, so the numbers
are compared to within ``REL`` relative plus ``ABS`` absolute (floats go through
JSON's shortest round-trip repr, which is exact); counts, flags and keys exactly.
Not bitwise: the numbers were stored on another machine, and the compiled kernels
(LLVM, fastmath) and numpy's reductions round differently on another CPU or build.
On an AMD EPYC with a fresh install the largest differences were 2e-7 relative
(tdcp-demo's yaw p95 after 600 s of TDCP clones; the MCMC-learned P1 runs' final
states) and 3e-9 absolute on final states near zero (tdcp-demo's final velocity of
1e-4 m/s). Any
intended change of a method moves its metrics by far more than 1e-6; an operation
reordering that moves them by 1e-11 (the bank kernel's merged tail, stop 28) no
longer shows here: tests/test_gmekf.py and the closed-form tests pin those kernels.
Long cases (sweeps, second seeds) are marked slow.
"""

import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "reference"))
from cases import CASES, compute  # noqa: E402

REF = json.loads((Path(__file__).resolve().parent / "data" / "reference_metrics.json").read_text())
from .conftest import DATA_DIR as SHARED  # MIXNAV_DATA or ../shared/data

#: allowed difference of a stored float: relative, and absolute (states near zero)
REL, ABS = 1e-6, 1e-8


def _diffs(stored, now, where=""):
    """Every difference between two nested results, as readable lines."""
    out = []
    if isinstance(stored, dict):
        for k in sorted(set(stored) | set(now or {})):
            if k not in (now or {}):
                out.append(f"{where}.{k}: missing now")
            elif k not in stored:
                continue  # a new output (e.g. a key the redesign adds) is not a regression
            else:
                out += _diffs(stored[k], now[k], f"{where}.{k}")
    elif isinstance(stored, list):
        if not isinstance(now, list) or len(now) != len(stored):
            out.append(f"{where}: length {len(stored)} stored, {None if now is None else len(now)} now")
        else:
            for i, (a, b) in enumerate(zip(stored, now)):
                out += _diffs(a, b, f"{where}[{i}]")
    elif isinstance(stored, float) and isinstance(now, (int, float)):
        same = stored == now or (math.isnan(stored) and math.isnan(now)) or \
            (math.isfinite(stored) and abs(now - stored) <= REL * abs(stored) + ABS)
        if not same:
            out.append(f"{where}: stored {stored!r}, now {now!r} (diff {now - stored:.3g})")
    elif stored != now:
        out.append(f"{where}: stored {stored!r}, now {now!r}")
    return out


def _params():
    for case in CASES:
        marks = [pytest.mark.slow] if case[5] else []
        yield pytest.param(case, id=case[0], marks=marks)


@pytest.mark.parametrize("case", list(_params()))
def test_numbers_are_those_before_the_redesign(case):
    if case[0] not in REF["cases"]:
        pytest.skip("no stored reference for this case (its data was absent when it was made)")
    data = None
    if case[1] == "dataset":
        if not SHARED.is_dir():
            pytest.skip("needs ../shared/data")
    now = json.loads(json.dumps(compute(case, data)))  # the same JSON round trip as the stored numbers
    diffs = _diffs(REF["cases"][case[0]], now, case[0])
    assert not diffs, f"{len(diffs)} numbers changed:\n" + "\n".join(diffs[:40])


def test_the_comparison_catches_a_change():
    """The comparison is not vacuous: one changed float, one changed count, one lost key."""
    stored = REF["cases"]["loose-demo/1"]
    now = json.loads(json.dumps(stored))
    m = next(iter(now))
    now[m]["horizontal_rmse_m"] *= 1 + 1e-5       # beyond REL
    now[m]["nis_count"] += 1
    del now[m]["final_sigma"]
    assert len(_diffs(stored, now)) == 3
