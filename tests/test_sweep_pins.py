"""The sweep summaries of issue 34, pinned (tests/data/sweep_pins.json, made by
tests/reference/make_sweep_pins.py): the drive-0708-aided outage sweep (30 s windows
every 20 s, one withheld at a time) and the smartloc-berlin start sweep (every 30 s from 0
to 150 s). An error statistic (median, p90, worst, RMSE) more than 10 % above its pin, or a
share of NEES-inconsistent windows more than 5 points above it, fails; so does the loss of
a method or a window. Numbers that improve pass (re-pin to keep the gain)."""

import json
import sys
from pathlib import Path

import pytest

from .conftest import DATA_DIR

sys.path.insert(0, str(Path(__file__).resolve().parent / "reference"))
from sweep_cases import SWEEP_CASES, compute  # noqa: E402

PINS = json.loads((Path(__file__).resolve().parent / "data" / "sweep_pins.json").read_text())
#: an error statistic may grow this much before it is a regression
REL = 0.10
#: a share of windows may grow this much
SHARE = 0.05


def regressions(pinned: dict, now: dict) -> list[str]:
    out = []
    for method, block in pinned.items():
        if method not in now:
            out.append(f"{method}: missing now")
            continue
        for k, v in block.items():
            w = now[method].get(k)
            if w is None:
                out.append(f"{method}.{k}: missing now")
            elif k.startswith("n_"):
                if w != v:
                    out.append(f"{method}.{k}: {v} pinned, {w} now")
            elif k.startswith("share_"):
                if w > v + SHARE:
                    out.append(f"{method}.{k}: {v:.3f} pinned, {w:.3f} now")
            elif k.endswith("_m") and w > v * (1 + REL):
                out.append(f"{method}.{k}: {v:.3f} pinned, {w:.3f} now (+{100 * (w / v - 1):.0f} %)")
    return out


@pytest.mark.parametrize("name", list(SWEEP_CASES))
def test_sweep_summary_holds(name):
    folder = DATA_DIR / SWEEP_CASES[name][3]
    if not folder.is_dir():
        pytest.skip(f"real data not found at {folder}")
    bad = regressions(PINS["cases"][name], compute(name, str(DATA_DIR)))
    assert not bad, "\n".join(bad)


def test_the_check_catches_a_regression():
    pinned = {"aided": {"n_windows": 47, "p90_horizontal_max_m": 8.0, "share_nees_above_99": 0.02,
                        "worst_window_start_s": 183.0}}
    ok = {"aided": {"n_windows": 47, "p90_horizontal_max_m": 8.7, "share_nees_above_99": 0.06,
                    "worst_window_start_s": 63.0}}
    assert regressions(pinned, ok) == []
    worse = {"aided": {"n_windows": 46, "p90_horizontal_max_m": 8.9, "share_nees_above_99": 0.08,
                       "worst_window_start_s": 63.0}}
    assert len(regressions(pinned, worse)) == 3
    assert regressions(pinned, {}) == ["aided: missing now"]
