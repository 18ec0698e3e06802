"""The shipped smartloc-berlin pipeline started at several times (issue 34).

Run:  PYTHONPATH=src python benchmarks/smartloc_start_sweep.py [--starts 0 30 60 90 120 150]
      [--methods epoch-mixture ...] [--data ../shared/data] [--out benchmarks/results]

For each start ``S`` the config's ``[alignment] start = S`` discards the odometry and the
pseudoranges before ``S`` (:func:`mixnav.experiment.vehicle_process.discard_before`); the
causal track alignment then runs on ``[S, S + window]`` and the filters from its end, so
every start is the shipped causal pipeline on a recording that began at ``S``. Each
method is scored (2-D error, estimate minus reference at the reference's epochs) from
its own start to the end, and on the span every start covers (``max(starts) + window``
to the end). The file's times begin at 0 s. Writes ``smartloc_start_sweep.md`` and
``.json`` into ``--out`` (``--tag`` names them otherwise, for a before/after pair).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from mixnav.config.loader import load_dataset
from mixnav.experiment.data_folder import find_data_dir
from mixnav.experiment.vehicle_process import read_vehicle, run_vehicle, vehicle_tables


def _stats(e: np.ndarray) -> dict:
    e = e[np.isfinite(e)]
    if not e.size:
        return {"rmse_m": float("nan"), "p95_m": float("nan"), "max_m": float("nan"), "epochs": 0}
    return {"rmse_m": float(np.sqrt(np.mean(e ** 2))), "p95_m": float(np.percentile(e, 95)),
            "max_m": float(e.max()), "epochs": int(e.size)}


def sweep(starts, methods=None, data=None, config="smartloc-berlin") -> tuple[dict, dict, float]:
    """``{start: {method: {"own": stats, "common": stats, "from_s": t}}}``, the alignment
    reports per start, and the common span's first time."""
    ds, source, _ = load_dataset(config)
    if methods:
        ds = ds.model_copy(update={"methods": [m for m in ds.methods if m.name in methods]})
    folder = find_data_dir(ds, data, source)
    inputs = read_vehicle(ds, source, folder)
    t_common = max(starts) + float(ds.alignment.window)
    out, aligns = {}, {}
    for s in starts:
        d = ds.model_copy(update={"alignment": ds.alignment.model_copy(update={"start": float(s)})})
        vo = run_vehicle(d, source, folder, inputs)
        aligns[s] = {k: v for k, v in vo.alignment.items() if not isinstance(v, list)}
        row = {}
        for name, t in vehicle_tables(vo).items():
            e = np.hypot(t["err_n_m"], t["err_e_m"]).to_numpy()
            tt = t["time_s"].to_numpy()
            row[name] = {"own": _stats(e), "common": _stats(e[tt >= t_common]), "from_s": float(tt[0])}
        out[s] = row
    return out, aligns, t_common


def summary(res: dict, key: str = "own") -> dict:
    """Per method: median and worst RMSE over the starts."""
    names = list(next(iter(res.values())))
    r = {}
    for n in names:
        v = np.array([res[s][n][key]["rmse_m"] for s in res])
        r[n] = {"median_m": float(np.median(v)), "worst_m": float(v.max()), "best_m": float(v.min())}
    return r


def report(res, aligns, t_common, starts, elapsed) -> list[str]:
    names = list(next(iter(res.values())))
    lines = ["# smartLoc Berlin: the causal pipeline started every 30 s (issue 34)", "",
             f"Produced by `benchmarks/smartloc_start_sweep.py` ({platform.machine()}, Python "
             f"{platform.python_version()}; {elapsed:.0f} s). Config: the shipped `smartloc-berlin` with "
             "`[alignment] start = S`: data before S discarded, the track alignment on [S, S + 20 s], the filters "
             "from its end. 2-D error against the reference. **own**: scored from each filter's start to the end; "
             f"**common**: scored on {t_common:g} s to the end (every start covers it). Numbers: the `.json`.", ""]
    for key, title in (("own", "From each start"), ("common", f"Common span ({t_common:g} s to the end)")):
        lines += [f"## {title}: 2-D RMSE [m] (p95 / max)", "",
                  "| method | " + " | ".join(f"start {s:g} s" for s in starts) + " | median | worst |",
                  "|---|" + "---|" * (len(starts) + 2)]
        sm = summary(res, key)
        for n in names:
            cells = [f"**{res[s][n][key]['rmse_m']:.2f}** ({res[s][n][key]['p95_m']:.1f} / "
                     f"{res[s][n][key]['max_m']:.1f})" for s in starts]
            lines.append(f"| {n} | " + " | ".join(cells) + f" | {sm[n]['median_m']:.2f} | {sm[n]['worst_m']:.2f} |")
        lines.append("")
    lines += ["## Alignment per start", "", "| start [s] | " + " | ".join(k for k in aligns[starts[0]] if k != "mode")
              + " |", "|---|" + "---|" * (len(aligns[starts[0]]) - 1)]
    for s in starts:
        a = aligns[s]
        lines.append(f"| {s:g} | " + " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v)
                                               for k, v in a.items() if k != "mode") + " |")
    return lines


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=float, nargs="+", default=[0, 30, 60, 90, 120, 150])
    ap.add_argument("--methods", nargs="*", default=None, help="method names of the config (default: all)")
    ap.add_argument("--data", default=None, help="folder holding smartloc-berlin/ (default: the config's)")
    ap.add_argument("--config", default="smartloc-berlin")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--tag", default="smartloc_start_sweep")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    res, aligns, t_common = sweep(a.starts, a.methods, a.data, a.config)
    elapsed = time.perf_counter() - t0
    lines = report(res, aligns, t_common, a.starts, elapsed)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{a.tag}.json").write_text(json.dumps(
        {"starts": a.starts, "common_from_s": t_common, "results": {str(k): v for k, v in res.items()},
         "summary_own": summary(res, "own"), "summary_common": summary(res, "common"),
         "alignment": {str(k): v for k, v in aligns.items()}}, indent=1))
    (out / f"{a.tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
