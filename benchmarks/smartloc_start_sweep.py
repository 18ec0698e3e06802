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

``--before JSON``: a ``.json`` of an earlier run (another commit) shown beside this one.
``--librsf DIR``: libRSF's ``App_GNSS`` outputs ``DIR/out_<S>.txt`` for the input file cut
at each start (lines before ``S`` dropped), scored like ours: from ``S``, from ``S +
window`` (our filters' span) and on the common span (``librsf_scores``).
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


#: how the libRSF numbers were made (issue 34; issue 21's build was gone)
LIBRSF_BUILD = (
    "TUC-ProAut/libRSF at d54801a, built on this machine class against Debian 12's libceres-dev 2.1.0 "
    "(with libeigen3-dev 3.4.0, libyaml-cpp-dev 0.7.0, libgeographiclib-dev 2.1.2): one initializer added, "
    "`manifold_ownership`, in `include/FactorGraph.h`'s `Problem::Options` (Ceres 2.1 has that field), and "
    "`-DGeographicLib_LIBRARIES=/usr/lib/x86_64-linux-gnu/libGeographicLib.so` (its FindGeographicLib looks for "
    "`libGeographic`); nothing else changed. `App_GNSS config/Default_GNSS.yaml in_<S>.txt out_<S>.txt` with the "
    "config as shipped (the VB max-sum-mixture on `gnss_bias`, the 60 s window with marginalisation, solved "
    "every epoch, the newest state of each solve saved), on `Berlin_Potsdamer_Platz_Input.txt` without its lines "
    "before S. Its window solves are capped at 5 s of wall time and 200 iterations each (`max_time`, "
    "`max_iterations`); the longest here took 2.2 s and 153 iterations (start 30 s), so these runs stayed under "
    "the caps, but on a busier machine that run could reach the time cap and differ. Whole runs took 38-159 s. "
    "From 0 s it gives issue 21's 7.97 m (p95 12.9, max 14.4) again.")


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
    sweep.reference = inputs.reference
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


def librsf_scores(folder, starts, window: float, t_common: float, reference) -> dict:
    """libRSF's saved positions (``point3``-like rows: time, then ECEF x, y, z) of each start,
    2-D error in the local level frame of the reference at the reference's epochs (times
    matched to 1 ms): ``{start: {"own": ..., "filters_span": ..., "common": ...}}``."""
    from mixnav.geodesy.frames import ecef_to_lla, lla_to_ned
    out = {}
    for s in starts:
        f = Path(folder) / f"out_{s:g}.txt"
        if not f.is_file():
            continue
        rows = [ln.split() for ln in f.read_text().splitlines() if ln.startswith("point3 ")]
        t = np.array([float(r[1]) for r in rows])
        xyz = np.array([[float(v) for v in r[2:5]] for r in rows])
        ref_t = reference.time
        hi = np.clip(np.searchsorted(ref_t, t), 0, len(ref_t) - 1)
        lo = np.clip(hi - 1, 0, len(ref_t) - 1)
        idx = np.where(np.abs(ref_t[lo] - t) < np.abs(ref_t[hi] - t), lo, hi)     # the nearest epoch
        ok = np.abs(ref_t[idx] - t) < 1e-3
        t, xyz, idx = t[ok], xyz[ok], idx[ok]
        lla0 = reference.lla[0]
        d = lla_to_ned(ecef_to_lla(xyz), lla0)[:, :2] - lla_to_ned(reference.lla[idx], lla0)[:, :2]
        e = np.hypot(d[:, 0], d[:, 1])
        out[s] = {"own": _stats(e[t >= s]), "filters_span": _stats(e[t > s + window]),
                  "common": _stats(e[t >= t_common]), "from_s": float(t[0]) if t.size else float("nan")}
    return out


def summary(res: dict, key: str = "own") -> dict:
    """Per method: median and worst RMSE over the starts."""
    names = list(next(iter(res.values())))
    r = {}
    for n in names:
        v = np.array([res[s][n][key]["rmse_m"] for s in res])
        r[n] = {"median_m": float(np.median(v)), "worst_m": float(v.max()), "best_m": float(v.min())}
    return r


def report(res, aligns, t_common, starts, elapsed, before=None, librsf=None) -> list[str]:
    names = list(next(iter(res.values())))
    lines = [f"# smartLoc Berlin: the causal pipeline started at {', '.join(f'{v:g}' for v in starts)} s (issue 34)",
             "",
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
    if before is not None:
        b = before["results"]
        lines += ["## Before and after: 2-D RMSE [m] from each start (before -> after)", "",
                  f"Before: `{before.get('label', 'the earlier run')}`.", "",
                  "| method | " + " | ".join(f"start {s:g} s" for s in starts) + " | median | worst |",
                  "|---|" + "---|" * (len(starts) + 2)]
        sb = before.get("summary_own", {})
        sm = summary(res, "own")
        for n in names:
            if n not in sb:
                continue
            cells = [f"{b[str(s)][n]['own']['rmse_m']:.2f} -> **{res[s][n]['own']['rmse_m']:.2f}**"
                     if str(s) in b else f"**{res[s][n]['own']['rmse_m']:.2f}**" for s in starts]
            lines.append(f"| {n} | " + " | ".join(cells) + f" | {sb[n]['median_m']:.2f} -> {sm[n]['median_m']:.2f} | "
                         f"{sb[n]['worst_m']:.2f} -> {sm[n]['worst_m']:.2f} |")
        lines.append("")
    if librsf:
        lines += ["## libRSF App_GNSS (default VB max-sum-mixture, 60 s sliding window) on the same cut inputs", "",
                  "Its own start (a least-squares fix of its first epoch), scored from the cut (`from S`), on our "
                  "filters' span (`from S + 20 s`) and the common span; our best causal method (epoch-mixture, "
                  "`from S + 20 s`) beside it. 2-D RMSE [m] (p95 / max).", "",
                  "| start [s] | libRSF from S | libRSF from S + 20 s | libRSF common | epoch-mixture from S + 20 s | "
                  "epoch-mixture common |", "|---|---|---|---|---|---|"]
        fmt = (lambda r: f"**{r['rmse_m']:.2f}** ({r['p95_m']:.1f} / {r['max_m']:.1f})")
        got = [s for s in starts if s in librsf]
        for s in got:
            L, m = librsf[s], res[s].get("epoch-mixture")
            lines.append(f"| {s:g} | {fmt(L['own'])} | {fmt(L['filters_span'])} | {fmt(L['common'])} | "
                         + (f"{fmt(m['own'])} | {fmt(m['common'])} |" if m else "- | - |"))
        med = (lambda v: f"{np.median(v):.2f} / {max(v):.2f}")
        cols = [[librsf[s][k]["rmse_m"] for s in got] for k in ("own", "filters_span", "common")]
        if all("epoch-mixture" in res[s] for s in got):
            cols += [[res[s]["epoch-mixture"][k]["rmse_m"] for s in got] for k in ("own", "common")]
        lines += ["| median / worst | " + " | ".join(med(c) for c in cols) + " |", "",
                  f"libRSF: {LIBRSF_BUILD}", ""]
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
    ap.add_argument("--data", default=None, help="the smartloc-berlin data folder (default: the config's)")
    ap.add_argument("--config", default="smartloc-berlin")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--tag", default="smartloc_start_sweep")
    ap.add_argument("--before", default=None, help="a .json of an earlier run to show beside this one")
    ap.add_argument("--before-label", default=None, help="what the earlier run was (commit)")
    ap.add_argument("--librsf", default=None, help="folder of libRSF App_GNSS outputs out_<start>.txt")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    res, aligns, t_common = sweep(a.starts, a.methods, a.data, a.config)
    elapsed = time.perf_counter() - t0
    before = None
    if a.before:
        before = json.loads(Path(a.before).read_text())
        before["label"] = a.before_label or a.before
    window = t_common - max(a.starts)
    librsf = librsf_scores(a.librsf, a.starts, window, t_common, sweep.reference) if a.librsf else None
    lines = report(res, aligns, t_common, a.starts, elapsed, before, librsf)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{a.tag}.json").write_text(json.dumps(
        {"starts": a.starts, "common_from_s": t_common, "results": {str(k): v for k, v in res.items()},
         "summary_own": summary(res, "own"), "summary_common": summary(res, "common"),
         "alignment": {str(k): v for k, v in aligns.items()},
         **({"librsf": {str(k): v for k, v in librsf.items()}} if librsf else {})}, indent=1))
    (out / f"{a.tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
