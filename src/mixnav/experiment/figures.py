"""Figures of solution tables.

Built on ``matplotlib.figure.Figure`` directly, never pyplot: no global
state, no backend selection, safe in worker processes.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from ..geodesy import earth

_KINDS = {
    "attitude": (("roll", "pitch", "yaw"), "deg", "attitude error"),
    "velocity": (("vn", "ve", "vd"), "mps", "velocity error"),
    "position": (("n", "e", "d"), "m", "position error"),
}
_LABEL_UNIT = {"deg": "deg", "mps": "m/s", "m": "m"}
_AXIS_NAME = {"roll": "roll", "pitch": "pitch", "yaw": "yaw", "vn": "north", "ve": "east",
              "vd": "down", "n": "north", "e": "east", "d": "down"}


def _shade(ax, outages):
    for a, b in outages:
        ax.axvspan(a, b, color="0.85", zorder=0, lw=0)


def error_figure(solutions: dict[str, pd.DataFrame], kind: str, outages=()) -> Figure:
    """Errors of each method with their +-3-sigma envelopes, three stacked axes."""
    if kind not in _KINDS:
        raise ValueError(f"unknown figure kind '{kind}'; choose one of {list(_KINDS)}")
    axes_names, unit, title = _KINDS[kind]
    fig = Figure(figsize=(9, 7), layout="constrained")
    axs = fig.subplots(3, 1, sharex=True)
    for i, (ax, a) in enumerate(zip(axs, axes_names)):
        _shade(ax, outages)
        for j, (name, df) in enumerate(solutions.items()):
            color = f"C{j}"
            t = df["time_s"].to_numpy()
            ax.plot(t, df[f"err_{a}_{unit}"], color=color, lw=1.0, label=name)
            sig = f"sig_{a}_{unit}"
            if sig in df.columns:
                s = 3 * df[sig].to_numpy()
                ax.plot(t, s, color=color, lw=0.8, ls="--")
                ax.plot(t, -s, color=color, lw=0.8, ls="--")
        ax.set_ylabel(f"{_AXIS_NAME[a]} [{_LABEL_UNIT[unit]}]")
        ax.grid(alpha=0.3)
    axs[0].set_title(f"{title} (estimate - truth); dashed: filter 3-sigma; grey: GNSS outage")
    axs[0].legend(loc="upper right", fontsize="small")
    axs[-1].set_xlabel("time [s]")
    return fig


def horizontal_error_figure(solutions: dict[str, pd.DataFrame], outages=()) -> Figure:
    """Horizontal position error against time, one line per method."""
    fig = Figure(figsize=(9, 3.5), layout="constrained")
    ax = fig.subplots()
    _shade(ax, outages)
    for j, (name, df) in enumerate(solutions.items()):
        ax.plot(df["time_s"], np.hypot(df["err_n_m"], df["err_e_m"]), color=f"C{j}", lw=1.0, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("horizontal error [m]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    return fig


def _local_ne(lat_deg, lon_deg, lat0, lon0):
    rm, rn = earth.radii(np.radians(lat0))
    n = np.radians(np.asarray(lat_deg) - lat0) * rm
    e = np.radians(np.asarray(lon_deg) - lon0) * rn * np.cos(np.radians(lat0))
    return n, e


def trajectory_figure(solutions: dict[str, pd.DataFrame], reference: pd.DataFrame | None = None,
                      gnss: pd.DataFrame | None = None, outages=()) -> Figure:
    """Plan view (north against east, metres about the first point)."""
    fig = Figure(figsize=(7, 7), layout="constrained")
    ax = fig.subplots()
    first = reference if reference is not None else next(iter(solutions.values()))
    lat0, lon0 = float(first["lat_deg"].iloc[0]), float(first["lon_deg"].iloc[0])
    if reference is not None:
        n, e = _local_ne(reference["lat_deg"], reference["lon_deg"], lat0, lon0)
        ax.plot(e, n, color="k", lw=1.5, label="truth / reference")
        t = reference["time_s"].to_numpy()
        for a, b in outages:
            sel = (t >= a) & (t <= b)
            ax.plot(e[sel], n[sel], color="orange", lw=4, alpha=0.6,
                    label="GNSS outage" if a == outages[0][0] else None)
    if gnss is not None and len(gnss):
        n, e = _local_ne(gnss["lat_deg"], gnss["lon_deg"], lat0, lon0)
        ax.plot(e, n, ".", color="0.5", ms=2, label="GNSS fixes")
    for j, (name, df) in enumerate(solutions.items()):
        n, e = _local_ne(df["lat_deg"], df["lon_deg"], lat0, lon0)
        ax.plot(e, n, color=f"C{j}", lw=1.0, label=name)
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    return fig
