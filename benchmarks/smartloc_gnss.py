"""smartLoc Berlin Potsdamer Platz as GNSS alone, scored against its moving ground truth (issue 36).

Workload: the shipped dataset ``smartloc-berlin-gnss`` (a car among tall buildings, 283 s,
GPS + GLONASS pseudoranges at about 5 Hz, already corrected in the file; 1372 epochs), run
through the gnss-raw pipeline (:mod:`mixnav.experiment.spp_process`, ``[raw_gnss] format =
"smartloc"``): the plain and the robust SPP and the constant-velocity filters of
urbannav-tst-static, every epoch scored against the data set's ground truth at its time
(``[reference] format = "smartloc"``). Every setting's source is in the dataset file (the
constant-velocity model's acceleration density from the odometry's velocity changes, not
from the ground truth). Horizontal errors in a local frame at each truth point.

The run is timed once (wall and CPU, imports done): the machine is shared, so the times are
indicative only.

Writes benchmarks/results/smartloc_gnss.md and .json. Run: python benchmarks/smartloc_gnss.py
"""

from __future__ import annotations

import datetime as dt
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mixnav import __version__  # noqa: E402
from mixnav.config.loader import load_dataset  # noqa: E402
from mixnav.experiment.data_folder import find_data_dir  # noqa: E402
from mixnav.experiment.spp_process import method_metrics, process_raw, raw_tables  # noqa: E402

OUT = ROOT / "benchmarks" / "results"
KEYS = ("horizontal_rmse_m", "horizontal_median_m", "horizontal_p95_m", "horizontal_max_m", "error_3d_rmse_m")


def main() -> None:
    ds, src, _ = load_dataset("smartloc-berlin-gnss")
    folder = find_data_dir(ds, None, src)
    w0, c0 = time.perf_counter(), time.process_time()
    po = process_raw(ds, src, folder)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    tables = raw_tables(po)
    methods = {n: method_metrics(po, n, t) for n, t in tables.items()}
    counts = po.reference.counts
    stamp = dt.datetime.now(dt.timezone.utc).replace(microsecond=0).isoformat()
    lines = ["# smartLoc Berlin Potsdamer Platz, GNSS alone, scored against its moving ground truth (issue 36)", "",
             f"Made by `benchmarks/smartloc_gnss.py` ({stamp}, mixnav {__version__}, Python "
             f"{platform.python_version()}, {platform.machine()}). Data: `smartloc-berlin-gnss` "
             "(src/mixnav/config/datasets/smartloc-berlin-gnss.toml: GPS + GLONASS pseudoranges corrected in "
             "the file, weighted by its variances, no elevation mask; the filters on the constant-velocity "
             "model with 0.7 m/s^2/sqrt(Hz) horizontal, from the odometry's velocity changes). "
             f"{len(po.track.tow)} epochs; reference epochs: {counts['scored']} scored, {counts['before_reference']} "
             f"before the ground truth, {counts['after_reference']} after it, {counts['in_reference_gaps']} in gaps "
             "longer than 1 s. Errors in metres over the solved epochs scored; availability = solved epochs / "
             "epochs. Nothing was chosen by its error against the ground truth.", "",
             "| method | solved | avail. | scored | h RMSE | median | p95 | max | 3-D RMSE |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for n, m in methods.items():
        lines.append(f"| {n} | {m['n_epochs']} | {100 * m['availability']:.1f} % | {m['n_scored']} | "
                     + " | ".join(f"{m[k]:.2f}" for k in KEYS) + " |")
    lines += ["", f"Whole run (read, SPP, robust SPP, every filter and smoother): {wall:.1f} s wall, {cpu:.1f} s CPU "
              "(one run on a shared machine).", "",
              "Context, not like for like: the same drive with the car's odometry (dead reckoning corrected "
              "by the same pseudoranges: the odometry-gnss dataset smartloc-berlin, smartloc.md) starts "
              "after a 20 s alignment and is scored from there, with wheel speed and yaw rate that GNSS "
              "alone lacks. Here the non-line-of-sight delays of the street canyon (tens of metres, "
              "positive) are most of the error, and the 3-D RMSE is mostly the vertical error "
              "(`vertical_rmse_m` per method in the .json).", ""]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "smartloc_gnss.md").write_text("\n".join(lines))
    (OUT / "smartloc_gnss.json").write_text(json.dumps({"made": stamp, "wall_s": wall, "cpu_s": cpu,
                                                        "reference_epochs": counts, "methods": methods},
                                                       indent=1, default=float))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
