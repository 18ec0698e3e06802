"""The regression cases of tests/test_reference_metrics.py and how each is computed.

Kept apart from the test so that ``make_reference.py`` can compute the stored
numbers with any version of the library (it was run on the code before the
engine redesign, commit 15ef457). The glue uses only entry points that a user
of ``mixnav run`` / ``mixnav process`` would use.
"""

from __future__ import annotations

import math

import numpy as np

#: (case id, kind, name, seed, sweep variant index or None, slow)
CASES = [
    ("loose-demo/1", "scenario", "loose-demo", 1, None, False),
    ("loose-demo/2", "scenario", "loose-demo", 2, None, False),
    ("tight-demo/1", "scenario", "tight-demo", 1, None, False),
    ("tdcp-demo/1", "scenario", "tdcp-demo", 1, None, False),
    ("tdcp-demo/2", "scenario", "tdcp-demo", 2, None, False),
    ("P1-sim1/1", "scenario", "P1-sim1", 1, None, False),
    ("P1-sim1/2", "scenario", "P1-sim1", 2, None, False),
    ("P1-sim2/1", "scenario", "P1-sim2", 1, None, False),
    ("P1-sim2/2", "scenario", "P1-sim2", 2, None, False),
    ("P2-s1/1", "scenario", "P2-s1", 1, None, False),
    ("P2-s2/1", "scenario", "P2-s2", 1, None, False),
    ("P2-s2/2", "scenario", "P2-s2", 2, None, False),
    ("P2-s3/1@0", "scenario", "P2-s3", 1, 0, False),
    ("P2-s3/1@-1", "scenario", "P2-s3", 1, -1, False),
    ("P1-sweep/1@0", "scenario", "P1-sweep", 1, 0, False),
    ("P1-sweep/1@-1", "scenario", "P1-sweep", 1, -1, False),
    ("P1-sweep-sim2/1@-1", "scenario", "P1-sweep-sim2", 1, -1, False),
    ("drive-0708", "dataset", "drive-0708", None, None, False),
    ("android-static", "dataset", "android-static", None, None, False),
]

#: metric keys that measure compute time (not reproducible, not compared)
TIMING = {"epoch_time_mean_us", "update_time_mean_us", "wall_time_s", "learning_time_s", "total_time_s",
          "online_refit_time_s", "solve_time_s", "solve_time_mean_us", "read_time_s", "filter_time_s",
          "real_time_factor", "smoother_time_s"}


def _clean(d):
    """Plain JSON numbers, timing keys dropped, recursively."""
    if isinstance(d, dict):
        return {k: _clean(v) for k, v in d.items() if k not in TIMING and "time_mean" not in k}
    if isinstance(d, (list, tuple)):
        return [_clean(v) for v in d]
    if isinstance(d, (np.floating, float)):
        return None if not math.isfinite(float(d)) else float(d)
    if isinstance(d, (np.integer, int)) and not isinstance(d, bool):
        return int(d)
    if isinstance(d, np.ndarray):
        return _clean(d.tolist())
    return d


def _result_numbers(res, table, outages):
    from mixnav.experiment.run import method_metrics
    m = method_metrics(res, table, outages)
    m["final_nav"] = res.nav[-1]
    m["final_sigma"] = res.sigma[-1]
    m["final_sensor"] = res.sensor[-1]
    m["nis_sum"] = float(np.sum(res.nis))
    m["nis_count"] = int(len(res.nis))
    return _clean(m)


def compute(case, data_dir=None) -> dict:
    """``{method: {key: number}}`` of one case."""
    cid, kind, name, seed, variant, _ = case
    if kind == "scenario":
        from mixnav.config import load_scenario
        from mixnav.experiment.run import run_scenario, solution_table
        sc, src, text = load_scenario(name)
        if variant is not None:
            from mixnav.config.loader import sweep_variants
            sc = sweep_variants(sc, text, src)[variant][1]
        run = run_scenario(sc, src, seed=seed)
        out = {}
        for mname, res in run.results.items():
            table = solution_table(res, run.sim.truth, run.sim.outages)
            out[mname] = _result_numbers(res, table, run.sim.outages)
        return out
    from mixnav.config import load_dataset
    from mixnav.experiment.process import process
    ds, src, _ = load_dataset(name)
    po = process(ds, src, data_dir)
    if ds.dataset.kind == "gnss-raw":
        from mixnav.experiment.spp_process import solution_table as spp_table, spp_metrics
        t = spp_table(po)
        num = t.select_dtypes("number")
        return {"spp": _clean({**spp_metrics(t, 0.0), "final_row": num.iloc[-1].to_numpy(dtype=float),
                               "column_sums": num.sum().to_numpy(dtype=float)})}
    from mixnav.experiment.run import solution_table
    withheld = tuple(tuple(w) for w in ds.gnss.withhold)
    ref = ds.reference
    lever = po.lever if ref is not None and ref.point == "antenna" else None
    return {mname: _result_numbers(res, solution_table(res, po.reference, withheld, lever=lever), withheld)
            for mname, res in po.results.items()}
