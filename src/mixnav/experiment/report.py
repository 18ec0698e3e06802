"""One self-contained HTML report: tables and figures (embedded PNG), no scripts."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

from ..io.atomic import atomic_write_bytes, atomic_write_text

_COLUMNS = [
    ("horizontal_rmse_m", "horiz. RMSE [m]"), ("horizontal_max_m", "horiz. max [m]"),
    ("vertical_rmse_m", "vert. RMSE [m]"), ("vertical_max_m", "vert. max [m]"),
    ("velocity_rmse_mps", "vel. RMSE [m/s]"), ("velocity_max_mps", "vel. max [m/s]"),
    ("roll_rmse_deg", "roll RMSE [deg]"), ("pitch_rmse_deg", "pitch RMSE [deg]"),
    ("yaw_rmse_deg", "yaw RMSE [deg]"), ("yaw_max_deg", "yaw max [deg]"),
    ("epoch_time_mean_us", "time/epoch [us]"),
]

_CSS = """body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:4px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}img{max-width:100%;display:block;margin:1em 0}
pre{background:#f6f6f6;padding:1em;overflow:auto;font-size:85%}"""


def _fmt(v) -> str:
    if isinstance(v, (int, float)):
        return f"{v:.3g}"
    return html.escape(str(v))


def write_report(out_dir: Path, title: str, metrics: dict, figures: dict, notes=(),
                 config_text: str | None = None) -> Path:
    """Save the figures as PNG and write ``report.html`` with them embedded.

    Parameters
    ----------
    out_dir : Path
    title : str
    metrics : dict
        ``{"methods": {name: {metric: value, ..., "outages": [...]}}, ...}``.
    figures : dict of name -> matplotlib Figure
    notes : sequence of str
    config_text : str, optional
        The scenario file, shown at the end.
    """
    out_dir = Path(out_dir)
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>"]
    methods = metrics.get("methods", {})
    cols = [(k, h) for k, h in _COLUMNS if any(k in m for m in methods.values())]
    parts.append("<h2>Accuracy and cost</h2><table><tr><th>method</th>"
                 + "".join(f"<th>{html.escape(h)}</th>" for _, h in cols) + "</tr>")
    for name, m in methods.items():
        parts.append(f"<tr><td>{html.escape(name)}</td>" + "".join(f"<td>{_fmt(m.get(k, ''))}</td>" for k, _ in cols)
                     + "</tr>")
    parts.append("</table>")
    if any(m.get("outages") for m in methods.values()):
        parts.append("<h2>GNSS outages</h2><table><tr><th>method</th><th>window [s]</th>"
                     "<th>horiz. max [m]</th><th>vert. max [m]</th><th>horiz. at end [m]</th></tr>")
        for name, m in methods.items():
            for o in m.get("outages", []):
                parts.append(f"<tr><td>{html.escape(name)}</td><td>{o['start_s']:g}-{o['end_s']:g}</td>"
                             f"<td>{_fmt(o['horizontal_max_m'])}</td><td>{_fmt(o['vertical_max_m'])}</td>"
                             f"<td>{_fmt(o['horizontal_final_m'])}</td></tr>")
        parts.append("</table>")
    rec = {n: m["recoveries"] for n, m in methods.items() if "recoveries" in m}
    if rec:
        parts.append("<h2>Numerical recoveries</h2><ul>" + "".join(
            f"<li>{html.escape(n)}: " + ", ".join(f"{html.escape(k)} {v}" for k, v in r.items()) + "</li>"
            for n, r in rec.items()) + "</ul>")
    if notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
    parts.append("<h2>Figures</h2>")
    for name, fig in figures.items():
        # render once: the same bytes go to the PNG file and into the page
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110)
        atomic_write_bytes(out_dir / f"{name}.png", buf.getvalue())
        b64 = base64.b64encode(buf.getvalue()).decode("ascii")
        parts.append(f"<h3>{html.escape(name)}</h3><img alt='{html.escape(name)}' src='data:image/png;base64,{b64}'>")
    if config_text:
        parts.append(f"<h2>Scenario</h2><pre>{html.escape(config_text)}</pre>")
    parts.append("</body></html>\n")
    path = out_dir / "report.html"
    atomic_write_text(path, "".join(parts))
    return path
