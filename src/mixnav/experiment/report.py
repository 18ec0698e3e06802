"""One self-contained HTML report: tables and figures (embedded PNG), no scripts.

The page has no JavaScript and no external resource, so it can be mailed or
archived as a single file. Every piece of text is escaped with
``html.escape``. The one exception is the interactive map
(:mod:`mixnav.experiment.webmap`), when given: written beside as ``map.html`` and
inlined as an iframe's ``srcdoc`` (the page stays one file), whose own page loads
Leaflet and the map tiles from the web when viewed; offline the iframe stays empty
and the trajectory PNG is the plan view.
"""

from __future__ import annotations

import base64
import html
import numbers
from collections.abc import Sequence
from pathlib import Path

from matplotlib.figure import Figure

from ..io.atomic import atomic_savefig, atomic_write_text

__all__ = ["write_report"]

#: Columns of the metrics table: metric key -> header (with unit).
_COLUMNS = [
    ("horizontal_rmse_m", "horiz. RMSE [m]"), ("horizontal_max_m", "horiz. max [m]"),
    ("vertical_rmse_m", "vert. RMSE [m]"), ("vertical_max_m", "vert. max [m]"),
    ("velocity_rmse_mps", "vel. RMSE [m/s]"), ("velocity_max_mps", "vel. max [m/s]"),
    ("roll_rmse_deg", "roll RMSE [deg]"), ("roll_max_deg", "roll max [deg]"),
    ("pitch_rmse_deg", "pitch RMSE [deg]"), ("pitch_max_deg", "pitch max [deg]"),
    ("yaw_rmse_deg", "yaw RMSE [deg]"), ("yaw_max_deg", "yaw max [deg]"),
    ("nis_mean_per_dof", "NIS/dof mean"), ("nis_median_per_dof", "NIS/dof median"),
    ("epoch_time_mean_us", "time/epoch [us]"), ("smoother_time_s", "smoother [s]"),
]

_DPI = 110

_CSS = """body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1100px;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:90%}
td,th{border:1px solid #bbb;padding:4px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}
img{max-width:100%;display:block;margin:1em 0}
iframe{width:100%;height:560px;border:1px solid #bbb}
pre{background:#f6f6f6;padding:1em;overflow:auto;font-size:85%}"""


def _esc(x) -> str:
    return html.escape(str(x), quote=True)


def _fmt(v) -> str:
    """A number with 3 significant digits; anything else escaped as text."""
    if isinstance(v, numbers.Real) and not isinstance(v, bool):
        return f"{float(v):.3g}"
    return _esc(v)


def _metrics_table(methods: dict) -> str:
    # Only columns some method has: e.g. epoch_time_mean_us is absent without timing.
    cols = [(k, h) for k, h in _COLUMNS if any(k in m for m in methods.values())]
    rows = ["<table><tr><th>method</th>" + "".join(f"<th>{_esc(h)}</th>" for _, h in cols) + "</tr>"]
    for name, m in methods.items():
        cells = "".join(f"<td>{_fmt(m[k]) if k in m else ''}</td>" for k, _ in cols)
        rows.append(f"<tr><td>{_esc(name)}</td>{cells}</tr>")
    rows.append("</table>")
    return "".join(rows)


def _outage_table(methods: dict) -> str:
    rows = ["<table><tr><th>method</th><th>window [s]</th><th>horiz. max [m]</th>"
            "<th>vert. max [m]</th><th>horiz. at end [m]</th></tr>"]
    for name, m in methods.items():
        for o in m.get("outages", []):
            rows.append(f"<tr><td>{_esc(name)}</td><td>{o['start_s']:g} - {o['end_s']:g}</td>"
                        f"<td>{_fmt(o['horizontal_max_m'])}</td><td>{_fmt(o['vertical_max_m'])}</td>"
                        f"<td>{_fmt(o['horizontal_final_m'])}</td></tr>")
    rows.append("</table>")
    return "".join(rows)


def _segment_table(methods: dict) -> str:
    """Per method and scored segment (a scenario's ``[scoring]``): its span and main errors."""
    cols = (("horizontal_rmse_m", "horiz. RMSE [m]"), ("horizontal_max_m", "horiz. max [m]"),
            ("vertical_rmse_m", "vert. RMSE [m]"), ("vertical_max_m", "vert. max [m]"),
            ("velocity_rmse_mps", "vel. RMSE [m/s]"), ("nees_pos_mean", "mean position NEES"))
    rows = ["<table><tr><th>method</th><th>segment</th><th>span [s]</th>"
            + "".join(f"<th>{_esc(h)}</th>" for _, h in cols) + "</tr>"]
    for name, m in methods.items():
        for seg, g in m.get("segments", {}).items():
            rows.append(f"<tr><td>{_esc(name)}</td><td>{_esc(seg)}</td><td>{g['start_s']:g} - {g['end_s']:g}</td>"
                        + "".join(f"<td>{_fmt(g[k]) if k in g else ''}</td>" for k, _ in cols) + "</tr>")
    rows.append("</table>")
    return "".join(rows)


def sweep_table(summary: dict, settings: dict) -> str:
    """An outage sweep's distribution per method (:func:`mixnav.experiment.sweep.summarize`)."""
    window, step = settings.get("window_s"), settings.get("step_s")
    span = settings.get("span_s", [float("nan")] * 2)
    head = (f"<p>{_fmt(settings.get('n_windows', ''))} windows of {_fmt(window)} s, every {_fmt(step)} s, "
            f"{_fmt(span[0])} - {_fmt(span[1])} s; one withheld at a time (the dataset's own windows are not "
            "withheld here). A window counts as out of band when its mean position NEES is above the "
            "chi-square(3) 99 % point, 11.3.</p>")
    rows = [head + "<table><tr><th>method</th><th>windows</th><th>median horiz. max [m]</th>"
            "<th>p90 [m]</th><th>worst [m]</th><th>worst window starts [s]</th>"
            "<th>median horiz. RMSE [m]</th><th>NEES out of band</th></tr>"]
    for name, b in summary.items():
        share = b.get("share_nees_above_99")
        rows.append(f"<tr><td>{_esc(name)}</td><td>{b['n_windows']}</td>"
                    f"<td>{_fmt(b['median_horizontal_max_m'])}</td><td>{_fmt(b['p90_horizontal_max_m'])}</td>"
                    f"<td>{_fmt(b['worst_horizontal_max_m'])}</td><td>{_fmt(b['worst_window_start_s'])}</td>"
                    f"<td>{_fmt(b['median_horizontal_rmse_m'])}</td>"
                    f"<td>{'' if share is None else f'{100 * share:.0f} %'}</td></tr>")
    rows.append("</table>")
    skipped = settings.get("skipped_windows_no_reference") or []
    if skipped:
        rows.append(f"<p>{len(skipped)} windows left out: the reference has no epoch in them.</p>")
    late = settings.get("skipped_windows_alignment") or []
    if late:
        rows.append(f"<p>{len(late)} windows left out: without their GNSS the alignment ends after they start.</p>")
    return "".join(rows)


def start_sweep_table(summary: dict, settings: dict) -> str:
    """A start sweep's distribution per method (:func:`mixnav.experiment.sweep.summarize_starts`)."""
    starts = ", ".join(f"{t:g}" for t in settings.get("starts_s", []))
    span = settings.get("common_span_s", [float("nan")] * 2)
    rows = [f"<p>The whole causal pipeline started at {_esc(starts)} s (the data before each discarded), each "
            f"run scored from its own filter start and on the span all runs cover, {_fmt(span[0])} - "
            f"{_fmt(span[1])} s.</p><table><tr><th>method</th><th>starts</th><th>median RMSE [m]</th>"
            "<th>worst RMSE [m]</th><th>worst start [s]</th><th>median RMSE, common span [m]</th>"
            "<th>worst, common span [m]</th></tr>"]
    for name, b in summary.items():
        rows.append(f"<tr><td>{_esc(name)}</td><td>{b['n_starts']}</td><td>{_fmt(b['median_horizontal_rmse_m'])}</td>"
                    f"<td>{_fmt(b['worst_horizontal_rmse_m'])}</td><td>{_fmt(b['worst_start_s'])}</td>"
                    f"<td>{_fmt(b['median_common_horizontal_rmse_m'])}</td>"
                    f"<td>{_fmt(b['worst_common_horizontal_rmse_m'])}</td></tr>")
    rows.append("</table>")
    return "".join(rows)


def write_report(out_dir: Path, title: str, metrics: dict, figures: dict[str, Figure],
                 notes: Sequence[str] = (), config_text: str | None = None,
                 sections: Sequence[tuple[str, str]] = (), web_map: str | None = None) -> Path:
    """Save the figures as PNG and write ``report.html`` with them embedded.

    Parameters
    ----------
    out_dir : Path
        Output folder, created if missing.
    title : str
        Page title and heading.
    metrics : dict
        ``{"scenario": str, "methods": {name: metrics}, ...}`` where each
        method's metrics come from
        :func:`mixnav.experiment.metrics.compute_metrics`, optionally with
        ``epoch_time_mean_us`` [us] and ``recoveries`` added.
    figures : dict of str -> matplotlib.figure.Figure
        Each is saved as ``<name>.png`` (dpi 110) and embedded in the page.
    notes : sequence of str
        Shown as a bullet list.
    config_text : str, optional
        The scenario file, shown verbatim at the end.
    sections : sequence of (title, html)
        Further sections placed after the metrics tables; the HTML must be
        built with every piece of text already escaped.
    web_map : str, optional
        An interactive map page (:func:`mixnav.experiment.webmap.map_html`): written as
        ``map.html`` and shown in an iframe ahead of the figures.

    Returns
    -------
    Path
        Path of ``report.html``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    methods = metrics.get("methods", {})
    parts = ["<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
             f"<title>{_esc(title)}</title><style>{_CSS}</style></head><body>",
             f"<h1>{_esc(title)}</h1>"]
    if "scenario" in metrics:
        parts.append(f"<p>Scenario: <b>{_esc(metrics['scenario'])}</b></p>")

    if methods:
        parts.append("<h2>Accuracy and cost</h2>")
        parts.append(_metrics_table(methods))
    if any(m.get("outages") for m in methods.values()):
        parts.append("<h2>GNSS outages</h2>")
        parts.append(_outage_table(methods))
    if any(m.get("segments") for m in methods.values()):
        parts.append("<h2>Scored segments</h2>")
        parts.append(_segment_table(methods))
    rec = {n: m["recoveries"] for n, m in methods.items() if m.get("recoveries")}
    if rec:
        parts.append("<h2>Numerical recoveries</h2><ul>" + "".join(
            f"<li>{_esc(n)}: " + ", ".join(f"{_esc(k)} {_esc(v)}" for k, v in r.items()) + "</li>"
            for n, r in rec.items()) + "</ul>")
    for title_, body in sections:
        parts.append(f"<h2>{_esc(title_)}</h2>{body}")
    if notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{_esc(n)}</li>" for n in notes) + "</ul>")

    if web_map is not None:
        atomic_write_text(out_dir / "map.html", web_map)
        parts.append("<h2>Map</h2><p>The trajectories on OpenStreetMap (needs a connection; also "
                     "<a href='map.html'>map.html</a>; offline, the plan view below): each method's track, the "
                     "reference, the GNSS fixes, the GNSS outage windows in orange; layers switch on and off "
                     "at the top right.</p>"
                     f"<iframe title='map' sandbox='allow-scripts' srcdoc='{_esc(web_map)}'></iframe>")
    if figures:
        parts.append("<h2>Figures</h2>")
    for name, fig in figures.items():
        png = out_dir / f"{name}.png"
        atomic_savefig(fig, png, dpi=_DPI)
        # Embed the bytes of the file just written, so page and PNG are identical.
        b64 = base64.b64encode(png.read_bytes()).decode("ascii")
        parts.append(f"<h3>{_esc(name)}</h3>"
                     f"<img src='data:image/png;base64,{b64}' alt='{_esc(name)}'>")

    if config_text:
        parts.append(f"<h2>Scenario file</h2><pre>{_esc(config_text)}</pre>")
    parts.append("</body></html>\n")
    path = out_dir / "report.html"
    atomic_write_text(path, "\n".join(parts))
    return path
