"""``mixnav tune`` on raw-GNSS recordings (issue 35, "Other recordings"): default against tuned,
scored against the reference only afterwards.

    python benchmarks/tune_raw_gnss.py [--budget 60] [--workers 1] [--only NAME] [--markdown]

For each recording (the phone's static log, the u-blox static log among high-rises, the
smartLoc drive as GNSS alone) three files are processed and scored:

- ``untuned``: the shipped dataset file with its ``[motion]`` noise keys (``accel_sigma``,
  ``vertical_accel_sigma``, ``clock_q_bias``, ``clock_q_drift``) taken out, so the schema's
  defaults apply: what a new user's file holds;
- ``tuned``: ``mixnav tune`` run on the untuned file (no reference read; the tuned method is
  the tool's default, the first epoch mixture);
- ``shipped``: the shipped file, whose values are documented a-priori choices (a static
  receiver, the smartLoc odometry's velocity changes).

Every filter method's 2-D error is scored on its own epochs, and the plain SPP of the same
file on the same epochs beside it ("never worse than the plain SPP on the same epochs").

The start sweep (``mixnav.start_sweep``, ``[motion] start``; the tuner scored its candidates
from its own starts, this asks whether the values hold from others): each of the three files
run from the starts of :data:`SWEEP_STEP` over the first half of the recording, every method
scored on the common span (from the latest filter start to the end: the same epochs for every
start and file); per method the median and worst RMSE over the starts, whether tuned is at
most shipped on both, and the tuned values with the comments ``mixnav tune`` wrote (a
proposal for the shipped file; this script changes none).

The wall time of the tuning itself, one worker, before and after the SPP stage was cached, is
benchmarks/tune_raw_speed.py's (its table is copied in when its results file exists).
Writes benchmarks/results/tune_raw_gnss.{json,md}.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import tomlkit

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATASETS = ROOT / "src" / "mixnav" / "config" / "datasets"
RECORDINGS = ("android-static-filters", "urbannav-tst-static", "smartloc-berlin-gnss")
MOTION_NOISE = ("accel_sigma", "vertical_accel_sigma", "clock_q_bias", "clock_q_drift")
#: the start sweep's step per recording [s]: about eight starts over the first half
SWEEP_STEP = {"android-static-filters": 15.0, "urbannav-tst-static": 60.0, "smartloc-berlin-gnss": 20.0}


def untuned_text(name: str) -> str:
    """The shipped file without its motion noise keys, its data folder made absolute."""
    doc = tomlkit.parse((DATASETS / f"{name}.toml").read_text())
    for k in MOTION_NOISE:
        doc["motion"].pop(k, None)
    data_dir = doc["dataset"]["data_dir"]
    doc["dataset"]["data_dir"] = str((ROOT / data_dir).resolve()) if not Path(data_dir).is_absolute() else data_dir
    return tomlkit.dumps(doc)


def scores(result) -> dict:
    """Per filter method: its epochs, 2-D RMSE / p95 / max, and the plain SPP's on the same epochs."""
    sol = result.solutions
    spp = sol["spp"]
    spp_h = np.hypot(spp["err_n_m"].to_numpy(float), spp["err_e_m"].to_numpy(float))
    out = {}
    for name, t in sol.items():
        if name in ("spp", "robust-spp"):
            continue
        h = np.hypot(t["err_n_m"].to_numpy(float), t["err_e_m"].to_numpy(float))
        ok = np.isfinite(h) & np.isfinite(spp_h)
        if not ok.any():
            continue
        rm = lambda x: float(np.sqrt(np.mean(x ** 2)))  # noqa: E731
        out[name] = {"epochs": int(ok.sum()), "rmse_m": rm(h[ok]), "p95_m": float(np.percentile(h[ok], 95)),
                     "max_m": float(h[ok].max()), "spp_rmse_m": rm(spp_h[ok]),
                     "spp_p95_m": float(np.percentile(spp_h[ok], 95))}
    return out


def sweep(path, name: str) -> dict:
    """Per method: the starts, and the median / worst over them of the RMSE on the common span
    and from each run's own start (``name``: the recording, for its step)."""
    import mixnav
    rows = mixnav.start_sweep(str(path), step=SWEEP_STEP[name], workers=1)
    out = {}
    for m, g in rows.groupby("method", sort=False):
        c, r = g["common_horizontal_rmse_m"].to_numpy(float), g["horizontal_rmse_m"].to_numpy(float)
        out[str(m)] = {"starts_s": g["start_s"].tolist(), "common_start_s": float(g["common_start_s"].iloc[0]),
                       "median_common_rmse_m": float(np.median(c)), "worst_common_rmse_m": float(c.max()),
                       "median_rmse_m": float(np.median(r)), "worst_rmse_m": float(r.max())}
    return out


def main(argv) -> None:
    import mixnav
    if "--markdown" in argv:   # the results file's markdown again, from its JSON
        (HERE / "results" / "tune_raw_gnss.md").write_text(markdown(json.loads(
            (HERE / "results" / "tune_raw_gnss.json").read_text())))
        return
    budget = int(argv[argv.index("--budget") + 1]) if "--budget" in argv else 60
    workers = int(argv[argv.index("--workers") + 1]) if "--workers" in argv else 1
    only = argv[argv.index("--only") + 1] if "--only" in argv else None
    out_json = HERE / "results" / "tune_raw_gnss.json"
    res = {"budget": budget, "workers": workers, "recordings": {}}
    if only:   # that recording again, the others kept from the results file
        res = json.loads(out_json.read_text())
        if (res["budget"], res["workers"]) != (budget, workers):
            raise SystemExit(f"--only: the results file is of --budget {res['budget']} --workers {res['workers']}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in [only] if only else RECORDINGS:
            src = Path(tmp) / f"{name}-untuned.toml"
            src.write_text(untuned_text(name))
            t0 = time.perf_counter()
            tr = mixnav.tune(src, Path(tmp) / f"tune-{name}", budget=budget, workers=workers)
            wall = time.perf_counter() - t0
            tuned = Path(tmp) / f"tune-{name}" / "tuned.toml"
            rec = {"tune_wall_s": wall, "filter_runs": tr.runs, "evaluations": len(tr.evaluations),
                   "method": json.loads((Path(tmp) / f"tune-{name}" / "tune.json").read_text())["method"],
                   "criterion_given": tr.given["criterion"], "criterion_tuned": tr.tuned["criterion"],
                   "chosen": {k: c["value"] for k, c in tr.chosen.items()},
                   "spread": {k: c.get("spread") for k, c in tr.chosen.items()}}
            rec["tuned_toml"] = tuned.read_text()
            for variant, path in (("untuned", src), ("tuned", tuned), ("shipped", name)):
                rec[variant] = scores(mixnav.process_dataset(path))
                rec[f"{variant}_sweep"] = sweep(path, name)
                print(name, variant, "swept", flush=True)
            res["recordings"][name] = rec
            print(name, "done", f"{wall:.0f} s", flush=True)
    res["load_average"] = os.getloadavg()
    out_json.write_text(json.dumps(res, indent=1) + "\n")
    (HERE / "results" / "tune_raw_gnss.md").write_text(markdown(res))
    print(markdown(res))


def markdown(res: dict) -> str:
    lines = ["# mixnav tune on raw-GNSS recordings: untuned, tuned, shipped (issue 35)", "",
             f"`benchmarks/tune_raw_gnss.py --budget {res['budget']} --workers {res['workers']}` (load average at "
             f"the end {' '.join(f'{x:.2f}' for x in res['load_average'])}, 2 shared cores). `untuned`: the "
             "shipped file without its `[motion]` noise keys (the schema's defaults); `tuned`: `mixnav tune` on "
             "it (the innovation log-likelihood over several starts; no reference read); `shipped`: the shipped "
             "file (a-priori values, each documented in it). Scored afterwards against the reference: 2-D RMSE / "
             "p95 / max over the method's epochs, and the plain SPP of the same file on the same epochs. The tuner "
             "scores the tuned method alone; the file's other filters run with the `[motion]` values tuned for it. "
             "Why the plain EKF among the high-rises is no better than the SPP, tuned by its own likelihood or not: "
             "`benchmarks/results/tune_raw_ekf_urban.md`.", ""]
    for name, rec in res["recordings"].items():
        lines += [f"## {name}", "",
                  f"Tuned method `{rec['method']}`; {rec['evaluations']} evaluations, {rec['filter_runs']} pipeline "
                  f"runs, {rec['tune_wall_s']:.0f} s; criterion {rec['criterion_given']:.4f} -> "
                  f"{rec['criterion_tuned']:.4f} (minus the log-likelihood per row).", "",
                  "Chosen: " + "; ".join(f"`{k}` = {v} (spread {rec['spread'][k] or '-'})"
                                         for k, v in rec["chosen"].items()), "",
                  "| method | epochs | untuned RMSE / p95 / max | tuned | shipped | plain SPP, same epochs (RMSE / p95) |"
                  " tuned worse than SPP? |",
                  "|---|---:|---|---|---|---|---|"]
        for m, t in rec["tuned"].items():
            def cell(v, m=m):
                s = rec[v].get(m)
                return "-" if s is None else f"{s['rmse_m']:.2f} / {s['p95_m']:.2f} / {s['max_m']:.1f}"
            lines.append(f"| {m} | {t['epochs']} | {cell('untuned')} | {cell('tuned')} | {cell('shipped')} | "
                         f"{t['spp_rmse_m']:.2f} / {t['spp_p95_m']:.2f} | "
                         f"{'yes' if t['rmse_m'] > t['spp_rmse_m'] else 'no'} |")
        lines.append("")
        if "tuned_sweep" in rec:
            lines += sweep_table(rec, name)
    speed = HERE / "results" / "tune_raw_speed.md"
    if speed.exists():
        lines += ["## Wall time of the tuning, one worker (copied from `benchmarks/results/tune_raw_speed.md`)", "",
                  *speed.read_text().splitlines()[2:], ""]
    return "\n".join(lines) + "\n"


def sweep_table(rec: dict, name: str) -> list[str]:
    """The start sweep of one recording: per method median / worst common-span RMSE over the
    starts for the three files, and whether tuned is at most shipped on both."""
    tw = rec["tuned_sweep"]
    any_m = next(iter(tw.values()))
    lines = [f"Start sweep: starts {', '.join(f'{x:g}' for x in any_m['starts_s'])} s (step {SWEEP_STEP[name]:g} s), "
             f"scored on the common span from {any_m['common_start_s']:.0f} s to the end (the same epochs for every "
             "start and file). Median / worst RMSE over the starts [m]:", "",
             "| method | untuned | tuned | shipped | tuned <= shipped (median, worst)? |", "|---|---|---|---|---|"]
    for m, t in tw.items():
        def cell(v, m=m):
            s = rec[f"{v}_sweep"].get(m)
            return "-" if s is None else f"{s['median_common_rmse_m']:.2f} / {s['worst_common_rmse_m']:.2f}"
        sh = rec["shipped_sweep"].get(m)
        ok = "-" if sh is None else ("yes" if at_most(t, sh) else "no")
        lines.append(f"| {m} | {cell('untuned')} | {cell('tuned')} | {cell('shipped')} | {ok} |")
    filters = [m for m in tw if m in rec["shipped_sweep"] and m not in ("spp", "robust-spp")]
    good = [m for m in filters if at_most(tw[m], rec["shipped_sweep"][m])]
    target = rec["method"]
    lines += ["", f"Tuned at most shipped (median and worst over the starts): the tuned method `{target}` "
              f"{'yes' if target in good else 'no'}; {len(good)} of {len(filters)} filters "
              f"({', '.join(good) or 'none'}). The tuned values, with the comments `mixnav tune` wrote "
              "(a proposal: no shipped file is changed here):", "", "```toml"]
    lines += tuned_lines(rec["tuned_toml"], target) + ["```", ""]
    return lines


def at_most(a: dict, b: dict) -> bool:
    """Median and worst common-span RMSE of ``a`` at most those of ``b``."""
    return a["median_common_rmse_m"] <= b["median_common_rmse_m"] and a["worst_common_rmse_m"] <= b["worst_common_rmse_m"]


def tuned_lines(text: str, target: str) -> list[str]:
    """The lines of a tuned.toml that ``mixnav tune`` wrote (a comment of its own), under their
    table (a method's table: of the tuned method ``target``)."""
    out, table = [], None
    for ln in text.splitlines():
        if ln.startswith("["):
            table = ln
        elif "# mixnav tune:" in ln:
            if table is not None:
                out.append(table + (f"   # of the [[methods]] named \"{target}\"" if table.startswith("[methods")
                                    else ""))
                table = None
            out.append(ln)
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
