"""Every shipped scenario and dataset gives the numbers it gave when they were pinned
(tests/data/reference_metrics.json, made by tests/reference/make_reference.py on the
commit and machine it records), through the public API (tests/reference/cases.py).

Numbers are compared to within ``REL`` relative plus ``ABS`` absolute (floats go
through JSON's shortest round-trip repr, which is exact); counts, flags and keys
exactly. Not bitwise by default: the compiled kernels (LLVM, fastmath) and numpy's
reductions round differently on another CPU or build (2e-7 relative was the largest
difference seen between two x86-64 machines: tdcp-demo's yaw p95 after 600 s of
TDCP clones). Any intended change of a method moves its metrics by far more than
1e-6. With ``MIXNAV_BITWISE=1`` on the machine that stored them, every solution
table column's bytes are compared too (SHA-256): the check that a refactoring kept
every operation in its order. Cases listed under ``not_bitwise`` in the file are
compared within the tolerance only: they were seen to differ in their last bits
between two runs of one commit (the MCMC-learned P1 mixtures inside one process;
smartloc-berlin's online-learned mixture under heavy load), with every metric
within the tolerance. A column's sum is compared within ``REL`` of the sum of its terms'
sizes (a signed column, yaw in degrees, cancels to far below them: smartloc's online
mixture and tdcp-demo/2 moved by 4e-6 of their cancelled sums on an AMD EPYC). Methods
listed in ``cases.CHAOTIC`` amplify those last bits into every number of their run and
are compared by their RMSE alone, within ``CHAOTIC_REL``, each with its reason. Long
cases are marked slow.
"""

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "reference"))
from cases import ABS, BITWISE, CASES, REL, _diffs, _without_digests, compute, loose  # noqa: E402,F401

REF = json.loads((Path(__file__).resolve().parent / "data" / "reference_metrics.json").read_text())
from .conftest import DATA_DIR as SHARED  # MIXNAV_DATA or ../shared/data

def _params():
    for case in CASES:
        marks = [pytest.mark.slow] if case[5] else []
        yield pytest.param(case, id=case[0], marks=marks)


@pytest.mark.parametrize("case", list(_params()))
def test_numbers_are_those_pinned(case):
    if case[0] not in REF["cases"]:
        pytest.skip("no stored reference for this case (its data was absent when it was made)")
    data = None
    if case[1] == "dataset":
        if not SHARED.is_dir():
            pytest.skip("needs ../shared/data")
    now = json.loads(json.dumps(compute(case, data)))  # the same JSON round trip as the stored numbers
    stored = REF["cases"][case[0]]
    if not BITWISE or case[0] in REF.get("not_bitwise", ()):
        stored, now = _without_digests(stored), _without_digests(now)
    stored, now, diffs = loose(case[0], stored, now)
    diffs += _diffs(stored, now, case[0])
    assert not diffs, f"{len(diffs)} numbers changed:\n" + "\n".join(diffs[:40])


def test_the_comparison_catches_a_change():
    """The comparison is not vacuous: one changed float, one changed count, one lost key."""
    stored = REF["cases"]["loose-demo/1"]
    now = json.loads(json.dumps(stored))
    m = next(iter(now))
    now[m]["metrics"]["horizontal_rmse_m"] *= 1 + 1e-5       # beyond REL
    now[m]["metrics"]["n_epochs"] += 1
    del now[m]["metrics"]["horizontal_max_m"]
    assert len(_diffs(stored, now)) == 3
    col = next(iter(now[m]["table"]))
    now[m]["table"][col]["sha256"] = "0" * 16                 # seen in the bitwise mode only
    assert len(_diffs(stored, now)) == 4
    assert len(_diffs(_without_digests(stored), _without_digests(now))) == 3


def test_a_chaotic_method_is_still_pinned_by_its_rmse():
    """The loose rule is not a skip: the IMM's RMSE moved beyond CHAOTIC_REL fails, within
    it passes, and the case's other methods are still compared as usual."""
    from cases import CHAOTIC_REL
    stored = REF["cases"]["drive-0708-multipath"]
    now = json.loads(json.dumps(stored))
    now["imm"]["metrics"]["horizontal_rmse_m"] *= 1 + 0.5 * CHAOTIC_REL
    now["imm"]["metrics"]["horizontal_max_m"] *= 0.3
    s2, n2, out = loose("drive-0708-multipath", stored, now)
    assert not out and "imm" not in n2 and not _diffs(s2, n2)
    now["imm"]["metrics"]["horizontal_rmse_m"] = stored["imm"]["metrics"]["horizontal_rmse_m"] * (1 + 2 * CHAOTIC_REL)
    now["em-imm"]["metrics"]["horizontal_rmse_m"] *= 1 + 1e-5
    s2, n2, out = loose("drive-0708-multipath", stored, now)
    assert len(out) == 1 and "imm.metrics.horizontal_rmse_m" in out[0]
    assert any("em-imm.metrics.horizontal_rmse_m" in d for d in _diffs(s2, n2))


def test_a_cancelled_sum_is_compared_by_its_terms():
    """A column sum far below its terms' sizes: a move within REL of the terms passes, one
    beyond fails; without abs_sum (an old pin) the sum's own size rules."""
    stored = {"c": {"sum": 1.0, "finite": 3}}
    ok = {"c": {"sum": 1.0 + 0.5 * REL * 1e4, "abs_sum": 1e4, "finite": 3}}
    bad = {"c": {"sum": 1.0 + 3 * REL * 1e4, "abs_sum": 1e4, "finite": 3}}
    assert not _diffs(stored, ok) and len(_diffs(stored, bad)) == 1
    assert _diffs(stored, {"c": {"sum": 1.0 + 0.5 * REL * 1e4, "finite": 3}})
