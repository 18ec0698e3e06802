"""smartloc-berlin: the track window and the C/N0 band edges chosen from the data alone (issue 34).

Run:  PYTHONPATH=src python benchmarks/smartloc_choose_settings.py [--data ../shared/data] [--out benchmarks/results]

The criterion needs no reference: the epoch mixture's **innovation log-likelihood** (the
sum over the pseudorange rows of the log predictive density of each innovation, before
the row is used: ``EpochMixtureEstimator.log_likelihood``, a prequential score of the
whole causal pipeline), summed over the rows from ``S + 40 s`` (the longest candidate
window's filter start, so every candidate is scored on the same rows) to the end, and
over the start sweep's starts ``S`` = 0, 30, ..., 150 s. The candidate of the largest
sum is chosen. The reference only fills the RMSE columns, printed beside and not used
for the choice.

Three stages, each the other setting held: (1) the window with the band edges shipped
before (issue 21's 5 dB bands [30, 35, 40, 45], set with the reference in view), (2) the
band edges with the window of (1), (3) the window again with the edges of (2). The band
edge candidates: none, fixed dB grids, and the K-quantiles of the recording's own C/N0
(every row of the file, rounded to whole dB-Hz: data, not reference).

Only the epoch-mixture method runs (the others do not use either setting).
Writes ``smartloc_choose_settings.md`` and ``.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
import warnings
from pathlib import Path

import numpy as np

from mixnav.config.loader import load_dataset
from mixnav.experiment.data_folder import find_data_dir
from mixnav.experiment.vehicle_process import read_vehicle, run_vehicle, vehicle_tables
from mixnav.filters.epoch_mixture import EpochMixtureEstimator

STARTS = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
WINDOWS = (10.0, 15.0, 20.0, 25.0, 30.0, 40.0)
SCORE_FROM = 40.0          # [s] after each start: the longest candidate window
COMMON_FROM = 170.0        # [s]: the start sweep's common span (150 s + the 20 s window)
OLD_EDGES = [30.0, 35.0, 40.0, 45.0]

#: (time, log predictive density) of every epoch of the run in progress
_LOG: list[tuple[float, float]] = []


def _logged_update(update):
    """The estimator's update, also writing each epoch's innovation log-likelihood to _LOG."""
    def wrapped(self, epoch):
        before = self.log_likelihood
        out = update(self, epoch)
        _LOG.append((float(epoch.time), self.log_likelihood - before))
        return out
    return wrapped


def edge_candidates(cn0: np.ndarray) -> list[tuple[str, list[float]]]:
    c = cn0[np.isfinite(cn0)]
    q = (lambda k: sorted({float(v) for v in np.round(np.percentile(c, np.arange(1, k) * 100.0 / k), 0)}))
    return [("none", []), ("[40]", [40.0]), ("median", q(2)), ("[35, 45]", [35.0, 45.0]),
            ("quartiles", q(4)), ("5 dB [30..45] (issue 21)", OLD_EDGES), ("quintiles", q(5)),
            ("5 dB [25..50]", [25.0, 30.0, 35.0, 40.0, 45.0, 50.0]), ("sextiles", q(6)), ("octiles", q(8)),
            ("deciles", q(10)), ("12-quantiles", q(12)), ("15-quantiles", q(15)), ("20-quantiles", q(20)),
            ("2.5 dB [25..50]", [float(v) for v in np.arange(25.0, 50.1, 2.5)]),
            ("3 dB [24..51]", [float(v) for v in range(24, 52, 3)]), ("2 dB [24..50]", [float(v) for v in range(24, 52, 2)])]


class Runner:
    def __init__(self, data=None):
        ds, self.source, _ = load_dataset("smartloc-berlin")
        self.ds = ds.model_copy(update={"methods": [m for m in ds.methods if m.name == "epoch-mixture"]})
        self.folder = find_data_dir(ds, data, self.source)
        self.inputs = read_vehicle(ds, self.source, self.folder)
        self.t0 = float(self.inputs.inc.time[0] - self.inputs.inc.dt[0])

    def run(self, window: float, edges: list[float]) -> dict:
        """Per start: RMSE (own, common span), the criterion's log-likelihood, the alignment."""
        m = self.ds.methods[0]
        method = m.model_copy(update={"options": {**m.options, "cn0_edges": list(edges)}})
        per = {}
        for s in STARTS:
            al = self.ds.alignment.model_copy(update={"start": s, "window": window, "cn0_edges": list(edges)})
            d = self.ds.model_copy(update={"alignment": al, "methods": [method]})
            _LOG.clear()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                vo = run_vehicle(d, self.source, self.folder, self.inputs)
            t = vehicle_tables(vo)["epoch-mixture"]
            e = np.hypot(t["err_n_m"], t["err_e_m"]).to_numpy()
            tt = t["time_s"].to_numpy() - self.t0
            lg = np.array(_LOG)
            rel = lg[:, 0] - self.t0
            per[s] = {"log_likelihood": float(lg[rel > s + SCORE_FROM, 1].sum()),
                      "log_likelihood_all_rows": float(lg[:, 1].sum()),
                      "rows_from": s + SCORE_FROM,
                      "rmse_m": float(np.sqrt(np.mean(e ** 2))),
                      "common_rmse_m": float(np.sqrt(np.mean(e[tt >= COMMON_FROM] ** 2))),
                      "alignment_log_likelihood": float(vo.alignment["log_likelihood"])}
        r = np.array([per[s]["rmse_m"] for s in STARTS])
        c = np.array([per[s]["common_rmse_m"] for s in STARTS])
        return {"window_s": window, "cn0_edges": list(edges), "per_start": {str(k): v for k, v in per.items()},
                "log_likelihood": float(sum(per[s]["log_likelihood"] for s in STARTS)),
                "median_rmse_m": float(np.median(r)), "worst_rmse_m": float(r.max()),
                "median_common_rmse_m": float(np.median(c)), "worst_common_rmse_m": float(c.max())}


def table(rows: list[tuple[str, dict]], chosen: str) -> list[str]:
    best = max(v["log_likelihood"] for _, v in rows)
    out = ["| candidate | criterion: log-likelihood (sum) | minus the best | per start (0 ... 150 s) | "
           "RMSE per start [m] | median / worst [m] | common median / worst [m] |",
           "|---|---|---|---|---|---|---|"]
    for name, v in rows:
        ps = v["per_start"]
        mark = " **(chosen)**" if name == chosen else ""
        out.append(f"| {name}{mark} | {v['log_likelihood']:.1f} | {v['log_likelihood'] - best:.1f} | "
                   + " ".join(f"{ps[str(s)]['log_likelihood']:.0f}" for s in STARTS) + " | "
                   + " ".join(f"{ps[str(s)]['rmse_m']:.2f}" for s in STARTS)
                   + f" | {v['median_rmse_m']:.2f} / {v['worst_rmse_m']:.2f} | "
                   f"{v['median_common_rmse_m']:.2f} / {v['worst_common_rmse_m']:.2f} |")
    return out


def logged_runner(argv, doc: str):
    """A script's ``--data`` / ``--out`` arguments and its :class:`Runner`, with the epoch
    mixture's updates logged (``_LOG``): the start of this script and of smartloc_min_distance.py."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    a = ap.parse_args(argv)
    EpochMixtureEstimator.update = _logged_update(EpochMixtureEstimator.update)
    return a, Runner(a.data)


def main(argv=None) -> None:
    t_wall = time.perf_counter()
    a, R = logged_runner(argv, __doc__)
    pick = (lambda rows: max(rows, key=lambda kv: kv[1]["log_likelihood"]))

    stage1 = [(f"{w:g} s", R.run(w, OLD_EDGES)) for w in WINDOWS]
    w1 = pick(stage1)[1]["window_s"]
    cands = edge_candidates(R.inputs.epochs.cn0)
    stage2 = [(f"{n} {e}", R.run(w1, e)) for n, e in cands]
    e2 = pick(stage2)[1]["cn0_edges"]
    stage3 = [(f"{w:g} s", R.run(w, e2)) for w in WINDOWS]
    w3 = pick(stage3)[1]["window_s"]
    elapsed = time.perf_counter() - t_wall

    lines = ["# smartLoc Berlin: the track window and the C/N0 band edges chosen without the reference (issue 34)", "",
             f"Produced by `benchmarks/smartloc_choose_settings.py` ({platform.machine()}, Python "
             f"{platform.python_version()}; {elapsed:.0f} s). Numbers: the `.json`.", "",
             "**Criterion** (no reference): the epoch mixture's innovation log-likelihood (each pseudorange row's "
             "log predictive density before it is used, summed) over the rows from `S + 40 s` to the end (the "
             "longest candidate window's filter start: every candidate is scored on the same rows), summed over "
             "the starts S = 0, 30, ..., 150 s of the start sweep; the largest is chosen. The RMSE columns (2-D, "
             "against the reference; from each filter's start and on the common span 170 s to the end) are "
             "printed beside, **not** used for the choice. Only the epoch-mixture method runs (no other method "
             "uses these settings).", "",
             f"C/N0 of the recording (all {int(np.isfinite(R.inputs.epochs.cn0).sum())} rows): 1st-99th percentile "
             f"{np.nanpercentile(R.inputs.epochs.cn0, 1):.0f}-{np.nanpercentile(R.inputs.epochs.cn0, 99):.0f} dB-Hz; "
             "the K-quantile candidates are its quantiles rounded to whole dB-Hz.", "",
             f"## 1. Window, with issue 21's band edges {OLD_EDGES}", ""]
    lines += table(stage1, f"{w1:g} s")
    lines += ["", f"## 2. C/N0 band edges, with the {w1:g} s window", ""]
    lines += table(stage2, next(n for n, v in stage2 if v["cn0_edges"] == e2))
    lines += ["", f"## 3. Window again, with the chosen edges {e2}", ""]
    lines += table(stage3, f"{w3:g} s")
    lines += ["", f"Chosen: window {w3:g} s, C/N0 band edges {e2}.", ""]
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "smartloc_choose_settings.json").write_text(json.dumps(
        {"criterion": "innovation log-likelihood of the epoch mixture, rows from S + 40 s, summed over starts",
         "starts_s": list(STARTS), "window_scan_old_edges": dict(stage1), "edge_scan": dict(stage2),
         "window_scan_chosen_edges": dict(stage3), "chosen": {"window_s": w3, "cn0_edges": e2}}, indent=1))
    (out / "smartloc_choose_settings.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
