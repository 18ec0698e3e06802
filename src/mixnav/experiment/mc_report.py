"""The report of a Monte Carlo experiment.

Tables: the mean of each metric over runs with its 95 % confidence interval,
per method (and per sweep value); the Monte Carlo consistency (NEES and NIS
averaged over runs against their chi-square bands). Figures: box plots of the
per-run metrics, RMS error over runs against the filter's 1- and 3-sigma,
run-averaged NEES and NIS with their bands and, for a sweep, each metric
against the swept value. It reuses :func:`mixnav.experiment.report.write_report`
(one self-contained HTML file, the same PNGs beside it).
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import ScalarFormatter

from .figures import _shade
from .report import write_report

#: Per-run metrics shown as box plots and in the table, when present: column -> label.
BOX_METRICS = {
    "horizontal_rmse_m": "horizontal RMSE [m]", "vertical_rmse_m": "vertical RMSE [m]",
    "velocity_rmse_mps": "velocity RMSE [m/s]", "yaw_rmse_deg": "yaw RMSE [deg]",
    "pitch_rmse_deg": "pitch RMSE [deg]", "roll_rmse_deg": "roll RMSE [deg]",
    "horizontal_max_m": "horizontal max [m]",
    "outage0_horizontal_max_m": "outage 1: max horizontal error [m]",
    "nees_pos_mean": "mean position NEES (3 if consistent)",
    "epoch_time_mean_us": "time per GNSS epoch [us]",
}

# series kind -> (axis stems, unit suffix of the columns, axis unit, title)
_KINDS = {
    "position": (("n", "e", "d"), "m", "m", "position error"),
    "velocity": (("vn", "ve", "vd"), "mps", "m/s", "velocity error"),
    "attitude": (("roll", "pitch", "yaw"), "deg", "deg", "attitude error"),
}


def _colours(methods: Sequence[str]) -> dict[str, str]:
    return {m: f"C{i % 10}" for i, m in enumerate(methods)}


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


def rms_error_figure(series: pd.DataFrame, kind: str, outages=()) -> Figure | None:
    """RMS over runs of each error component (solid) with the filter's RMS
    1-sigma (dashed) and 3-sigma (dotted), one axis per component.

    For a consistent filter the solid line follows the dashed one.
    """
    stems, suffix, unit, title = _KINDS[kind]
    if f"rms_err_{stems[0]}_{suffix}" not in series:
        return None
    fig = Figure(figsize=(9, 7), layout="constrained")
    axs = fig.subplots(3, 1, sharex=True)
    methods = list(dict.fromkeys(series["method"]))
    col = _colours(methods)
    for ax, st in zip(axs, stems):
        _shade(ax, outages)
        for m in methods:
            g = series[series["method"] == m]
            t = g["time_s"].to_numpy()
            ax.plot(t, g[f"rms_err_{st}_{suffix}"], color=col[m], lw=1.0, label=f"{m} RMS error")
            sig = f"rms_sig_{st}_{suffix}"
            if sig in g:
                ax.plot(t, g[sig], color=col[m], lw=0.8, ls="--", label=f"{m} 1-sigma")
                ax.plot(t, 3 * g[sig], color=col[m], lw=0.6, ls=":", label=f"{m} 3-sigma")
        ax.set_ylabel(f"{st} [{unit}]")
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(ScalarFormatter())
        ax.grid(alpha=0.3, which="both")
    axs[0].set_title(f"{title}: RMS over runs vs the filter's sigma")
    axs[0].legend(fontsize="small", ncol=3)
    axs[-1].set_xlabel("time [s]")
    return fig


def nees_figure(series: pd.DataFrame, outages=()) -> Figure | None:
    """Run-averaged position and velocity NEES with their 95 % chi-square bands."""
    qs = [q for q in ("pos", "vel") if f"mean_nees_{q}" in series]
    if not qs:
        return None
    fig = Figure(figsize=(9, 2.8 * len(qs) + 0.6), layout="constrained")
    axs = np.atleast_1d(fig.subplots(len(qs), 1, sharex=True))
    methods = list(dict.fromkeys(series["method"]))
    col = _colours(methods)
    for ax, q in zip(axs, qs):
        _shade(ax, outages)
        for m in methods:
            g = series[series["method"] == m]
            ax.plot(g["time_s"], g[f"mean_nees_{q}"], color=col[m], lw=0.9, label=m)
        g = series[series["method"] == methods[0]]
        ax.plot(g["time_s"], g[f"nees_{q}_lo"], "k--", lw=0.7, label="95 % band")
        ax.plot(g["time_s"], g[f"nees_{q}_hi"], "k--", lw=0.7)
        ax.axhline(3, color="k", lw=0.5, alpha=0.5)
        ax.set_ylabel(f"NEES {q} (3 dof)")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axs[0].set_title(f"NEES averaged over {int(series['n_runs'].max())} runs")
    axs[0].legend(fontsize="small")
    axs[-1].set_xlabel("time [s]")
    return fig


def nis_figure(series: pd.DataFrame) -> Figure | None:
    """NIS per degree of freedom averaged over runs at each update epoch, with its band."""
    s = series[np.isfinite(series["mean_nis_per_dof"])] if "mean_nis_per_dof" in series else None
    if s is None or s.empty:
        return None
    fig = Figure(figsize=(9, 3.4), layout="constrained")
    ax = fig.subplots()
    methods = list(dict.fromkeys(s["method"]))
    col = _colours(methods)
    for m in methods:
        g = s[s["method"] == m]
        ax.plot(g["time_s"], g["mean_nis_per_dof"], ".", ms=2, color=col[m], label=m)
    g = s[s["method"] == methods[0]]
    ax.plot(g["time_s"], g["nis_lo"], "k--", lw=0.7, label="95 % band")
    ax.plot(g["time_s"], g["nis_hi"], "k--", lw=0.7)
    ax.axhline(1, color="k", lw=0.5, alpha=0.5)
    ax.set_ylabel("NIS / dof")
    ax.set_xlabel("time [s]")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.set_title(f"NIS per degree of freedom averaged over up to {int(s['n_nis'].max())} runs")
    ax.legend(fontsize="small")
    return fig


def sweep_figure(summary: pd.DataFrame, columns: dict[str, str], sweep_name: str) -> Figure:
    """Mean of each metric (with its 95 % CI as error bars) against the swept value."""
    cols = [c for c in columns if c in set(summary["metric"])]
    n = len(cols)
    ncol = 3 if n > 4 else max(n, 1)
    nrow = int(np.ceil(n / ncol)) if n else 1
    fig = Figure(figsize=(4 * ncol, 3.2 * nrow), layout="constrained")
    axs = np.atleast_1d(fig.subplots(nrow, ncol)).ravel()
    methods = list(dict.fromkeys(summary["method"]))
    col = _colours(methods)
    for ax, c in zip(axs, cols):
        for m in methods:
            g = summary[(summary["metric"] == c) & (summary["method"] == m)].sort_values("sweep_value")
            ax.errorbar(g["sweep_value"], g["mean"], yerr=g["ci95_half"].fillna(0), color=col[m],
                        marker="o", ms=3, capsize=2, label=m)
        ax.set_title(columns[c], fontsize="medium")
        ax.set_xlabel(sweep_name)
        ax.grid(alpha=0.3)
    if cols:
        axs[0].legend(fontsize="small")
    for ax in axs[len(cols):]:
        ax.set_visible(False)
    return fig


def _table(df: pd.DataFrame) -> str:
    """An HTML table of a small DataFrame (numbers to 4 significant digits), escaped."""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    rows = []
    for _, r in df.iterrows():
        cells = []
        for v in r:
            if isinstance(v, (float, np.floating)):
                cells.append(f"<td>{v:.4g}</td>" if np.isfinite(v) else "<td></td>")
            else:
                cells.append(f"<td>{html.escape(str(v))}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><tr>{head}</tr>" + "".join(rows) + "</table>"


def _mean_ci_table(summary: pd.DataFrame, columns: dict[str, str] = BOX_METRICS) -> pd.DataFrame:
    """Wide table: one row per (sweep value,) method, 'mean +- CI' per metric of ``columns``."""
    keys = ["sweep_value", "method"] if "sweep_value" in summary.columns else ["method"]
    s = summary[summary["metric"].isin(list(columns))].copy()
    s["cell"] = [f"{m:.4g} ± {h:.2g}" if np.isfinite(h) else f"{m:.4g}" if np.isfinite(m) else ""
                 for m, h in zip(s["mean"], s["ci95_half"])]  # blank: no run has it (a smoothed method's times)
    wide = s.pivot_table(index=keys, columns="metric", values="cell", aggfunc="first")
    wide = wide[[c for c in columns if c in wide.columns]].rename(columns=columns)
    return wide.reset_index()


#: Labels of further metrics a headline table may name.
LABELS = {**BOX_METRICS,
          "roll_max_deg": "roll max [deg]", "pitch_max_deg": "pitch max [deg]", "yaw_max_deg": "yaw max [deg]",
          "vertical_max_m": "vertical max [m]", "learning_time_s": "learning time [s]",
          "total_time_s": "total time: filter + learning [s]",
          "smoother_time_s": "RTS smoother time [s]",
          "online_refits": "online refits", "online_refit_time_s": "online refit time [s]",
          **{f"outage{i}_{k}_max_m": f"outage {i + 1}: max {k} error [m]" for i in range(9)
             for k in ("horizontal", "vertical")}}


def _label(key: str, segments: Sequence[str] = ()) -> str:
    """The label of a metric key; ``segment_<name>_<metric>`` (a scored segment of ``segments``)
    as ``<name>: <metric's label>``."""
    for g in sorted(segments, key=len, reverse=True):     # the longest name first: "a" vs "a_b"
        if key.startswith(f"segment_{g}_"):
            rest = key[len(f"segment_{g}_"):]
            return f"{g}: {LABELS.get(rest, rest)}"
    return LABELS.get(key, key)


def headline_columns(keys: Sequence[str], segments: Sequence[str] = ()) -> dict[str, str]:
    """Labels of a scenario's ``report_table`` metric keys (the key itself when unknown;
    ``segments``: the names of its scored segments, whose keys are labelled by segment)."""
    return {k: _label(k, segments) for k in keys}


#: Per scored segment, the metrics of the report's segment table.
SEGMENT_METRICS = ("horizontal_rmse_m", "horizontal_max_m", "vertical_rmse_m", "vertical_max_m",
                   "velocity_rmse_mps", "nees_pos_mean")


def segment_columns(segments: Sequence[str]) -> dict[str, str]:
    """Column -> label of the segment table: :data:`SEGMENT_METRICS` of each scored segment."""
    return {f"segment_{g}_{k}": _label(f"segment_{g}_{k}", segments) for g in segments for k in SEGMENT_METRICS}


#: the figures an experiment's report may draw (``<name>.png`` beside ``report.html``)
EXPERIMENT_FIGURES = ("sweep", "boxplots", "rms_error_position", "rms_error_velocity", "rms_error_attitude",
                      "nees", "nis")


def write_experiment_report(out_dir: Path, scenario: str, results: pd.DataFrame, summary: pd.DataFrame,
                            config_text: str | None = None, series: pd.DataFrame | None = None,
                            consistency: pd.DataFrame | None = None, outages=(),
                            sweep_name: str | None = None, headline: Sequence[str] = (),
                            segments: Sequence[str] = (), figures: bool = True) -> Path:
    """``report.html`` of an experiment folder.

    Parameters
    ----------
    results, summary : pandas.DataFrame
        Per-run records and :func:`mixnav.experiment.montecarlo.aggregate` of them.
    series, consistency : pandas.DataFrame, optional
        :func:`mixnav.experiment.mc_series.summarise_series` and
        :func:`~mixnav.experiment.mc_series.consistency_table` of the runs.
    outages : sequence of (start_s, end_s)
        GNSS outage windows, shaded in the time plots.
    sweep_name : str, optional
        Name of the swept quantity (sweep experiments).
    headline : sequence of str
        Metric keys of the scenario's headline table (``scenario.report_table``),
        shown first and, for a sweep, drawn against the swept value.
    segments : sequence of str
        Names of the scenario's scored segments (``[scoring]``): a table of their
        metrics (means over runs), after the headline table.
    figures : bool
        Draw the PNG figures (the report's time to write is mostly theirs: about 1 s each);
        without them the report holds the tables alone, says so, and figures an earlier
        write of the folder left are removed (they would show other results).
    """
    sweep = "sweep_value" in results.columns
    runs = int(results["seed"].nunique())
    notes = [f"{runs} seeded runs per method"
             + (f" and sweep value ({sweep_name})" if sweep else "")
             + f" (seeds {int(results['seed'].min())}-{int(results['seed'].max())}); tables give "
             "means over runs with the half width of their 95 % confidence interval "
             "(t distribution).",
             "NEES and NIS are averaged over runs at each epoch; for N runs of a consistent filter "
             "N x mean NEES follows chi2(N x dof), whose 2.5 % and 97.5 % quantiles give the band. "
             "Epochs within a run are correlated, so the in-band fraction can fall below 95 % by more "
             "than chance would allow for independent epochs."]
    sections = []
    if headline:
        sections.append(("Headline table: means over runs (95 % CI)",
                         _table(_mean_ci_table(summary, headline_columns(headline, segments)))))
    if segments:
        sections.append(("Scored segments: means over runs (95 % CI)",
                         _table(_mean_ci_table(summary, segment_columns(segments)))))
    sections.append(("Means over runs (95 % CI)", _table(_mean_ci_table(summary))))
    if consistency is not None and not consistency.empty:
        sections.append(("Monte Carlo consistency", _table(consistency)))
    figs: dict[str, Figure] = {}
    if not figures:
        notes.append("Figures not drawn (--no-figures, or figures=False from Python): the tables above hold the numbers.")
        for name in EXPERIMENT_FIGURES:
            (Path(out_dir) / f"{name}.png").unlink(missing_ok=True)
    elif sweep:
        figs["sweep"] = sweep_figure(summary, headline_columns(headline, segments) if headline else BOX_METRICS,
                                     sweep_name or "sweep value")
    else:
        figs["boxplots"] = boxplot_figure(results, BOX_METRICS)
    if figures and series is not None and not series.empty and not sweep:
        for kind in ("position", "velocity", "attitude"):
            f = rms_error_figure(series, kind, outages)
            if f is not None:
                figs[f"rms_error_{kind}"] = f
        for name, f in (("nees", nees_figure(series, outages)), ("nis", nis_figure(series))):
            if f is not None:
                figs[name] = f
    # the means are in the table of sections (with their CIs), not in write_report's own table
    return write_report(Path(out_dir), f"mixnav experiment: {scenario}", {"methods": {}}, figs,
                        notes=notes, config_text=config_text, sections=sections)
