"""Land-vehicle aiding on drive-0708: accuracy in the withheld windows and cost, side by side.

    python benchmarks/bench_aiding_drive0708.py [--data DIR]

Runs the shipped dataset configs ``drive-0708`` (the GNSS_IMU project's
windows) and ``drive-0708-aided`` (mixnav's shipped windows); each holds the plain
EKF and the aided EKF (NHC 10 Hz, ZUPT, ZARU) with its RTS smoother. Writes
benchmarks/results/aiding_drive0708.md: maximum horizontal error and mean
position/velocity NEES per window, NIS/dof per kind, and the filter and smoother
times against the plain EKF's in the same process (best of 3).
"""

from __future__ import annotations

import sys
from datetime import datetime
from pathlib import Path

import numpy as np

from _timing import best_time
from mixnav.api import process_dataset
from mixnav.engine.smoother import rts_smooth
from mixnav.experiment.process import process
from mixnav.config import load_dataset

PEER = {"plain": (39.3, 25.3, 22.5), "zupt": (18.7, 5.2, 23.7), "smoother": (2.94, 3.37, 1.42)}
CHI2_99_3 = 11.345  # chi-square(3) 99 % quantile: the share of epochs above it is reported
CASES = {"drive-0708": ((100, 130), (250, 280), (400, 430)),
         "drive-0708-aided": ((133, 163), (228, 258), (363, 393))}


def window_rows(r, wins):
    rows = []
    for name, t in r.solutions.items():
        cells = []
        for a, b in wins:
            s = t[(t.time_s >= a) & (t.time_s <= b)]
            cells.append((float(np.hypot(s.err_n_m, s.err_e_m).max()), float(s.nees_pos.mean()),
                          float(np.mean(s.nees_pos > CHI2_99_3)), float(s.nees_vel.mean())))
        rows.append((name, cells))
    return rows


def timing(name, data):
    """Best-of-3 forward time of each method and the backward pass, one process."""
    ds, src, _ = load_dataset(name)
    best = {}
    for _ in range(3):
        po = process(ds, src, data)
        for m, res in po.results.items():
            if m.endswith("-smoothed"):
                continue
            best[m] = min(best.get(m, np.inf), res.timing["wall_time_s"])
    # the backward pass alone, on a result with its history
    from mixnav.experiment import methods
    m = next(x for x in ds.methods if x.smooth)
    from mixnav.experiment.aiding import AidingInputs
    aid = AidingInputs(ds.aiding, po.imu, po.fixes, po.init.time, float(po.imu.time[-1]), source=src)
    from mixnav.config.loader import imu_model
    model = imu_model(ds.imu.grade, ds.imu.errors, src, "imu.errors", "imu.grade")
    filt, meas = methods.build(m, model, po.fixes, po.lever, src, 1, aiding=aid)
    out_t = po.results[m.name].time
    res = filt.run(po.imu, po.init, meas, output_times=out_t, history=True)
    bw = best_time(lambda: rts_smooth(res), 3)
    duration = float(po.imu.time[-1] - po.init.time)
    return best, bw, duration, res.timing["wall_time_s"]


def main():
    data = sys.argv[sys.argv.index("--data") + 1] if "--data" in sys.argv else None
    lines = ["# Land-vehicle aiding on drive-0708 (benchmarks/bench_aiding_drive0708.py)", "",
             f"Recorded {datetime.now():%Y-%m-%d %H:%M}. Errors are the antenna against the withheld RTK "
             "fixes (fixed only) inside each window; NEES is the mean over the window's reference epochs "
             "(3 dof each; in brackets the share of epochs above the chi-square(3) 99 % bound, 11.3); the "
             "velocity NEES is against the reference velocity put at its epochs ([reference] velocity_delay).",
             ""]
    for name, wins in CASES.items():
        r = process_dataset(name, data)
        lines += [f"## {name}", "", "| method | " + " | ".join(f"{a}-{b} s: max [m] / NEES pos (> chi2 99 %) / NEES vel"
                                                              for a, b in wins) + " |",
                  "|---|" + "---|" * len(wins)]
        for m, cells in window_rows(r, wins):
            lines.append(f"| {m} | " + " | ".join(f"{e:.2f} / {p:.1f} ({100 * f:.0f} %) / {v:.1f}"
                                                   for e, p, f, v in cells) + " |")
        if name == "drive-0708":
            for k, v in PEER.items():
                lines.append(f"| GNSS_IMU {k} (published) | " + " | ".join(f"{x:.2f}" for x in v) + " |")
        lines += ["", "NIS/dof per kind (aided):", ""]
        res = r.results["aided"]
        for k in np.unique(res.nis_kind):
            s = res.nis_kind == k
            lines.append(f"- {k}: {res.nis[s].sum() / res.nis_dim[s].sum():.2f} ({int(s.sum())} epochs)")
        best, bw, duration, fw_hist = timing(name, data)
        lines += ["", "| cost (best of 3, one process) | time [s] | x real time |", "|---|---|---|"]
        for m, w in best.items():
            lines.append(f"| {m} filter | {w:.3f} | {duration / w:.0f} |")
        lines.append(f"| aided filter with history | {fw_hist:.3f} | {duration / fw_hist:.0f} |")
        lines.append(f"| aided smoother backward pass | {bw:.3f} | backward / forward {bw / fw_hist:.2f} |")
        lines.append(f"| aided filter + smoother | {fw_hist + bw:.3f} | {duration / (fw_hist + bw):.0f} |")
        lines.append("")
    out = Path(__file__).resolve().parent / "results" / "aiding_drive0708.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
