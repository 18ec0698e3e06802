"""``mixnav tune``'s files: ``tuned.toml``, ``tune.json``, ``report.md`` and ``tune.png``,
each written whole or not at all (:mod:`mixnav.io.atomic`)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


def _f(x, fmt=".3f") -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def write_outputs(out: Path, result, header: dict) -> None:
    from ...io.atomic import atomic_write_text
    atomic_write_text(out / "tuned.toml", result.tuned_text)
    kind = header.get("criterion_kind")
    criterion = (WITHHELD if kind == "withheld-satellites" else LIKELIHOOD if kind == "likelihood" else
                 "mean negative log predictive density of the withheld GNSS fixes (cross-validation); the GNSS "
                 "innovation log-likelihood per update beside it")
    body = {**header, "criterion": criterion,
            "given": result.given, "tuned": result.tuned, "chosen": result.chosen, "not_tuned": result.not_tuned,
            "evaluations": result.evaluations}
    atomic_write_text(out / "tune.json", json.dumps(body, indent=1, default=float) + "\n")
    _figure(out / "tune.png", result)
    report = _vehicle_report if kind in ("likelihood", "withheld-satellites") else _report
    atomic_write_text(out / "report.md", report(result, header))


LIKELIHOOD = ("minus the tuned method's innovation log-likelihood per pseudorange row (each row's log predictive "
              "density before it is used), over the rows from each start + score_after_s, summed over the starts of "
              "the whole causal pipeline")
WITHHELD = ("withheld satellites: half the satellites withheld per run (two folds), per epoch the median over them "
            "of |residual - the epoch's median residual| from the filter's position [m], averaged over the epochs from "
            "each start + score_after_s, over the starts of the whole causal pipeline; the innovation "
            "log-likelihood per update of the rows used beside it")


def _chosen_lines(result) -> list[str]:
    lines = ["", "## Chosen values", "", "| key | value | how | spread |", "|---|---|---|---|"]
    if not result.chosen:
        lines.append("| - | - | none written" + (": the file as given is kept" if result.kept_as_given
                                                 else "") + " | - |")
    for k, c in result.chosen.items():
        lines.append(f"| `{k}` | {c.get('value', c.get('from_data', '-'))} | {c.get('how', c.get('data_how', ''))} "
                     f"| {c.get('spread') or '-'} |")
    if result.not_tuned:
        lines += ["", "## Not tuned", ""] + [f"- `{k}`: {v}" for k, v in result.not_tuned.items()]
    return lines


def _vehicle_report(result, h: dict) -> str:
    g, t = result.given, result.tuned
    withheld = h["criterion_kind"] == "withheld-satellites"
    lines = [f"# mixnav tune: {h['dataset']}", "",
             f"Method tuned: `{h['method']}`; "
             f"{h.get('pipeline', 'the whole causal pipeline (track alignment, then the filter)')} run from "
             f"{len(h['starts_s'])} starts ({', '.join(f'{s:g}' for s in h['starts_s'])} s)"
             + (", each twice with half the satellites withheld" if withheld else "")
             + f"; the rows from each start + {h['score_after_s']:g} s scored; {h['evaluations_spent']} evaluations "
             f"({h['filter_runs']} pipeline runs) of a budget of {h['budget']}. No reference was read.", "",
             f"Criterion: {WITHHELD if withheld else LIKELIHOOD}.", "",
             "## The criterion, the file as given against tuned", "",
             "| | criterion (lower is better) | its standard error | per start | innovation log-lik. per update |",
             "|---|---|---|---|---|"]
    for name, s in (("as given", g), ("tuned", t)):
        per = " ".join(f"{x:.3f}" if withheld else f"{x:.0f}" for x in s.get("per_start") or [])
        lines.append(f"| {name} | {_f(s['criterion'], '.4f')} | {_f(s['criterion_se'], '.3f')} | {per} | "
                     f"{_f(s['innovation_ll_per_update'], '.2f')} |")
    lines += _chosen_lines(result)
    lines += ["", "![criterion against each key](tune.png)", ""]
    return "\n".join(lines)


def _report(result, h: dict) -> str:
    g, t = result.given, result.tuned
    lines = [f"# mixnav tune: {h['dataset']}", "",
             f"Method tuned: `{h['method']}`; span {h['span_s'][0]:.1f}-{h['span_s'][1]:.1f} s; "
             f"{sum(len(f) for f in h['cv_windows'])} cross-validation windows of {h['window_s']:g} s in "
             f"{h['folds']} folds; {h['evaluations_spent']} evaluations ({h['filter_runs']} filter runs) of a "
             f"budget of {h['budget']}. No reference was read.", "",
             "## The criterion, the file as given against tuned", "",
             "| | CV mean NLPD (lower is better) | innovation log-lik. per update | CV median / p90 / worst "
             "horizontal max vs own GNSS [m] |", "|---|---|---|---|"]
    for name, s in (("as given", g), ("tuned", t)):
        lines.append(f"| {name} | {_f(s['nlpd'])} | {_f(s['innovation_ll_per_update'])} | "
                     f"{_f(s['cv_median_hmax_m'], '.2f')} / {_f(s['cv_p90_hmax_m'], '.2f')} / "
                     f"{_f(s['cv_worst_hmax_m'], '.2f')} |")
    if result.kept_as_given:
        lines += ["", f"**tuned.toml is the file as given.** {result.kept_as_given[0].upper()}"
                  f"{result.kept_as_given[1:]}. What the search's best had (not written):", ""]
        lines += [f"- `{k}` = {v['value']} ({v['how']})" for k, v in result.found.items()] or ["- (nothing moved)"]
    lines += _chosen_lines(result)
    lines += ["", "## Where the two criteria disagree", "",
              "Per key, in the search's last visit of it (the other keys the same across its points), the value "
              "each criterion prefers. The search follows the cross-validation (the IMU time offset and the GNSS "
              "velocity delay excepted: they follow the innovation likelihood, which a timing error shows in every "
              "update): it scores positions after seconds "
              "without GNSS, which is what the bias walks and the constraint sigmas act on; the innovation "
              "likelihood scores 0.25-1 s predictions.", "",
              "| key | cross-validation best | innovation-likelihood best | agree |", "|---|---|---|---|"]
    for k, curve in _curves(result).items():
        if not curve:
            continue
        pts = [x for x in curve if x[4] == curve[-1][4]]
        cv = min(pts, key=lambda x: x[2])[1]
        ll = max(pts, key=lambda x: x[3] if x[3] is not None else -math.inf)[1]
        lines.append(f"| `{k}` | {cv:.4g} | {ll:.4g} | {'yes' if cv == ll else 'no'} |")
    lines += ["", "![criterion against each key](tune.png)", ""]
    return "\n".join(lines)


def _curves(result) -> dict:
    """Per searched key its evaluated points: the search's record (also when the file as given
    was kept and nothing is in ``chosen``), else the chosen values' own."""
    got = {k: c for k, c in result.curves.items() if len(c) >= 2}
    return got or {k: c["curve"] for k, c in result.chosen.items() if c.get("curve")}


def _figure(path: Path, result) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ...io.atomic import atomic_savefig
    curves = _curves(result)
    ylabel = "criterion" if "per_start" in (result.given or {}) else "CV mean NLPD"
    n = max(len(curves), 1)
    cols = min(3, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False)
    for ax, (k, cv) in zip(axes.ravel(), curves.items()):
        x = np.array([c[1] for c in cv], float)
        y = np.array([c[2] for c in cv], float)
        ok = np.isfinite(y)
        ax.plot(x[ok], y[ok], "o", ms=4)
        ax.set_title(k, fontsize=9)
        if (x[ok] > 0).all():
            ax.set_xscale("log")
        ax.set_ylabel(ylabel)
    for ax in axes.ravel()[len(curves):]:
        ax.axis("off")
    fig.tight_layout()
    try:
        atomic_savefig(fig, path, dpi=90)
    finally:
        plt.close(fig)
