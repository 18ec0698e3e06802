"""Sliding-window GNSS outage sweep on drive-0708-aided (issue 34).

    python benchmarks/sweep_drive0708_pullaway.py [--config NAME] [--methods aided,aided-smoothed] [--out FILE]

Loads the dataset once (the pipeline's ``load``) and runs it once per window
(``run``), withholding ONE 30 s window at a time: windows start every 10 s, from
the first multiple of 10 s at least 5 s after the alignment, while the window ends
at least 10 s before the end of the data (45 windows, 60-90 s ... 500-530 s).
The dataset's own windows are not withheld. For every window and method: the
largest horizontal error over the window and its unaided tail (``metrics``'
``outages`` entry) and the mean position NEES over the window's reference epochs.

The summary gives the median, p90 and worst of the maxima and the share of windows
whose mean position NEES is above the chi-square(3) 99 % bound (11.34), over all
windows and over the two halves of a split: windows starting at odd multiples of
10 s ("odd", for choosing settings) and at even ones ("even", for reporting only).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from mixnav.config import load_dataset
from mixnav.experiment.data_folder import find_data_dir
from mixnav.experiment.pipelines import pipeline

CHI2_99_3 = 11.345
LENGTH, STEP = 30.0, 10.0


def windows(t_align: float, t_end: float) -> list[tuple[float, float]]:
    a = np.ceil((t_align + 5.0) / STEP) * STEP
    out = []
    while a + LENGTH <= t_end - 10.0:
        out.append((float(a), float(a + LENGTH)))
        a += STEP
    return out


def sweep(name: str, methods: list[str], data: str | None = None, verbose: bool = True) -> dict:
    ds, src, _ = load_dataset(name)
    p = pipeline(ds, src)
    folder = find_data_dir(ds, data, src)
    inputs = p.load(ds, src, folder)
    # the alignment time and the end, from a run with no window withheld
    base = p.run(ds.model_copy(update={"gnss": ds.gnss.model_copy(update={"withhold": []})}), src, folder, inputs)
    wins = windows(base.init.time, float(base.imu.time[-1]))
    rows = []
    t0 = time.perf_counter()
    for w in wins:
        d = ds.model_copy(update={"gnss": ds.gnss.model_copy(update={"withhold": [w]})})
        po = p.run(d, src, folder, inputs)
        tab = p.tables(po)
        met = p.metrics(po, tab)
        row = {"start_s": w[0]}
        for m in methods:
            t = tab[m]
            s = t[(t.time_s >= w[0]) & (t.time_s <= w[1])]
            row[m] = {"max_m": met[m]["outages"][0]["horizontal_max_m"],
                      "nees_pos": float(np.nanmean(s.nees_pos))}
        rows.append(row)
        if verbose:
            print(f"{w[0]:5.0f}-{w[1]:3.0f} s  " + "  ".join(
                f"{m}: {row[m]['max_m']:6.2f} m NEES {row[m]['nees_pos']:7.2f}" for m in methods), flush=True)
    if verbose:
        print(f"{len(wins)} windows in {time.perf_counter() - t0:.1f} s")
    return {"config": name, "windows": rows, "summary": summary(rows, methods)}


def summary(rows, methods) -> dict:
    out = {}
    for part, sel in (("all", lambda a: True), ("odd", lambda a: round(a / STEP) % 2 == 1),
                      ("even", lambda a: round(a / STEP) % 2 == 0)):
        rs = [r for r in rows if sel(r["start_s"])]
        for m in methods:
            mx = np.array([r[m]["max_m"] for r in rs])
            ne = np.array([r[m]["nees_pos"] for r in rs])
            out.setdefault(part, {})[m] = {
                "n": len(rs), "median_m": float(np.median(mx)), "p90_m": float(np.percentile(mx, 90)),
                "worst_m": float(mx.max()), "worst_start_s": rs[int(np.argmax(mx))]["start_s"],
                "over_10m": int((mx > 10).sum()), "nees_over_bound": int((ne > CHI2_99_3).sum()),
                "nees_over_share": float(np.mean(ne > CHI2_99_3)), "nees_median": float(np.median(ne))}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="drive-0708-aided")
    ap.add_argument("--methods", default="aided,aided-smoothed")
    ap.add_argument("--data", default=None)
    ap.add_argument("--out", default=None, help="write the rows and summary as JSON")
    a = ap.parse_args(argv)
    res = sweep(a.config, a.methods.split(","), a.data)
    for part, s in res["summary"].items():
        for m, v in s.items():
            print(f"{part:4s} {m:15s} n={v['n']:2d} median {v['median_m']:5.2f} p90 {v['p90_m']:5.2f} "
                  f"worst {v['worst_m']:5.2f} ({v['worst_start_s']:.0f} s) >10 m: {v['over_10m']:2d} "
                  f"NEES>bound {v['nees_over_bound']:2d} ({100 * v['nees_over_share']:.1f} %) "
                  f"NEES median {v['nees_median']:.2f}")
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    sys.exit(main())
