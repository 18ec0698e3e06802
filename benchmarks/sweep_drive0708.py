"""drive-0708 over many outages: the outage sweep of the shipped aided configuration.

    python benchmarks/sweep_drive0708.py [--data DIR] [--workers 2] [--out benchmarks/results]

Runs :func:`mixnav.experiment.sweep.run_outage_sweep` on ``drive-0708-aided`` (the plain
EKF, the aided EKF with NHC/ZUPT/ZARU and its RTS smoother): 30 s GNSS windows every 10 s
from the alignment to the end of the drive, one withheld at a time, and beside it the
three windows the GNSS_IMU project published (``drive-0708``) and the dataset's own
three. Writes ``outage_sweep_drive0708.md`` and ``.json`` (every row, the per-method
distribution, the wall time of the whole sweep on ``--workers`` processes).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from datetime import datetime
from pathlib import Path

import numpy as np

from mixnav.config import load_dataset
from mixnav.experiment.pipelines import pipeline, process
from mixnav.experiment.sweep import NEES_POS_99, run_outage_sweep

#: GNSS_IMU's published maxima in its three windows (100-130, 250-280, 400-430 s) [m], as
#: benchmarks/bench_aiding_drive0708.py quotes them (its plain filter, ZUPT and smoother)
PEER = {"plain": (39.3, 25.3, 22.5), "zupt": (18.7, 5.2, 23.7), "smoother": (2.94, 3.37, 1.42)}


def own_windows(name: str, data: str | None) -> dict:
    """Each method's maximum in the dataset's own withheld windows [m]."""
    ds, source, _ = load_dataset(name)
    p = pipeline(ds, source)
    po = process(ds, source, data)
    return {m: [o["horizontal_max_m"] for o in v["outages"]] for m, v in p.metrics(po, p.tables(po)).items()}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    a = ap.parse_args()
    res = run_outage_sweep("drive-0708-aided", "30 s", "10 s", data=a.data, workers=a.workers)
    summary, st = res.summary, res.settings
    peer_rows = own_windows("drive-0708", a.data)
    own_rows = own_windows("drive-0708-aided", a.data)
    out = Path(a.out)
    doc = {"recorded": datetime.now().isoformat(timespec="minutes"), "machine": platform.machine(),
           "python": sys.version.split()[0], "cores": os.cpu_count(), "workers": a.workers,
           "settings": st, "summary": summary, "peer_windows": peer_rows, "own_windows": own_rows,
           "rows": res.rows.to_dict(orient="records")}
    (out / "outage_sweep_drive0708.json").write_text(json.dumps(doc, indent=1) + "\n")
    L = ["# drive-0708 over many outages (benchmarks/sweep_drive0708.py)", "",
         f"Recorded {doc['recorded']} on {doc['machine']} ({doc['cores']} cores), {a.workers} worker processes. "
         f"`mixnav process drive-0708-aided --outage-sweep \"30 s\" --sweep-step \"10 s\"`: {st['n_windows']} windows "
         f"of 30 s every 10 s from {st['span_s'][0]:g} s (the alignment ends at {st['aligned_at_s']:.1f} s) to "
         f"{st['span_s'][1]:.1f} s, each withheld alone; the errors are the antenna's against the withheld RTK "
         "fixes (fixed only) in the window and in the unaided stretch after it. Causal methods (ekf, aided) and "
         "the smoother (aided-smoothed) are each their own row. A window is out of band when its mean position "
         f"NEES is above the chi-square(3) 99 % point ({NEES_POS_99:.2f}).", "",
         f"The whole sweep took **{st['wall_time_s']:.1f} s** (read once, {st['n_windows'] + 1} runs of three "
         "methods).", "",
         "| method | windows | median max [m] | p90 [m] | worst [m] (window start) | median RMSE [m] | NEES out of band |",
         "|---|---|---|---|---|---|---|"]
    for name, b in summary.items():
        share = b.get("share_nees_above_99")
        L.append(f"| {name} | {b['n_windows']} | {b['median_horizontal_max_m']:.2f} | {b['p90_horizontal_max_m']:.2f} "
                 f"| {b['worst_horizontal_max_m']:.2f} ({b['worst_window_start_s']:g} s) | "
                 f"{b['median_horizontal_rmse_m']:.2f} | {'-' if share is None else f'{100 * share:.0f} %'} |")
    L += ["", "## Beside the fixed windows", "",
          "| method | GNSS_IMU's windows 100-130 / 250-280 / 400-430 s [m] | the dataset's own 133-163 / 228-258 / "
          "363-393 s [m] | sweep median / p90 / worst [m] |", "|---|---|---|---|"]
    for name, b in summary.items():
        L.append(f"| {name} | {' / '.join(f'{v:.2f}' for v in peer_rows[name])} | "
                 f"{' / '.join(f'{v:.2f}' for v in own_rows[name])} | {b['median_horizontal_max_m']:.2f} / "
                 f"{b['p90_horizontal_max_m']:.2f} / {b['worst_horizontal_max_m']:.2f} |")
    for k, v in PEER.items():
        L.append(f"| GNSS_IMU {k} (published, its windows only) | {' / '.join(f'{x:.2f}' for x in v)} | - | - |")
    aided = res.rows[res.rows.method == "aided"].set_index("start_s")["horizontal_max_m"]
    plain = res.rows[res.rows.method == "ekf"].set_index("start_s")["horizontal_max_m"]
    L += ["", f"The aided filter beats the plain one in {int((aided < plain).sum())} of {len(aided)} windows; "
          f"its worst windows start at {', '.join(f'{t:g} s' for t in aided.sort_values().index[-3:][::-1])}.", "",
          "## Every window", "",
          "| start [s] | " + " | ".join(f"{m} max [m] / NEES" for m in summary) + " | distance [m] | course change "
          "[deg] | still [s] |", "|---" * (len(summary) + 4) + "|"]
    for t0, g in res.rows.groupby("start_s"):
        g = g.set_index("method")
        first = g.iloc[0]
        L.append(f"| {t0:g} | " + " | ".join(f"{g.loc[m, 'horizontal_max_m']:.2f} / {g.loc[m, 'nees_pos_mean']:.1f}"
                                              for m in summary)
                 + f" | {first['distance_m']:.0f} | {first['heading_change_deg']:.0f} | {first['still_s']:.1f} |")
    (out / "outage_sweep_drive0708.md").write_text("\n".join(L) + "\n")
    print("\n".join(L[:20]))
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main())
