"""drive-0708: accuracy in the three withheld windows, and processing speed.

    python benchmarks/bench_drive0708.py      # writes benchmarks/results/drive-0708.{json,md}

Wall time includes reading the files (IMU CSV + tag, RTKLIB .pos twice: as
GNSS input and as reference); the real-time factor is the processed span
(from the in-motion alignment to the end) over that wall time. Best of 3.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from _timing import best_of
from mixnav.config import load_dataset
from mixnav.experiment.process import process
from mixnav.experiment.run import method_metrics, solution_table

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MIXNAV_DATA", ROOT.parent / "shared" / "data")) / "drive-0708"
RESULTS = ROOT / "benchmarks" / "results"


def main():
    ds, src, _ = load_dataset("drive-0708-plain")
    # the first call warms up numba's cache
    wall, po = best_of(lambda: process(ds, src, str(DATA)), 3, warmup=True)
    res = po.results["ekf"]
    table = solution_table(res, po.reference, ds.gnss.withhold, lever=po.lever)
    m = method_metrics(res, table, ds.gnss.withhold)
    span = float(po.imu.time[-1] - po.init.time)
    out = {"date": time.strftime("%Y-%m-%d %H:%M"), "processed_span_s": span, "record_s": float(po.imu.time[-1]),
           "wall_time_s": wall, "read_time_s": po.read_time_s, "filter_time_s": po.filter_time_s,
           "real_time_factor": span / wall, "gnss_epochs_used": m["measurement_epochs"],
           "epoch_time_mean_us": m["epoch_time_mean_us"],
           "outages": [{"window_s": [o["start_s"], o["end_s"]], "horizontal_max_m": o["horizontal_max_m"],
                        "vertical_max_m": o["vertical_max_m"]} for o in m["outages"]],
           "horizontal_rmse_outside_outages_m": m["horizontal_rmse_outside_outages_m"],
           "vertical_rmse_outside_outages_m": m["vertical_rmse_outside_outages_m"],
           "velocity_rmse_mps": m["velocity_rmse_mps"], "nis_per_dof_mean": m["nis_mean_per_dof"],
           "nis_per_dof_median": float(np.median(res.nis / res.nis_dim)), "recoveries": m["recoveries"]}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "drive-0708.json").write_text(json.dumps(out, indent=2) + "\n")
    md = ["# drive-0708, loose EKF, three 30 s GNSS outages (benchmarks/bench_drive0708.py)", "",
          f"Recorded {out['date']}. Reference: the withheld RTK fixed solutions (antenna point).", "",
          "| window [s] | max horizontal error [m] | max vertical error [m] |", "| --- | --- | --- |"]
    md += [f"| {o['window_s'][0]:g}-{o['window_s'][1]:g} | {o['horizontal_max_m']:.2f} | {o['vertical_max_m']:.2f} |"
           for o in out["outages"]]
    md += ["", "| quantity | value |", "| --- | --- |"]
    md += [f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in out.items()
           if k not in ("outages", "date")]
    (RESULTS / "drive-0708.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
