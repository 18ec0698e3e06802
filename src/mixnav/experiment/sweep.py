"""Accuracy as a distribution, not one favourable case: the outage sweep and the start sweep.

:func:`outage_sweep` withholds the GNSS in one window at a time, sliding across the whole
recording after the alignment (the dataset's own ``withhold`` windows are not withheld in
the sweep), runs every method of the dataset on each, and scores each method inside the
window against the reference: one row per method and window (:data:`OUTAGE_SWEEP_COLUMNS`).
The file is read once; the windows run in this process, on local worker processes or on a
Dask cluster, each from the same read data, so a window gives the same row wherever it
runs.

:func:`summarize` reduces the rows to the block that ``metrics.json`` carries per method
(``outage_sweep``): the median, 90th percentile and worst of the windows' horizontal
maxima and the share of windows whose mean position NEES is above the chi-square(3) 99 %
bound. :class:`SweepResult` is what ``mixnav process --outage-sweep`` writes beside the
dataset's own outputs (``outage_sweep.csv``, the block, a figure and a report table).

:func:`start_sweep`, for datasets that start from their own data (odometry-gnss, gnss-raw), runs the
whole causal pipeline from several start times (the data before each discarded, as if the
recording began there) and scores each run from its own start and on the span every run
covers (from the last run's filter start to the end): one row per method and start
(:data:`START_SWEEP_COLUMNS`), ``start_sweep.csv`` and a ``start_sweep`` block.
"""

from __future__ import annotations

import math
import os
import time as _time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import chi2

from .. import units as u
from ..errors import ArgumentError, ConfigError, DataError, MixnavError

__all__ = ["outage_sweep", "run_outage_sweep", "start_sweep", "run_start_sweep", "summarize", "summarize_starts",
           "sweep_windows", "SweepResult", "OUTAGE_SWEEP_COLUMNS", "START_SWEEP_COLUMNS", "NEES_POS_99"]

#: One row per method and window: the window [s], the method's errors inside it (and in the
#: unaided stretch until the next GNSS update) [m], its mean NEES there, and what the vehicle
#: did in it according to the reference: distance [m], course change [deg], time still [s].
OUTAGE_SWEEP_COLUMNS = ("method", "start_s", "end_s", "horizontal_max_m", "horizontal_rmse_m", "vertical_max_m",
                        "nees_pos_mean", "nees_vel_mean", "distance_m", "heading_change_deg", "still_s")

#: One row per method and start time: the start [s] and where the filters began after the
#: alignment [s]; the 2-D error from the run's own start (RMSE, p95, max [m], epochs) and on
#: the span every run covers (``common_*``).
START_SWEEP_COLUMNS = ("method", "start_s", "filter_start_s", "horizontal_rmse_m", "horizontal_p95_m",
                       "horizontal_max_m", "n_epochs", "common_start_s", "common_horizontal_rmse_m",
                       "common_horizontal_p95_m", "common_horizontal_max_m")

#: The chi-square(3) 99 % point (11.34): a window whose mean 3-D position NEES is above it is
#: counted in ``share_nees_above_99``. The per-epoch bound, applied to the window's mean, as the
#: NEES tables of benchmarks/results/ read it: lenient for a long window (the mean of
#: independent epochs would have a tighter bound), but the epochs of an outage are strongly
#: correlated, so the per-epoch bound is the honest one to state.
NEES_POS_99 = float(chi2.ppf(0.99, 3))

#: Below this speed [m/s] (from the reference's successive positions) the vehicle counts as still.
STILL_SPEED_MPS = 0.2


def _seconds(value, argument: str) -> float:
    """A time given as a number of seconds or as text with a unit (``"30 s"``), in seconds."""
    if value is None:
        raise ArgumentError("is required", argument=argument)
    if isinstance(value, str):
        try:
            return float(u.parse_quantity(value, u.TIME))
        except MixnavError as exc:
            raise ArgumentError(str(exc), argument=argument) from None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ArgumentError(f"expected seconds or a time with its unit ('30 s'), got {value!r}", argument=argument)
    v = float(value)
    if not math.isfinite(v):
        raise ArgumentError(f"must be finite, got {value!r}", argument=argument)
    return v


def sweep_windows(first: float, last: float, window: float, step: float) -> list[tuple[float, float]]:
    """The windows ``[s, s + window]`` for ``s = first, first + step, ...`` that end by ``last``
    (all times in seconds). An ArgumentError names ``window`` when it does not fit in
    ``[first, last]`` and ``step`` when it is not positive."""
    if not window > 0:
        raise ArgumentError(f"must be positive, got {window:g} s", argument="window")
    if not step > 0:
        raise ArgumentError(f"must be positive, got {step:g} s", argument="step")
    if window > last - first:
        raise ArgumentError(f"a {window:g} s window does not fit in the span {first:.1f} - {last:.1f} s "
                            f"({last - first:.1f} s) of the recording after the alignment", argument="window")
    n = int(math.floor((last - first - window) / step + 1e-9)) + 1
    return [(first + i * step, first + i * step + window) for i in range(n)]


def window_motion(reference, start: float, end: float) -> dict:
    """What the vehicle did in ``[start, end]`` by the reference's positions: ``distance_m``
    (horizontal path length), ``heading_change_deg`` (sum of the course's absolute changes
    between moving steps) and ``still_s`` (time at below :data:`STILL_SPEED_MPS`)."""
    from ..geodesy.frames import lla_to_ned
    sel = (reference.time >= start) & (reference.time <= end)
    t, lla = reference.time[sel], reference.lla[sel]
    if len(t) < 2:
        return {"distance_m": 0.0, "heading_change_deg": 0.0, "still_s": 0.0}
    ned = lla_to_ned(lla, lla[0])
    d = np.diff(ned[:, :2], axis=0)
    step = np.hypot(d[:, 0], d[:, 1])
    dt = np.diff(t)
    speed = np.divide(step, dt, out=np.zeros_like(step), where=dt > 0)
    moving = speed >= STILL_SPEED_MPS
    course = np.arctan2(d[:, 1], d[:, 0])
    both = moving[1:] & moving[:-1]
    turn = np.angle(np.exp(1j * np.diff(course)))[both]
    return {"distance_m": float(step.sum()), "heading_change_deg": float(np.degrees(np.abs(turn).sum())),
            "still_s": float(dt[~moving].sum())}


def summarize(rows: pd.DataFrame) -> dict[str, dict]:
    """Per method, the ``outage_sweep`` block of metrics.json: ``n_windows``,
    ``{median,p90,worst}_horizontal_max_m``, ``median_horizontal_rmse_m``,
    ``worst_window_start_s`` and ``share_nees_above_99`` (the share of windows with a mean
    position NEES above :data:`NEES_POS_99`; absent for a method without covariances)."""
    out: dict[str, dict] = {}
    for name, g in rows.groupby("method", sort=False):
        h = g["horizontal_max_m"].to_numpy(float)
        b = {"n_windows": int(len(g)),
             "median_horizontal_max_m": float(np.median(h)),
             "p90_horizontal_max_m": float(np.percentile(h, 90)),
             "worst_horizontal_max_m": float(h.max()),
             "worst_window_start_s": float(g["start_s"].to_numpy(float)[int(np.argmax(h))]),
             "median_horizontal_rmse_m": float(np.median(g["horizontal_rmse_m"].to_numpy(float)))}
        nees = g["nees_pos_mean"].to_numpy(float)
        if np.isfinite(nees).any():
            b["share_nees_above_99"] = float(np.mean(nees[np.isfinite(nees)] > NEES_POS_99))
        out[str(name)] = b
    return out


@dataclass
class SweepResult:
    """A sweep's rows (:data:`OUTAGE_SWEEP_COLUMNS`), its settings and the windows it left out."""

    kind: str                     # "outage_sweep"
    rows: pd.DataFrame
    settings: dict = field(default_factory=dict)

    @property
    def summary(self) -> dict[str, dict]:
        return summarize(self.rows) if self.kind == "outage_sweep" else summarize_starts(self.rows)

    def figure(self):
        """Outage sweep: each method's horizontal maximum against the window's start, with the
        distance and course change of each window below (the vehicle's motion by the
        reference). Start sweep: each method's RMSE from its own start and on the common span
        against the start time."""
        from .figures import start_sweep_figure, sweep_figure
        return sweep_figure(self.rows, self.settings) if self.kind == "outage_sweep" else \
            start_sweep_figure(self.rows, self.settings)

    def section_html(self) -> str:
        """The report's table: per method the distribution over the windows or start times."""
        from .report import start_sweep_table, sweep_table
        return sweep_table(self.summary, self.settings) if self.kind == "outage_sweep" else \
            start_sweep_table(self.summary, self.settings)


# ---------------------------------------------------------------- running one window

#: Per process: (dataset reference, data folder) -> (dataset, source, pipeline, folder, inputs).
_LOADED: dict[tuple, tuple] = {}


def _load(dataset: str, data: str | None):
    key = (dataset, data)
    if key not in _LOADED:
        from ..config import load_dataset
        from .data_folder import find_data_dir
        from .pipelines import pipeline
        ds, source, _ = load_dataset(dataset)
        p = pipeline(ds, source)
        folder = find_data_dir(ds, data, source)
        _LOADED.clear()   # one dataset per worker at a time: the inputs can be large
        _LOADED[key] = (ds, source, p, folder, p.load(ds, source, folder))
    return _LOADED[key]


def _run_quietly(p, ds, source, folder, inputs):
    """The pipeline's run of ``ds`` without the data's warnings: the sweep's first run said them."""
    from ..io.imu_checks import DataWarning
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return p.run(ds, source, folder, inputs)


def _window_rows(dataset: str, data: str | None, window: tuple[float, float]) -> list[dict]:
    """Every method's row for one withheld window (runs anywhere: loads the dataset once per
    process); none when the alignment, which needs GNSS, moved past the window's start."""
    from .ins_common import with_withheld
    ds, source, p, folder, inputs = _load(dataset, data)
    po = _run_quietly(p, with_withheld(ds, [window]), source, folder, inputs)
    if po.init.time > window[0]:
        return []
    metrics = p.metrics(po, p.tables(po))
    rows = []
    for name, m in metrics.items():
        o = m["outages"][0]
        rows.append({"method": name, "start_s": float(window[0]), "end_s": float(window[1]),
                     "horizontal_max_m": o["horizontal_max_m"], "horizontal_rmse_m": o["horizontal_rmse_m"],
                     "vertical_max_m": o["vertical_max_m"], "nees_pos_mean": o.get("nees_pos_mean", math.nan),
                     "nees_vel_mean": o.get("nees_vel_mean", math.nan)})
    return rows


def _worker_init(dataset: str, data: str | None) -> None:
    from .parallel import die_with_parent
    die_with_parent()
    _load(dataset, data)


def _dataset_ref(dataset) -> str:
    """A dataset as another process (or folder) can load it: a shipped name, or a file's absolute path."""
    p = Path(str(dataset))
    return str(p.resolve()) if p.suffix == ".toml" or p.exists() else str(dataset)


@contextmanager
def _said_as_keys(source: str, keys: dict[str, str]):
    """An ArgumentError about a value read from ``[evaluation]`` (``keys``: argument ->
    ``evaluation.<key>``) becomes a ConfigError naming the file and the key, not an argument
    the caller did not give."""
    try:
        yield
    except ArgumentError as exc:
        if exc.argument in keys:
            raise ConfigError(exc.message, file=source, key=keys[exc.argument]) from None
        raise


def _from_file(ev, **arguments) -> dict[str, str]:
    """argument -> ``evaluation.<key>`` for each argument (``name=(value, key)``) left as None
    that the dataset's ``[evaluation]`` gives."""
    return {a: f"evaluation.{k}" for a, (v, k) in arguments.items()
            if v is None and ev is not None and getattr(ev, k) is not None}


def run_outage_sweep(dataset, window=None, step=None, span=None, *, data=None, workers: int | None = None,
                     scheduler: str | None = None, progress: bool = False) -> SweepResult:
    """:func:`outage_sweep` with its settings and skipped windows (:class:`SweepResult`)."""
    from ..config import load_dataset
    from .pipelines import pipeline_key
    ref = _dataset_ref(dataset)
    ds, source, _ = load_dataset(ref)
    ev = getattr(ds, "evaluation", None)
    key = pipeline_key(ds)
    if key not in ("ins-gnss", "ins-gnss+raw-gnss"):
        raise ConfigError(f"an outage sweep withholds GNSS from an INS; dataset kind '{key}' has no GNSS "
                          "to withhold from an IMU (ins-gnss datasets only; a start sweep suits this kind)",
                          file=source, key="evaluation.outage_sweep")
    if ds.reference is None:
        raise ConfigError("an outage sweep scores the withheld windows against the reference: the dataset "
                          "has no [reference]", file=source, key="reference")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ArgumentError(f"must be a positive integer, got {workers!r}", argument="workers")
    keys = _from_file(ev, window=(window, "outage_sweep"), step=(step, "sweep_step"), span=(span, "sweep_span"))
    with _said_as_keys(source, keys):
        window = _seconds(window if window is not None else (ev.outage_sweep if ev else None), "window")
        step = _seconds(step, "step") if step is not None else \
            (ev.sweep_step if ev is not None and ev.sweep_step is not None else window / 3.0)
        if span is None and ev is not None and ev.sweep_span is not None:
            span = ev.sweep_span
        return _outage_sweep(ref, source, window, step, span, data, workers, scheduler, progress)


def _outage_sweep(ref, source, window, step, span, data, workers, scheduler, progress) -> SweepResult:
    # the run without any window: where the alignment ends and the GNSS and reference end
    t0 = _time.perf_counter()
    ds, source_, p, folder, inputs = _load(ref, None if data is None else str(data))
    from .ins_common import with_withheld
    base = p.run(with_withheld(ds, []), source_, folder, inputs)   # says the data's warnings, once
    first = math.ceil(base.init.time)
    last = float(min(base.all_fixes.time[-1], base.reference.time[-1], base.imu.time[-1]))
    if span is not None:
        a, b = (_seconds(span[0], "span"), _seconds(span[1], "span"))
        if not b > a:
            raise ArgumentError(f"ends ({b:g} s) before it starts ({a:g} s)", argument="span")
        if a < first or b > last:
            raise ArgumentError(f"[{a:g}, {b:g}] s is not inside the recording after the alignment "
                                f"[{first:g}, {last:.1f}] s", argument="span")
        first, last = a, b
    windows = sweep_windows(first, last, window, step)
    # a window the reference does not cover cannot be scored: left out, and said
    scored = [w for w in windows if np.any((base.reference.time >= w[0]) & (base.reference.time <= w[1]))]
    skipped = [w for w in windows if w not in scored]
    if not scored:
        raise DataError(f"the reference covers none of the {len(windows)} sweep windows in "
                        f"[{first:g}, {last:.1f}] s: nothing to score", file=source)
    rows = [r for rs in _run_tasks(_window_rows, ref, None if data is None else str(data), scored, workers,
                                   scheduler, progress, "windows") for r in rs]
    ran = {(r["start_s"], r["end_s"]) for r in rows}
    late = [w for w in scored if w not in ran]   # the alignment waited for GNSS past the window's start
    scored = [w for w in scored if w in ran]
    if not scored:
        raise DataError(f"no sweep window in [{first:g}, {last:.1f}] s could be scored: the reference covers "
                        f"{len(scored) + len(late)} of {len(windows)}, and in those the alignment waits for the "
                        "withheld GNSS", file=source)
    df = pd.DataFrame(rows)
    motion = {w: window_motion(base.reference, *w) for w in scored}
    for k in ("distance_m", "heading_change_deg", "still_s"):
        df[k] = [motion[(a, b)][k] for a, b in zip(df["start_s"], df["end_s"])]
    order = {name: i for i, name in enumerate(base.results)}
    df = df.sort_values(["method", "start_s"], key=lambda c: c.map(order) if c.name == "method" else c,
                        kind="stable").reset_index(drop=True)[list(OUTAGE_SWEEP_COLUMNS)]
    settings = {"window_s": window, "step_s": step, "span_s": [first, last], "n_windows": len(scored),
                "skipped_windows_no_reference": [list(w) for w in skipped],
                "skipped_windows_alignment": [list(w) for w in late],
                "aligned_at_s": float(base.init.time), "wall_time_s": _time.perf_counter() - t0}
    return SweepResult("outage_sweep", df, settings)


def _run_tasks(task, ref: str, data: str | None, items, workers, scheduler, progress, label) -> list:
    """``task(ref, data, item)`` for every item: here, on a local process pool or on a Dask
    cluster, with a progress bar; the results in completion order."""
    from .parallel import Progress, dask_client, dask_map, pool_map
    bar = Progress(len(items), progress, label=label)
    tasks = [(ref, data, it) for it in items]
    try:
        if scheduler:
            client = dask_client(scheduler.strip())
            try:
                return dask_map(client, task, tasks, bar)
            finally:
                client.close()
        if (workers or os.cpu_count() or 1) == 1 or len(items) < 2:
            out = []
            for t in tasks:
                out.append(task(*t))
                bar.advance()
            return out
        return pool_map(task, tasks, min(workers or os.cpu_count() or 1, len(items)), bar,
                        initializer=_worker_init, initargs=(ref, data))
    finally:
        bar.close()


def outage_sweep(dataset, window=None, step=None, span=None, *, data=None, workers: int | None = None,
                 scheduler: str | None = None, progress: bool = False) -> pd.DataFrame:
    """Withhold the GNSS in one window at a time across a recording and score every method in each.

    Parameters
    ----------
    dataset : str
        A shipped dataset config (``mixnav.config.list_datasets()``) or a .toml file, of kind
        ``ins-gnss`` (fixes or RINEX) with a ``[reference]``.
    window : str or float, optional
        The outage length: ``"30 s"`` or seconds (default: ``[evaluation] outage_sweep``).
    step : str or float, optional
        Between window starts (default: ``[evaluation] sweep_step``, else a third of ``window``).
    span : (start, end), optional
        Times [s since the first IMU sample, or text with units] the windows must lie in
        (default: ``[evaluation] sweep_span``, else from the alignment, rounded up to a whole
        second, to the last GNSS or reference epoch).
    data : str, optional
        Folder holding the data files (default: the config's ``data_dir``).
    workers : int, optional
        Local worker processes (default: all cores; 1 runs in this process).
    scheduler : str, optional
        A Dask scheduler's address (``tcp://host:8786``) to run the windows on instead.
    progress : bool
        A progress bar on stderr.

    Returns
    -------
    pandas.DataFrame
        One row per method and window, columns :data:`OUTAGE_SWEEP_COLUMNS`, in the order of
        the dataset's methods, then of the windows. :func:`summarize` gives the per-method
        distribution. Windows the reference does not cover are left out
        (:func:`run_outage_sweep` lists them).

    Raises
    ------
    ArgumentError
        A window longer than the span, a step that is not positive, a span outside the
        recording (the message names the argument).
    ConfigError
        A dataset with no GNSS to withhold from an IMU, or without a reference.
    """
    return run_outage_sweep(dataset, window, step, span, data=data, workers=workers, scheduler=scheduler,
                            progress=progress).rows


# ---------------------------------------------------------------- the start sweep

def summarize_starts(rows: pd.DataFrame) -> dict[str, dict]:
    """Per method, the ``start_sweep`` block of metrics.json: ``n_starts``, the median and
    worst of the runs' RMSE from their own start (``{median,worst}_horizontal_rmse_m``,
    ``worst_start_s``) and on the common span (``{median,worst}_common_horizontal_rmse_m``)."""
    out: dict[str, dict] = {}
    for name, g in rows.groupby("method", sort=False):
        r, c = g["horizontal_rmse_m"].to_numpy(float), g["common_horizontal_rmse_m"].to_numpy(float)
        out[str(name)] = {"n_starts": int(len(g)), "median_horizontal_rmse_m": float(np.median(r)),
                          "worst_horizontal_rmse_m": float(r.max()),
                          "worst_start_s": float(g["start_s"].to_numpy(float)[int(np.argmax(r))]),
                          "median_common_horizontal_rmse_m": float(np.median(c)),
                          "worst_common_horizontal_rmse_m": float(c.max())}
    return out


def _start_run(dataset: str, data: str | None, start: float) -> dict:
    """One run from ``start``: per method its own-start scores and the (time, 2-D error) series
    the common span is scored on later (runs anywhere: loads the dataset once per process)."""
    ds, source, p, folder, inputs = _load(dataset, data)
    if start > 0:
        out = _run_quietly(p, p.with_start(ds, start), source, folder, inputs)
    else:   # the first start's run says the data's warnings
        out = p.run(p.with_start(ds, start), source, folder, inputs)
    if getattr(out, "init", None) is None:
        raise ConfigError("a start sweep moves the filters' start: the dataset has no filter method (only the "
                          "epoch-by-epoch SPP, which no start changes)", file=source, key="methods")
    t_start = float(out.init.time)
    runs = {}
    for name, t in p.tables(out).items():
        if "err_n_m" not in t:
            raise ConfigError("a start sweep scores every run against the reference: the dataset has none",
                              file=source, key="reference")
        time = t["time_s"].to_numpy(float)
        h = np.hypot(t["err_n_m"].to_numpy(float), t["err_e_m"].to_numpy(float))
        # from the filters' start on, at the epochs with a solution (a raw-GNSS table has a row
        # for every epoch, empty before the start and where the SPP failed)
        keep = (time >= t_start - 1e-9) & np.isfinite(h)
        time, h = time[keep], h[keep]
        if not len(h):
            raise DataError(f"method '{name}' has no solution after the start {start:g} s", file=source)
        runs[name] = {"filter_start_s": t_start, "horizontal_rmse_m": float(np.sqrt(np.mean(h ** 2))),
                      "horizontal_p95_m": float(np.percentile(h, 95)), "horizontal_max_m": float(h.max()),
                      "n_epochs": int(len(h)), "time": time, "h": h}
    return {"start": float(start), "runs": runs}


def run_start_sweep(dataset, step=None, span=None, *, data=None, workers: int | None = None,
                    scheduler: str | None = None, progress: bool = False) -> SweepResult:
    """:func:`start_sweep` with its settings (:class:`SweepResult`)."""
    from ..config import load_dataset
    from .pipelines import pipeline
    ref = _dataset_ref(dataset)
    ds, source, _ = load_dataset(ref)
    ev = getattr(ds, "evaluation", None)
    p = pipeline(ds, source)
    if not hasattr(p, "with_start"):
        raise ConfigError(f"a start sweep runs the whole causal pipeline from later starts; dataset kind "
                          f"'{ds.dataset.kind}' does not start from its own data (odometry-gnss and gnss-raw "
                          "do; an outage sweep suits an IMU + GNSS dataset)", file=source, key="evaluation.start_sweep")
    if getattr(ds, "reference", None) is None and getattr(ds, "reference_point", None) is None:
        raise ConfigError("a start sweep scores every run against the reference: the dataset has no "
                          "[reference] or [reference_point]", file=source, key="reference")
    keys = _from_file(ev, step=(step, "start_sweep"), span=(span, "sweep_span"))
    with _said_as_keys(source, keys):
        step = _seconds(step if step is not None else (ev.start_sweep if ev else None), "step")
        if not step > 0:
            raise ArgumentError(f"must be positive, got {step:g} s", argument="step")
        if span is None and ev is not None and ev.sweep_span is not None:
            span = ev.sweep_span
        return _start_sweep(ref, source, step, span, data, workers, scheduler, progress)


def _start_sweep(ref, source, step, span, data, workers, scheduler, progress) -> SweepResult:
    t0 = _time.perf_counter()
    first = _start_run(ref, None if data is None else str(data), 0.0)
    end = float(max(r["time"][-1] for r in first["runs"].values()))
    if span is None:   # at least half the recording left to score from the last start
        a, b = 0.0, 0.5 * end
    else:
        a, b = _seconds(span[0], "span"), _seconds(span[1], "span")
        if not b >= a:
            raise ArgumentError(f"ends ({b:g} s) before it starts ({a:g} s)", argument="span")
        if b >= end:
            raise ArgumentError(f"[{a:g}, {b:g}] s: the last start must be before the recording's end "
                                f"({end:.1f} s)", argument="span")
    starts = [a + i * step for i in range(int(math.floor((b - a) / step + 1e-9)) + 1)]
    rest = [t for t in starts if t != 0.0]
    runs = ([first] if 0.0 in starts else []) + _run_tasks(_start_run, ref, None if data is None else str(data),
                                                           rest, workers, scheduler, progress, "starts")
    runs.sort(key=lambda r: r["start"])
    common = max(r["filter_start_s"] for run in runs for r in run["runs"].values())
    rows = []
    for run in runs:
        for name, r in run["runs"].items():
            sel = r["time"] >= common
            h = r["h"][sel]
            rows.append({"method": name, "start_s": run["start"], "filter_start_s": r["filter_start_s"],
                         "horizontal_rmse_m": r["horizontal_rmse_m"], "horizontal_p95_m": r["horizontal_p95_m"],
                         "horizontal_max_m": r["horizontal_max_m"], "n_epochs": r["n_epochs"],
                         "common_start_s": common, "common_horizontal_rmse_m": float(np.sqrt(np.mean(h ** 2))),
                         "common_horizontal_p95_m": float(np.percentile(h, 95)),
                         "common_horizontal_max_m": float(h.max())})
    order = {name: i for i, name in enumerate(first["runs"])}
    df = pd.DataFrame(rows).sort_values(["method", "start_s"], key=lambda c: c.map(order) if c.name == "method"
                                        else c, kind="stable").reset_index(drop=True)[list(START_SWEEP_COLUMNS)]
    settings = {"step_s": step, "starts_s": starts, "common_span_s": [common, end],
                "wall_time_s": _time.perf_counter() - t0}
    return SweepResult("start_sweep", df, settings)


def start_sweep(dataset, step=None, span=None, *, data=None, workers: int | None = None,
                scheduler: str | None = None, progress: bool = False) -> pd.DataFrame:
    """Run the whole causal pipeline from several start times and score each run.

    Parameters
    ----------
    dataset : str
        A shipped dataset config or a .toml file that starts from its own data and has a
        reference: ``odometry-gnss`` (e.g. ``"smartloc-berlin"``: ``[alignment] start``, the
        data before it discarded) or ``gnss-raw`` with filter methods (``[motion] start``:
        the filters start at the first SPP fix at or after it; the SPP rows, epoch by
        epoch, are scored from there too).
    step : str or float, optional
        Between the start times: ``"30 s"`` or seconds (default: ``[evaluation] start_sweep``).
    span : (first, last), optional
        The first and last start time [s since the first odometry sample, or text with
        units] (default: ``[evaluation] sweep_span``, else from 0 to half the recording).
    data, workers, scheduler, progress
        As :func:`outage_sweep`.

    Returns
    -------
    pandas.DataFrame
        One row per method and start, columns :data:`START_SWEEP_COLUMNS`: each run scored
        from its own filter start and on the common span (from the latest filter start of
        all runs to the end); :func:`summarize_starts` gives the per-method distribution.

    Raises
    ------
    ArgumentError
        A step that is not positive, a span that ends before it starts or at the recording's end.
    ConfigError
        A dataset kind that does not align from its own data, or no reference.
    """
    return run_start_sweep(dataset, step, span, data=data, workers=workers, scheduler=scheduler,
                           progress=progress).rows
