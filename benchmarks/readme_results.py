"""The README's table of headline results, built from the results files (none copied by hand).

    python benchmarks/readme_results.py           # print the table
    python benchmarks/readme_results.py --write   # put it into README.md between its markers

Every number is read from a file under benchmarks/results/ or benchmarks/reproductions/
that a benchmark script regenerates; tests/test_readme.py fails when the README's table
and this script's output differ (rerun with ``--write`` after regenerating a results file).
Each row puts the peer beside mixnav like for like: the same epochs, causal beside causal
or online, smoother beside smoother; a row without a like-for-like peer says so.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"
START, END = "<!-- results: benchmarks/readme_results.py -->", "<!-- /results -->"


def _json(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def _md_row(path: Path, first_cell: str) -> list[str]:
    """The cells of the markdown table row of ``path`` whose first cell starts with ``first_cell``."""
    for line in path.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0].startswith(first_cell):
            return cells
    raise SystemExit(f"{path}: no table row starting with {first_cell!r}")


def rows() -> list[tuple[str, str, str, str, str]]:
    """(recording and test, mixnav method, mixnav, peer beside it, source) per headline."""
    sys.path.insert(0, str(HERE))
    from sweep_drive0708 import PEER
    out = []
    d = _json("outage_sweep_drive0708.json")
    s, n = d["summary"], d["settings"]["n_windows"]
    a, sm, ek = s["aided"], s["aided-smoothed"], s["ekf"]
    src = "[outage_sweep_drive0708.md](benchmarks/results/outage_sweep_drive0708.md)"
    out.append((f"drive-0708 (car, MEMS IMU, RTK), {n} GNSS outages of 30 s across the drive, one at a time: "
                "max horizontal error per outage, median / p90 / worst",
                "EKF + NHC/ZUPT/ZARU, causal",
                f"{a['median_horizontal_max_m']:.1f} / {a['p90_horizontal_max_m']:.1f} / "
                f"{a['worst_horizontal_max_m']:.1f} m (NEES out of band in {100 * a['share_nees_above_99']:.0f} %)",
                f"no peer result on these windows; mixnav's plain EKF {ek['median_horizontal_max_m']:.0f} / "
                f"{ek['p90_horizontal_max_m']:.0f} / {ek['worst_horizontal_max_m']:.0f} m", src))
    out.append(("the same outages", "the same, RTS smoother",
                f"{sm['median_horizontal_max_m']:.2f} / {sm['p90_horizontal_max_m']:.2f} / "
                f"{sm['worst_horizontal_max_m']:.2f} m", "-", src))
    pw = d["peer_windows"]["aided-smoothed"]
    out.append(("drive-0708, GNSS_IMU's three 30 s outages: max horizontal error", "the same, RTS smoother",
                " / ".join(f"{v:.2f}" for v in pw) + " m",
                "GNSS_IMU's smoother (published): " + " / ".join(f"{v:.2f}" for v in PEER["smoother"]) + " m", src))
    sl = _json("smartloc.json")["causal"]["epoch-mixture"]
    ss = _json("smartloc_start_sweep.json")
    lr0 = ss["librsf"]["0"]["filters_span"]
    src_s = "[smartloc.md](benchmarks/results/smartloc.md), [smartloc_start_sweep.md](benchmarks/results/smartloc_start_sweep.md)"
    out.append((f"smartLoc Berlin (urban canyon, odometry + GPS/GLONASS pseudoranges): 2-D RMSE (p95, max) from "
                f"{sl['from_s']:.0f} s, {sl['epochs']} epochs",
                "whole-epoch LOS/NLOS mixture, causal",
                f"{sl['rmse_m']:.2f} m ({sl['p95_m']:.1f}, {sl['max_m']:.1f})",
                f"libRSF VB max-sum-mixture, online (60 s window), same epochs: {lr0['rmse_m']:.2f} m "
                f"({lr0['p95_m']:.1f}, {lr0['max_m']:.1f})", src_s))
    own = ss["summary_own"]["epoch-mixture"]
    lr = [ss["librsf"][k]["filters_span"]["rmse_m"] for k in ss["librsf"]]
    lr_sorted = sorted(lr)
    lr_med = (lr_sorted[len(lr) // 2] + lr_sorted[(len(lr) - 1) // 2]) / 2
    starts = ", ".join(ss["librsf"])
    out.append((f"smartLoc, the whole causal pipeline started at {starts} s: 2-D RMSE median / worst",
                "the same", f"{own['median_m']:.2f} / {own['worst_m']:.2f} m",
                f"libRSF online on the same spans: {lr_med:.2f} / {max(lr):.2f} m", src_s))
    u = _json("urbannav_spp.json")["results"]["GPS+GLONASS+Galileo+BeiDou"]["methods"]["spp"]
    rk = [r for r in _json("rtklib_urbannav.json")["rows"]
          if r["version"] == "ex" and r["systems"] == "GPS+GLONASS+Galileo+BeiDou" and not r["raim"]][0]
    out.append(("urbannav-tst-static (u-blox F9P among high-rise buildings, GPS+GLONASS+Galileo+BeiDou, 15 deg "
                "mask): horizontal RMSE of single-point positioning, epochs solved",
                "plain SPP, every epoch",
                f"{u['h_rmse_m']:.1f} m, {u['epochs']} of 986",
                f"RTKLIB demo5 EX 2.5.1 rnx2rtkp, rerun here (same orbits, mask, atmosphere; its own weights): "
                f"{rk['h_rmse_m']:.1f} m, "
                f"{rk['epochs_solved']} of 986",
                "[urbannav_spp.md](benchmarks/results/urbannav_spp.md), "
                "[rtklib_urbannav.md](benchmarks/results/rtklib_urbannav.md)"))
    p4 = ROOT / "benchmarks" / "reproductions" / "P4_tables.md"
    em, imm = _md_row(p4, "EM-IMM"), _md_row(p4, "IMM (P4")
    out.append(("P4-vehicle (simulated, 50 runs): max horizontal error in the multipath episode",
                "EM-IMM (P4)", f"{em[2]} m", f"the IMM without the bias estimate: {imm[2]} m",
                "[P4_tables.md](benchmarks/reproductions/P4_tables.md)"))
    return out


def table() -> str:
    lines = ["| recording and test | mixnav method | mixnav | beside it | numbers |", "|---|---|---|---|---|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows()]
    return "\n".join(lines)


def _block(text: str):
    m = re.search(re.escape(START) + r"\n(.*?)" + re.escape(END), text, flags=re.S)
    if m is None:
        raise SystemExit(f"README.md has no block between {START} and {END}")
    return m


def readme_block(text: str) -> str:
    """The part of the README between the markers, without its last newline (a SystemExit
    naming the markers when absent)."""
    return _block(text).group(1).rstrip("\n")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--write", action="store_true", help="replace the README's block")
    a = ap.parse_args()
    t = table()
    if a.write:
        p = ROOT / "README.md"
        text = p.read_text()
        m = _block(text)
        p.write_text(text[:m.start(1)] + t + "\n" + text[m.end(1):])
    print(t)
    return 0


if __name__ == "__main__":
    sys.exit(main())
