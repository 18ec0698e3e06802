"""Monte Carlo reproduction of paper P3 (GMPF against the particle filter) on P3-flight.

    python benchmarks/reproductions/make_p3.py [--runs 50] [--workers 2] [--out DIR]
                                               [--variants paper fix-init] [--overwrite]

Runs the shipped ``P3-flight`` scenario for seeds 1..runs through the Monte Carlo layer
(:func:`mixnav.experiment.montecarlo.run_experiment`: every method on the same simulated
data per seed, resumable, one record per run) and aggregates with 95 % confidence
intervals (:func:`~mixnav.experiment.montecarlo.aggregate`, t distribution;
:func:`~mixnav.experiment.montecarlo.paired_comparison` for the paired differences).

Methods: those of the scenario file (EKF, UKF, the SIR particle filter with 2000
particles) and P3's GMPF when the estimator registry has ``"gmpf"`` (appended here with
2000 particles; otherwise skipped with a note, and its columns wait for a rerun).

Variants (``--variants``, default both):

``paper``     the scenario as shipped: P3's initial errors (position 0.2 arcmin, 0.2 arcmin,
              50 m = 369.8, 307.2, 50 m 1 sigma).
``fix-init``  the same runs with the filters' initial position error drawn with the GNSS
              fix's sigma (3.7, 3.7, 5 m), as a filter started at the first fix would be.
              Beyond the paper: with P3's 370 m spread the SIR filter's 2000 particles
              hold almost none within a few metres of the first fix (P3.md).

Scores: whole-run RMS of pitch, heading (yaw), 3-D velocity, horizontal and vertical
position (``mixnav.experiment.metrics``), the pitch and heading RMS after the rest
segment (100-1000 s, from the per-run series), the run's mean position NEES, the filter
time per 1 s GNSS epoch (mechanization included), and the number of runs a method lost
(horizontal RMS above ``DIVERGED_M``). Writes the experiment folders into ``--out``,
``P3_tables.md`` and ``P3.png`` (RMS error over runs per epoch, P3's figures 2-7:
pitch, heading, east and vertical velocity, east position (P3: longitude) and height)
beside this file.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).parent
#: a run whose horizontal position RMS exceeds this is counted as lost: 10 x the fixes'
#: 3.7 m sigma (the EKF's is about 1 m)
DIVERGED_M = 37.0
#: the window the "after rest" scores use [s]: heading is barely observable at rest
AFTER_REST = (100.0, 1000.0)
GMPF_BLOCK = '''
[[methods]]
name = "gmpf"
type = "loose-ekf"
estimator = "gmpf"
states = 15
[methods.options]
particles = 2000
'''
LABEL = {"ekf": "EKF", "ukf": "UKF", "pf": "PF (SIR, 2000 particles)", "gmpf": "GMPF (P3, 2000 particles)"}
VARIANTS = {"paper": "P3's initial errors (369.8, 307.2, 50 m; 20', 20', 30'; 0.01 m/s)",
            "fix-init": "initial position from the first fix (3.7, 3.7, 5 m); the rest as P3"}
#: (column, label, unit, digits)
SCORES = [("pitch_rmse_deg", "pitch RMS", "deg", 4), ("yaw_rmse_deg", "heading RMS", "deg", 4),
          ("pitch_after_rest_deg", "pitch RMS 100-1000 s", "deg", 4),
          ("yaw_after_rest_deg", "heading RMS 100-1000 s", "deg", 4),
          ("velocity_rmse_mps", "velocity RMS", "m/s", 4), ("horizontal_rmse_m", "horizontal RMS", "m", 3),
          ("vertical_rmse_m", "vertical RMS", "m", 3), ("nees_pos_mean", "position NEES (3)", "", 2),
          ("epoch_time_mean_us", "time per epoch", "us", 0)]
#: per-epoch panels of the figure: (series column, title, unit), P3 figs. 2-7
PANELS = [("err_pitch_deg", "pitch (P3 fig. 2)", "deg"), ("err_yaw_deg", "heading (P3 fig. 3)", "deg"),
          ("err_ve_mps", "east velocity (P3 fig. 4)", "m/s"), ("err_vd_mps", "vertical velocity (P3 fig. 5)", "m/s"),
          ("err_e_m", "east position (P3 fig. 6: longitude)", "m"), ("err_d_m", "height (P3 fig. 7)", "m")]


def has_gmpf() -> bool:
    """Whether the estimator registry of this mixnav has P3's GMPF."""
    from mixnav.filters.registry import estimator_names
    return "gmpf" in estimator_names()


def scenario_text(variant: str, gmpf: bool) -> str:
    """The P3-flight text of ``variant``, with the GMPF method appended when ``gmpf``
    and the shipped file does not list it yet."""
    from mixnav.config.loader import resolve
    text, _ = resolve("P3-flight", "scenarios", "scenario")
    if gmpf and not re.search(r'estimator\s*=\s*"gmpf"', text):
        text = text.rstrip("\n") + "\n" + GMPF_BLOCK
    if variant == "fix-init":
        old = 'position_sigma = ["369.8 m", "307.2 m", "50 m"]'
        if old not in text:
            raise SystemExit(f"P3-flight no longer has {old!r}: update make_p3.py")
        text = text.replace(old, 'position_sigma = ["3.7 m", "3.7 m", "5 m"]')
        text = text.replace('name = "P3-flight"', 'name = "P3-flight-fix-init"')
    return text


def after_rest(out_dir: Path) -> pd.DataFrame:
    """Per run and method, the pitch and heading RMS over :data:`AFTER_REST` [deg]."""
    from mixnav.experiment.montecarlo import series_files
    rows = []
    files, _ = series_files(out_dir)
    for f in files:
        seed = int(re.search(r"series_(\d+)", f.name).group(1))
        s = pd.read_parquet(f, columns=["method", "time_s", "err_pitch_deg", "err_yaw_deg"])
        s = s[(s.time_s >= AFTER_REST[0]) & (s.time_s <= AFTER_REST[1])]
        for m, g in s.groupby("method"):
            rows.append({"seed": seed, "method": m,
                         "pitch_after_rest_deg": float(np.sqrt(np.mean(g.err_pitch_deg ** 2))),
                         "yaw_after_rest_deg": float(np.sqrt(np.mean(g.err_yaw_deg ** 2)))})
    return pd.DataFrame(rows)


def run_variant(variant: str, runs: int, workers: int, out: Path, overwrite: bool, gmpf: bool):
    """Run (or resume) one variant's experiment; its records with the after-rest scores, and
    the per-epoch summary over runs."""
    from mixnav.experiment.mc_series import summarise_series
    from mixnav.experiment.montecarlo import run_experiment, series_files
    folder = out / variant
    folder.mkdir(parents=True, exist_ok=True)
    path = out / f"P3-flight-{variant}.toml"
    path.write_text(scenario_text(variant, gmpf))
    resume = (folder / "manifest.json").is_file() and not overwrite
    before = len(list((folder / "runs").glob("run_*.parquet"))) if resume else 0
    res = run_experiment(str(path), runs, folder, workers=workers, resume=resume, seeds_from=1,
                         overwrite=overwrite)
    res = res[res.seed.between(1, runs)]
    res = res.merge(after_rest(folder), on=["seed", "method"], how="left")
    files, _ = series_files(folder)
    files = [f for f in files if 1 <= int(re.search(r"series_(\d+)", f.name).group(1)) <= runs]
    computed = len(list((folder / "runs").glob("run_*.parquet"))) - before
    return res, summarise_series(files), computed


def _cell(a: pd.DataFrame, method: str, metric: str, digits: int) -> str:
    r = a[(a.method == method) & (a.metric == metric)]
    if r.empty or not np.isfinite(r["mean"].iloc[0]):
        return "—"
    r = r.iloc[0]
    fmt = ".3g" if abs(r["mean"]) >= 1e5 else f".{digits}f"     # a lost filter's NEES
    half = "" if not np.isfinite(r.ci95_half) else f" ± {r.ci95_half:{fmt}}"
    return f"{r['mean']:{fmt}}{half}"


def tables(results: dict, runs: int, elapsed: float, workers: int, gmpf: bool) -> str:
    from mixnav.experiment.montecarlo import aggregate, paired_comparison
    lines = ["# P3-flight tables (generated by make_p3.py)", "",
             f"{runs} runs per variant, seeds 1-{runs}; {elapsed:.0f} s wall with {workers} workers for the "
             f"{sum(r[2] for r in results.values())} runs computed by this invocation (the others were "
             "already recorded in --out). "
             "Mean ± half width of the 95 % confidence interval of the mean over runs (t distribution, "
             "mixnav.experiment.montecarlo.aggregate). Whole-run RMS unless the column says otherwise.", ""]
    if not gmpf:
        lines += ["**GMPF not run**: this mixnav's estimator registry has no \"gmpf\"; its rows "
                  "wait for a rerun of make_p3.py after it is merged.", ""]
    for variant, (res, _, _) in results.items():
        methods = [m for m in LABEL if m in set(res.method)]
        lost = {m: res[(res.method == m) & ~(res.horizontal_rmse_m <= DIVERGED_M)].seed.tolist() for m in methods}
        kept = res[~res.apply(lambda r: r.seed in lost[r.method], axis=1)]
        lines += [f"## {variant}: {VARIANTS[variant]}", ""]
        lines += ["| method | runs lost (horizontal RMS > 37 m) | " + " | ".join(
            f"{lab} [{u}]" if u else lab for _, lab, u, _ in SCORES) + " |",
            "|---|---|" + "---|" * len(SCORES)]
        a_all, a_kept = aggregate(res), aggregate(kept)
        for m in methods:
            a = a_kept if lost[m] and len(lost[m]) < runs else a_all
            note = f"{len(lost[m])}" + (" (scores over the others)" if a is a_kept else "")
            lines.append(f"| {LABEL[m]} | {note} | " + " | ".join(_cell(a, m, c, d) for c, _, _, d in SCORES) + " |")
        med = res.groupby("method")[[c for c, *_ in SCORES]].median()
        lines += ["", "Medians over all runs (lost ones included):", "",
                  "| method | " + " | ".join(lab for _, lab, _, _ in SCORES) + " |", "|---|" + "---|" * len(SCORES)]
        for m in methods:
            lines.append(f"| {LABEL[m]} | " + " | ".join(f"{med.loc[m, c]:.3g}" if d else f"{med.loc[m, c]:.0f}"
                                                        for c, _, _, d in SCORES) + " |")
        pairs = [(a, b) for a, b in (("gmpf", "pf"), ("gmpf", "ekf"), ("pf", "ekf"), ("ukf", "ekf"))
                 if a in methods and b in methods]
        lines += ["", "Paired differences A - B over the seeds (mean, 95 % CI; all runs):", "",
                  "| A - B | " + " | ".join(lab for _, lab, _, _ in SCORES[:7]) + " |", "|---|" + "---|" * 7]
        for a, b in pairs:
            cells = []
            for c, _, _, d in SCORES[:7]:
                try:
                    p = paired_comparison(res, c, a, b)
                    cells.append(f"{p['mean_diff']:.{d}f} [{p['ci95_low']:.{d}f}, {p['ci95_high']:.{d}f}]")
                except Exception as exc:   # too few finite pairs
                    cells.append(f"— ({exc.__class__.__name__})")
            lines.append(f"| {a} - {b} | " + " | ".join(cells) + " |")
        for m in methods:
            if len(lost[m]) == runs:
                lines += ["", f"{LABEL[m]}: lost every run (smallest horizontal RMS "
                          f"{res[res.method == m].horizontal_rmse_m.min():.0f} m)"]
            elif lost[m]:
                lines += ["", f"{LABEL[m]}: lost runs (seeds) {lost[m][:20]}{' ...' if len(lost[m]) > 20 else ''}"]
        lines.append("")
    return "\n".join(lines) + "\n"


def figure(results: dict, path: Path) -> None:
    """RMS error over runs per epoch: one row per P3 figure, one column per variant."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cols = list(results)
    fig, ax = plt.subplots(len(PANELS), len(cols), figsize=(6.5 * len(cols), 2.3 * len(PANELS)),
                           sharex=True, squeeze=False, constrained_layout=True)
    colors = {"ekf": "k", "ukf": "C2", "pf": "C3", "gmpf": "C0"}
    for j, variant in enumerate(cols):
        res, series, _ = results[variant]
        lost = set(res[~(res.horizontal_rmse_m <= DIVERGED_M)].method)
        for i, (c, title, unit) in enumerate(PANELS):
            a = ax[i, j]
            for m in LABEL:
                s = series[series.method == m] if not series.empty else series
                if s.empty or f"rms_{c}" not in s:
                    continue
                a.semilogy(s.time_s, s[f"rms_{c}"], color=colors[m], lw=0.9, ls="--" if m == "ukf" else "-",
                           label=LABEL[m] + (" (incl. lost runs)" if m in lost else ""))
            a.set_title(f"{variant}: RMS {title}", fontsize="small")
            a.set_ylabel(unit)
            a.grid(alpha=0.3, which="both")
            if i == 0:
                a.legend(fontsize="x-small", loc="upper right")
        ax[-1, j].set_xlabel("time [s]")
    fig.savefig(path, dpi=100)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("runs/p3"))
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    ap.add_argument("--overwrite", action="store_true", help="clear earlier experiments in --out")
    ap.add_argument("--tables", type=Path, default=HERE / "P3_tables.md")
    ap.add_argument("--figure", type=Path, default=HERE / "P3.png")
    a = ap.parse_args(argv)
    gmpf = has_gmpf()
    if not gmpf:
        print("note: the estimator registry has no 'gmpf' (P3's GMPF): running EKF, UKF and PF only; "
              "rerun after it is merged to fill the GMPF rows", file=sys.stderr)
    t0 = time.perf_counter()
    results = {}
    for v in a.variants:
        results[v] = run_variant(v, a.runs, a.workers, a.out, a.overwrite, gmpf)
        print(f"{v}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    text = tables(results, a.runs, time.perf_counter() - t0, a.workers, gmpf)
    a.tables.write_text(f"<!-- benchmarks/reproductions/make_p3.py --runs {a.runs} --workers {a.workers} -->\n\n"
                        + text)
    figure(results, a.figure)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
