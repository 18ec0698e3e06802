"""Figures of solution tables.

Built on ``matplotlib.figure.Figure`` directly, never pyplot: no global
state, no backend selection, safe in worker processes. ``Figure.savefig``
renders through the Agg canvas on its own.

Each method keeps one colour (``C0``, ``C1``, ... in the order of the
``solutions`` dict) across all figures.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from ..geodesy import earth

__all__ = ["error_figure", "horizontal_error_figure", "mode_probability_figure", "start_sweep_figure", "sweep_figure", "trajectory_figure"]

# kind -> (column stems, column unit suffix, title)
_KINDS = {
    "attitude": (("roll", "pitch", "yaw"), "deg", "attitude error"),
    "velocity": (("vn", "ve", "vd"), "mps", "velocity error"),
    "position": (("n", "e", "d"), "m", "position error"),
}
_LABEL_UNIT = {"deg": "deg", "mps": "m/s", "m": "m"}
_AXIS_NAME = {"roll": "roll", "pitch": "pitch", "yaw": "yaw", "vn": "north", "ve": "east",
              "vd": "down", "n": "north", "e": "east", "d": "down"}
_OUTAGE_GREY = "0.85"


def _shade(ax, outages: Sequence[tuple[float, float]]) -> None:
    """Grey bands behind the data for the GNSS outage windows [s]."""
    for a, b in outages:
        ax.axvspan(a, b, color=_OUTAGE_GREY, zorder=0, lw=0)


def _need(df: pd.DataFrame, name: str, method: str) -> None:
    if name not in df.columns:
        raise ValueError(f"solution of method '{method}' has no column '{name}'")


def error_figure(solutions: dict[str, pd.DataFrame], kind: str,
                 outages: Sequence[tuple[float, float]] = ()) -> Figure:
    """Errors of each method with their +-3-sigma envelopes, three stacked axes.

    Parameters
    ----------
    solutions : dict of str -> pandas.DataFrame
        Solution table of each method; needs ``time_s`` [s] and the
        ``err_*`` columns of ``kind``; ``sig_*`` columns are drawn when present.
    kind : {"attitude", "velocity", "position"}
        roll/pitch/yaw [deg], vn/ve/vd [m/s] or north/east/down [m].
    outages : sequence of (start_s, end_s)
        GNSS outage windows [s], shaded grey.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if kind not in _KINDS:
        raise ValueError(f"unknown figure kind '{kind}'; choose one of {list(_KINDS)}")
    stems, unit, title = _KINDS[kind]
    fig = Figure(figsize=(9, 7), layout="constrained")
    axs = fig.subplots(3, 1, sharex=True)
    for ax, a in zip(axs, stems):
        _shade(ax, outages)
        for j, (name, df) in enumerate(solutions.items()):
            color = f"C{j}"
            err = f"err_{a}_{unit}"
            _need(df, "time_s", name)
            _need(df, err, name)
            t = df["time_s"].to_numpy(dtype=float)
            ax.plot(t, df[err].to_numpy(dtype=float), color=color, lw=1.0, label=name)
            sig = f"sig_{a}_{unit}"
            if sig in df.columns:  # methods without a covariance have no envelope
                s = 3.0 * df[sig].to_numpy(dtype=float)
                ax.plot(t, s, color=color, lw=0.8, ls="--")
                ax.plot(t, -s, color=color, lw=0.8, ls="--")
        ax.set_ylabel(f"{_AXIS_NAME[a]} [{_LABEL_UNIT[unit]}]")
        ax.grid(alpha=0.3)
    axs[0].set_title(f"{title} (estimate - truth); dashed: filter 3-sigma; grey: GNSS outage")
    if solutions:
        axs[0].legend(loc="upper right", fontsize="small")
    axs[-1].set_xlabel("time [s]")
    return fig


def horizontal_error_figure(solutions: dict[str, pd.DataFrame],
                            outages: Sequence[tuple[float, float]] = ()) -> Figure:
    """Horizontal position error ``hypot(err_n, err_e)`` [m] against time, one line per method.

    Parameters
    ----------
    solutions : dict of str -> pandas.DataFrame
        Solution tables with ``time_s`` [s], ``err_n_m`` and ``err_e_m`` [m].
    outages : sequence of (start_s, end_s)
        GNSS outage windows [s], shaded grey.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=(9, 3.5), layout="constrained")
    ax = fig.subplots()
    _shade(ax, outages)
    for j, (name, df) in enumerate(solutions.items()):
        for col in ("time_s", "err_n_m", "err_e_m"):
            _need(df, col, name)
        h = np.hypot(df["err_n_m"].to_numpy(dtype=float), df["err_e_m"].to_numpy(dtype=float))
        ax.plot(df["time_s"].to_numpy(dtype=float), h, color=f"C{j}", lw=1.0, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("horizontal error [m]")
    ax.set_title("horizontal position error; grey: GNSS outage")
    ax.grid(alpha=0.3)
    if solutions:
        ax.legend(fontsize="small")
    return fig


def _local_ne(lat_deg, lon_deg, lat0_deg: float, lon0_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """North, east [m] of points about (lat0, lon0) [deg], flat Earth with WGS-84 radii there.

    Good to well under a metre over a few kilometres, which is all a plan view needs.
    """
    rm, rn = earth.radii(np.radians(lat0_deg))
    n = np.radians(np.asarray(lat_deg, dtype=float) - lat0_deg) * rm
    e = np.radians(np.asarray(lon_deg, dtype=float) - lon0_deg) * rn * np.cos(np.radians(lat0_deg))
    return n, e


def trajectory_figure(solutions: dict[str, pd.DataFrame], reference: pd.DataFrame | None = None,
                      gnss: pd.DataFrame | None = None,
                      outages: Sequence[tuple[float, float]] = ()) -> Figure:
    """Plan view: north against east [m] about the first reference (or solution) point.

    Parameters
    ----------
    solutions : dict of str -> pandas.DataFrame
        Solution tables with ``lat_deg``, ``lon_deg`` [deg]; one line each.
    reference : pandas.DataFrame, optional
        Truth or reference trajectory (``time_s`` [s], ``lat_deg``,
        ``lon_deg`` [deg]), drawn black; its stretches inside the outage
        windows are highlighted.
    gnss : pandas.DataFrame, optional
        GNSS fixes (``time_s``, ``lat_deg``, ``lon_deg``), drawn as dots.
    outages : sequence of (start_s, end_s)
        GNSS outage windows [s].

    Returns
    -------
    matplotlib.figure.Figure
    """
    if reference is not None:
        first = reference
    elif solutions:
        first = next(iter(solutions.values()))
    else:
        raise ValueError("trajectory_figure needs a reference or at least one solution")
    fig = Figure(figsize=(7, 7), layout="constrained")
    ax = fig.subplots()
    lat0, lon0 = float(first["lat_deg"].iloc[0]), float(first["lon_deg"].iloc[0])
    if reference is not None:
        n, e = _local_ne(reference["lat_deg"], reference["lon_deg"], lat0, lon0)
        ax.plot(e, n, color="k", lw=1.5, label="reference")
        t = reference["time_s"].to_numpy(dtype=float)
        for i, (a, b) in enumerate(outages):
            sel = (t >= a) & (t <= b)
            ax.plot(e[sel], n[sel], color="orange", lw=4, alpha=0.6, zorder=1.5,
                    label="GNSS outage" if i == 0 else None)
    if gnss is not None and len(gnss):
        n, e = _local_ne(gnss["lat_deg"], gnss["lon_deg"], lat0, lon0)
        ax.plot(e, n, ".", color="0.5", ms=2, label="GNSS fixes")
    for j, (name, df) in enumerate(solutions.items()):
        n, e = _local_ne(df["lat_deg"], df["lon_deg"], lat0, lon0)
        ax.plot(e, n, color=f"C{j}", lw=1.0, label=name)
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title(f"plan view about {lat0:.6f} deg, {lon0:.6f} deg")
    # datalim keeps the box size and stretches the limits, so metres look like metres
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    return fig


def mode_probability_figure(solutions: dict[str, pd.DataFrame],
                            outages: Sequence[tuple[float, float]] = ()) -> Figure | None:
    """IMM mode probabilities against time: one panel per method that has ``p_mode_<name>``
    columns (:func:`mixnav.experiment.outputs.solution_table`), one line per mode; None when
    no method has them."""
    imms = {name: [c for c in df.columns if c.startswith("p_mode_")] for name, df in solutions.items()}
    imms = {k: v for k, v in imms.items() if v}
    if not imms:
        return None
    fig = Figure(figsize=(9, 1.2 + 2.0 * len(imms)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(imms), 1, sharex=True, squeeze=False)[:, 0])
    for ax, (name, cols) in zip(axes, imms.items()):
        df = solutions[name]
        _shade(ax, outages)
        t = df["time_s"].to_numpy(dtype=float)
        for k, c in enumerate(cols):
            ax.plot(t, df[c].to_numpy(dtype=float), color=f"C{k}", lw=1.0, label=c.removeprefix("p_mode_"))
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("probability")
        ax.set_title(f"{name}: mode probabilities; grey: GNSS outage")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small", loc="center right")
    axes[-1].set_xlabel("time [s]")
    return fig


def noise_sigma_figure(solutions: dict[str, pd.DataFrame], truth=None,
                       outages: Sequence[tuple[float, float]] = ()) -> Figure | None:
    """The measurement-noise sigma VB-adaptive filters tracked (``vb_sigma_<channel>``
    columns) against time: one panel per observable (position, velocity), one colour per
    axis, one line style per method; the true sd of the simulated noise in black where
    ``truth = (times, {channel: sd})`` has it. None when no method tracked a sigma."""
    cols = {name: [c for c in df.columns if c.startswith("vb_sigma_")] for name, df in solutions.items()}
    cols = {k: v for k, v in cols.items() if v}
    if not cols:
        return None
    kinds = sorted({c.removeprefix("vb_sigma_").rsplit("_", 1)[0] for v in cols.values() for c in v})
    fig = Figure(figsize=(9, 1.2 + 2.4 * len(kinds)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(kinds), 1, sharex=True, squeeze=False)[:, 0])
    styles = ["-", "--", ":", "-."]
    for ax, kind in zip(axes, kinds):
        _shade(ax, outages)
        for m, (name, cs) in enumerate(cols.items()):
            df = solutions[name]
            t = df["time_s"].to_numpy(dtype=float)
            first = True
            for c in cs:
                label = c.removeprefix("vb_sigma_")
                if not label.startswith(kind + "_"):
                    continue
                axis = label.rsplit("_", 1)[1]
                k = "ned".find(axis) if axis in ("n", "e", "d") else cs.index(c)
                # many channels (a pseudorange per satellite): one legend entry per method
                text = f"{name} {axis}" if len(cs) <= 12 else (f"{name} (one line per channel)" if first else None)
                first = False
                ax.plot(t, df[c].to_numpy(dtype=float), color=f"C{k % 10}",
                        ls=styles[m % len(styles)], lw=1.0, label=text)
        if truth is not None:
            tt, sd = truth
            for axis in "ned":
                key = f"{kind}_{axis}"
                if key in sd:
                    ax.plot(tt, sd[key], color="k", lw=0.8, alpha=0.6,
                            label="true sd" if axis == "n" else None)
        ax.set_ylabel("m/s" if kind in ("velocity", "range_rate") else "m")
        ax.set_title(f"{kind}: tracked noise sigma; grey: GNSS outage")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="x-small", loc="upper left", ncol=4)
    axes[-1].set_xlabel("time [s]")
    return fig


def sweep_figure(rows: pd.DataFrame, settings: dict | None = None) -> Figure:
    """An outage sweep (:mod:`mixnav.experiment.sweep`): each method's horizontal maximum in
    each window against the window's start (log scale), and below it what the vehicle did
    in the window by the reference: distance [m] and course change [deg] (bars) and the time
    it stood still [s] (line). ``rows``: the sweep's rows (``method, start_s, end_s,
    horizontal_max_m, distance_m, heading_change_deg, still_s``)."""
    for k in ("method", "start_s", "end_s", "horizontal_max_m", "distance_m", "heading_change_deg", "still_s"):
        _need(rows, k, "sweep")
    fig = Figure(figsize=(9.0, 6.0), layout="constrained")
    ax, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    for i, (name, g) in enumerate(rows.groupby("method", sort=False)):
        ax.semilogy(g["start_s"], g["horizontal_max_m"], "o-", ms=3, lw=1, color=f"C{i}", label=str(name))
    ax.set_ylabel("horizontal max in window [m]")
    window = settings.get("window_s") if settings else None
    ax.set_title("outage sweep" + (f": {window:g} s windows" if window else "") + ", by window start")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    w = rows.drop_duplicates("start_s")
    width = float(np.min(np.diff(w["start_s"]))) * 0.8 if len(w) > 1 else 1.0
    ax2.bar(w["start_s"], w["distance_m"], width=width, color="0.6", label="distance [m]")
    ax2.bar(w["start_s"], w["heading_change_deg"], width=width * 0.4, color="C3", alpha=0.7,
            label="course change [deg]")
    ax2.plot(w["start_s"], w["still_s"], "k.-", lw=1, label="still [s]")
    ax2.set_xlabel("window start [s]")
    ax2.set_ylabel("in the window")
    ax2.grid(True, alpha=0.3)
    ax2.legend(fontsize="x-small", ncol=3)
    return fig


def start_sweep_figure(rows: pd.DataFrame, settings: dict | None = None) -> Figure:
    """A start sweep (:mod:`mixnav.experiment.sweep`): each method's 2-D RMSE from its own
    start (solid) and on the span every run covers (dashed) against the start time."""
    for k in ("method", "start_s", "horizontal_rmse_m", "common_horizontal_rmse_m"):
        _need(rows, k, "start sweep")
    fig = Figure(figsize=(8.0, 4.5), layout="constrained")
    ax = fig.subplots()
    for i, (name, g) in enumerate(rows.groupby("method", sort=False)):
        ax.plot(g["start_s"], g["horizontal_rmse_m"], "o-", color=f"C{i}", label=f"{name}")
        ax.plot(g["start_s"], g["common_horizontal_rmse_m"], "s--", color=f"C{i}", alpha=0.6, ms=4)
    span = (settings or {}).get("common_span_s")
    ax.set_title("start sweep: 2-D RMSE from each start (solid)"
                 + (f" and on {span[0]:.0f}-{span[1]:.0f} s (dashed)" if span else ""))
    ax.set_xlabel("start [s]")
    ax.set_ylabel("horizontal RMSE [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", ncol=2)
    return fig
