"""The sweeps whose summaries are pinned (tests/test_sweep_pins.py, make_sweep_pins.py)."""

from __future__ import annotations

from pathlib import Path

#: name -> (dataset, kind, arguments): the drive-0708 outage sweep across the whole drive and
#: the smartLoc start sweep of issue 34
SWEEP_CASES = {
    "drive-0708-aided/outage-30s-10s": ("drive-0708-aided", "outage", ("30 s", "10 s", None), "drive-0708"),
    "smartloc-berlin/start-30s-0-150s": ("smartloc-berlin", "start", ("30 s", ("0 s", "150 s")), "smartloc-berlin"),
}


def compute(name: str, data_root: str) -> dict:
    """The case's per-method summary (the metrics.json block), every value a float or int."""
    from mixnav.experiment.sweep import run_outage_sweep, run_start_sweep
    dataset, kind, args, folder = SWEEP_CASES[name]
    data = str(Path(data_root) / folder)
    if kind == "outage":
        res = run_outage_sweep(dataset, *args, data=data, workers=1)
    else:
        res = run_start_sweep(dataset, *args, data=data, workers=1)
    return res.summary
