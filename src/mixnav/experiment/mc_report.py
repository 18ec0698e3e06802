"""The report of a Monte Carlo experiment: mean metrics with confidence
intervals, and box plots of the per-run metrics of every method.

It reuses :func:`mixnav.experiment.report.write_report` (one self-contained
HTML file, figures embedded, the same PNGs beside it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from .report import write_report

#: Per-run metrics shown as box plots, when present: column -> label.
BOX_METRICS = {
    "horizontal_rmse_m": "horizontal RMSE [m]", "vertical_rmse_m": "vertical RMSE [m]",
    "velocity_rmse_mps": "velocity RMSE [m/s]", "yaw_rmse_deg": "yaw RMSE [deg]",
    "pitch_rmse_deg": "pitch RMSE [deg]", "roll_rmse_deg": "roll RMSE [deg]",
    "outage0_horizontal_max_m": "outage 1: max horizontal error [m]",
    "nees_pos_mean": "mean position NEES (3 if consistent)",
    "epoch_time_mean_us": "time per GNSS epoch [us]",
}


def boxplot_figure(results: pd.DataFrame, columns: dict[str, str]) -> Figure:
    """One box plot per metric, one box per method (each point a run)."""
    cols = [c for c in columns if c in results.columns]
    n = len(cols)
    ncol = 3 if n > 4 else max(n, 1)
    nrow = int(np.ceil(n / ncol)) if n else 1
    fig = Figure(figsize=(4 * ncol, 3.2 * nrow), layout="constrained")
    axs = np.atleast_1d(fig.subplots(nrow, ncol)).ravel()
    methods = list(dict.fromkeys(results["method"]))
    for ax, c in zip(axs, cols):
        data = [results.loc[results["method"] == m, c].dropna().to_numpy() for m in methods]
        ax.boxplot(data, tick_labels=methods, showmeans=True)
        ax.set_title(columns[c], fontsize="medium")
        ax.grid(alpha=0.3, axis="y")
    for ax in axs[len(cols):]:
        ax.set_visible(False)
    return fig


def write_experiment_report(out_dir: Path, scenario: str, results: pd.DataFrame, summary: pd.DataFrame,
                            config_text: str | None = None) -> Path:
    """``report.html`` of an experiment folder (tables of means, CIs in the notes, box plots)."""
    means = summary.pivot(index="method", columns="metric", values="mean")
    methods = {m: {k: float(v) for k, v in row.items() if np.isfinite(v)} for m, row in means.iterrows()}
    runs = int(results["seed"].nunique())
    notes = [f"{runs} seeded runs per method (seeds {int(results['seed'].min())}-{int(results['seed'].max())}); "
             "the table shows means over runs; 95 % confidence intervals of the means (t distribution):"]
    for _, r in summary[summary["metric"].isin(["horizontal_rmse_m", "yaw_rmse_deg", "velocity_rmse_mps",
                                                "epoch_time_mean_us"])].iterrows():
        notes.append(f"{r['method']}: {r['metric']} = {r['mean']:.4g} +- {r['ci95_half']:.2g} (n = {int(r['n'])})")
    figs = {"boxplots": boxplot_figure(results, BOX_METRICS)}
    return write_report(Path(out_dir), f"mixnav experiment: {scenario}", {"methods": methods}, figs,
                        notes=notes, config_text=config_text)
