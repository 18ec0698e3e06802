"""The library API for notebooks: everything ``mixnav`` does, from Python, as DataFrames.

    import mixnav
    run = mixnav.run_scenario("loose-demo", seed=1)
    run.metrics                      # one row per method
    run.solutions["ekf"]             # the solution table (docs/outputs.md)

    res = mixnav.filter_loose(imu, fixes, init, imu_model=mixnav.imu_grade("mems"))
    res.table                        # your own data, one call

Every function validates its arguments and names the one that is wrong
(:class:`mixnav.errors.ArgumentError`); units and shapes are in the
docstrings (SI units, radians).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .data import GnssFixes, ImuData, InitialState
from .errors import ArgumentError

__all__ = ["RunResult", "LooseResult", "ExperimentResult", "run_scenario", "process_dataset", "run_experiment",
           "tune", "outage_sweep", "start_sweep", "filter_loose", "imu_grade", "export_rinex"]


@dataclass
class RunResult:
    """A scenario run or a processed dataset, as DataFrames.

    Attributes
    ----------
    solutions : dict of str -> pandas.DataFrame
        Per method, the solution table (columns in docs/outputs.md; errors
        against the truth or reference when there is one).
    metrics : pandas.DataFrame
        One row per method: RMSE and maxima, NEES/NIS, timing, recovery counts.
    results : dict of str -> FilterResult
        The raw results (arrays, covariances, ``estimates`` per state block).
    truth : pandas.DataFrame or None
        The truth (scenario) or reference (dataset) trajectory: time_s, lat_deg, lon_deg, height_m.
    installation : dict
        A processed dataset's installation check (level at rest, rest window, the
        estimated installation states and the values to configure; docs/aiding.md);
        empty for a scenario.
    """

    solutions: dict
    metrics: "object"
    results: dict
    truth: "object" = None
    _output: object = field(default=None, repr=False)
    _config_text: str | None = field(default=None, repr=False)

    @property
    def installation(self) -> dict:
        return dict(getattr(self._output, "installation", None) or {})

    def write(self, out_dir, overwrite: bool = False) -> dict:
        """Write what ``mixnav run`` / ``mixnav process`` writes (tables, metrics.json,
        figures, report.html) into ``out_dir``; returns the metrics dictionary. The folder
        policy of the commands applies (docs/validation.md): a non-empty folder that is not
        the same command's output is refused unless ``overwrite``."""
        if hasattr(self._output, "sim"):  # a simulated run
            from .experiment.run import write_run
            return write_run(Path(out_dir), self._output, self._config_text, overwrite=overwrite)
        from .experiment.pipelines import pipeline
        return pipeline(self._output.dataset).write(Path(out_dir), self._output, self._config_text,
                                                    overwrite=overwrite)


def _metrics_frame(metrics: dict):
    import pandas as pd
    rows = {}
    for name, m in metrics.items():
        row = {k: v for k, v in m.items() if not isinstance(v, (dict, list))}
        row.update({f"recoveries.{k}": v for k, v in m.get("recoveries", {}).items()})
        for seg, sm in m.get("segments", {}).items():   # a scenario's [scoring] segments
            row.update({f"segment_{seg}_{k}": v for k, v in sm.items() if k not in ("start_s", "end_s")})
        rows[name] = row
    return pd.DataFrame.from_dict(rows, orient="index")


def _frame(time, lla):
    import pandas as pd
    return pd.DataFrame({"time_s": time, "lat_deg": np.degrees(lla[:, 0]), "lon_deg": np.degrees(lla[:, 1]),
                         "height_m": lla[:, 2]})


def run_scenario(name_or_path: str, seed: int | None = None) -> RunResult:
    """Simulate one seeded run of a scenario and filter it with every method.

    Parameters
    ----------
    name_or_path : str
        A shipped scenario (``mixnav.config.list_scenarios()``) or a .toml file.
    seed : int, optional
        Seed of the run (default: the scenario's own).
    """
    from .config import load_scenario
    from .experiment.run import method_metrics, run_scenario as _run, run_tables
    if seed is not None and (not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ArgumentError(f"must be a non-negative integer, got {seed!r}", argument="seed")
    sc, source, text = load_scenario(str(name_or_path))
    run = _run(sc, source, seed=seed)
    sim = run.sim
    tables = run_tables(run)
    metrics = {name: method_metrics(res, tables[name], sim.outages, sim.gnss_bias, sc.scored_segments)
               for name, res in run.results.items()}
    return RunResult(tables, _metrics_frame(metrics), run.results, _frame(sim.truth.time, sim.truth.lla), run, text)


def process_dataset(name_or_path: str, data: str | None = None) -> RunResult:
    """Run the methods of a dataset config on real recorded data and score them.

    Parameters
    ----------
    name_or_path : str
        A shipped dataset config (``mixnav.config.list_datasets()``) or a .toml file.
    data : str, optional
        Folder holding the data files (default: the config's ``data_dir``).

    A raw-GNSS dataset (``kind = "gnss-raw"``) gives the epoch-by-epoch single-point
    solution (``"spp"`` when the config names no methods) and its constant-velocity
    filters (:mod:`mixnav.experiment.spp_process`); an odometry +
    pseudorange dataset (``kind = "odometry-gnss"``, e.g. ``"smartloc-berlin"``) runs its
    methods on the dead-reckoning model (:mod:`mixnav.experiment.vehicle_process`).
    """
    from .config import load_dataset
    from .experiment.pipelines import pipeline, process
    ds, source, text = load_dataset(str(name_or_path))
    p = pipeline(ds, source)
    out = process(ds, source, data)
    tables = p.tables(out)
    return RunResult(tables, _metrics_frame(p.metrics(out, tables)), out.results, p.truth(out), out, text)


@dataclass
class ExperimentResult:
    """A Monte Carlo experiment's tables (:func:`run_experiment`), as written into its folder.

    Attributes
    ----------
    results : pandas.DataFrame
        One row per seed and method (``results.parquet``; columns in docs/outputs.md).
    summary : pandas.DataFrame
        Per method and metric the mean over runs and its 95 % interval (``summary.csv``).
    series : pandas.DataFrame
        Per epoch the RMS errors, sigmas, NEES and NIS over runs (``series_summary.parquet``;
        empty when the runs kept no series).
    consistency : pandas.DataFrame
        The Monte Carlo consistency checks (``consistency.csv``; empty without them).
    out : pathlib.Path
        The folder (``report.html`` there).
    """

    results: "object"
    summary: "object"
    series: "object"
    consistency: "object"
    out: Path


def run_experiment(scenario: str, runs: int, out, *, workers: int | None = None, resume: bool = False,
                   seeds_from: int = 0, scheduler: str | None = None, overwrite: bool = False,
                   progress: bool = False, figures: bool = True) -> ExperimentResult:
    """What ``mixnav experiment`` does: every method of ``scenario`` over seeds ``seeds_from ..
    seeds_from + runs - 1`` on local cores (or a Dask ``scheduler``), the records kept in ``out``
    (resumable), then the summaries and ``report.html`` (``figures=False``: the tables alone).
    Arguments as :func:`mixnav.experiment.montecarlo.run_experiment`.

        r = mixnav.run_experiment("loose-demo", 20, "runs/mc")
        r.summary.query("metric == 'horizontal_rmse_m'")
    """
    from .experiment.montecarlo import run_experiment as _run, write_experiment_outputs
    out = Path(out)
    results = _run(scenario, runs, out, workers=workers, resume=resume, seeds_from=seeds_from, progress=progress,
                   scheduler=scheduler, overwrite=overwrite)
    tables = write_experiment_outputs(scenario, results, out, figures=figures)
    return ExperimentResult(results, tables["summary"], tables["series"], tables["consistency"], out)


def tune(name_or_path: str, out, *, budget: int | None = None, workers: int | None = None, scheduler: str | None = None,
         data: str | None = None, fix=(), span=None, window="30 s", folds: int = 6, method: str | None = None,
         criterion: str | None = None, resume: bool = False, overwrite: bool = False, progress: bool = False,
         seed: int = 0):
    """Tune a dataset file from its own data, never reading its reference, and write ``out``
    (``tuned.toml``, ``tune.json``, ``report.md``): a
    :class:`~mixnav.experiment.tuning.TuneResult` (:func:`mixnav.experiment.tuning.tune`,
    arguments there; docs/tuning.md).

        r = mixnav.tune("my-car.toml", "runs/tune", budget=60)
        r.tuned["nlpd"], r.chosen["imu.errors.arw"]["value"]
    """
    from .experiment.tuning import tune as _tune
    return _tune(name_or_path, out, budget=budget, workers=workers, scheduler=scheduler, data=data, fix=fix,
                 span=span, window=window, folds=folds, method=method, criterion=criterion, resume=resume,
                 overwrite=overwrite, progress=progress, seed=seed)


def outage_sweep(name_or_path: str, window=None, step=None, span=None, *, data: str | None = None,
                 workers: int | None = None, scheduler: str | None = None, progress: bool = False):
    """Withhold the GNSS in one window at a time across a recording and score every method in
    each: a DataFrame, one row per method and window
    (:func:`mixnav.experiment.sweep.outage_sweep`, arguments and columns there).

        rows = mixnav.outage_sweep("drive-0708-aided", "30 s", "10 s")
        mixnav.experiment.sweep.summarize(rows)["aided"]["p90_horizontal_max_m"]
    """
    from .experiment.sweep import outage_sweep as _sweep
    return _sweep(name_or_path, window, step, span, data=data, workers=workers, scheduler=scheduler,
                  progress=progress)


def start_sweep(name_or_path: str, step=None, span=None, *, data: str | None = None,
                workers: int | None = None, scheduler: str | None = None, progress: bool = False):
    """Run a dataset's whole causal pipeline from several start times (every ``step``) and score
    each run from its own start and on the span all runs cover: a DataFrame, one row per
    method and start (:func:`mixnav.experiment.sweep.start_sweep`, arguments and columns there).

        rows = mixnav.start_sweep("smartloc-berlin", "30 s", ("0 s", "150 s"))
    """
    from .experiment.sweep import start_sweep as _sweep
    return _sweep(name_or_path, step, span, data=data, workers=workers, scheduler=scheduler, progress=progress)


def export_rinex(name_or_path: str, out_dir, seed: int | None = None, start: str = "2024-03-13T10:00:00",
                 overwrite: bool = False) -> dict:
    """Simulate one run of a scenario with raw satellites and write it as a dataset a user could
    have recorded: IMU CSV, RINEX 3 observation and navigation files, reference trajectory and
    ``dataset.toml`` (``mixnav export``; :mod:`mixnav.experiment.export`).

    Parameters
    ----------
    name_or_path : str
        A shipped scenario (with ``[gnss.satellites]``, e.g. ``"tight-demo"``) or a .toml file.
    out_dir : path
        The folder to write (the output-folder policy: docs/validation.md).
    seed : int, optional
        Seed of the run (default: the scenario's own).
    start : str
        GPS calendar time of the simulation's start, ``YYYY-MM-DDThh:mm:ss``.

    Returns
    -------
    dict
        Role (``imu``, ``observations``, ``navigation``, ``reference``, ``dataset``) -> path;
        process the dataset with :func:`process_dataset` on ``["dataset"]``.
    """
    from .config import load_scenario
    from .experiment.export import export_dataset
    if seed is not None and (not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ArgumentError(f"must be a non-negative integer, got {seed!r}", argument="seed")
    sc, source, _ = load_scenario(str(name_or_path))
    return dict(export_dataset(sc, out_dir, seed=seed, start=start, source=source, overwrite=overwrite).files)


def imu_grade(grade: str, **overrides: str):
    """An IMU error model from a named grade (``"navigation"``, ``"tactical"``, ``"mems"``),
    with datasheet overrides as text with units (``gyro_bias="2 deg/h"``)."""
    from .ins.imu_model import GRADES, ImuErrorModel
    if grade not in GRADES:
        raise ArgumentError(f"unknown IMU grade '{grade}' (known: {', '.join(GRADES)})", argument="grade")
    return ImuErrorModel.from_datasheet(dict(overrides), grade=grade)


@dataclass
class LooseResult:
    """:func:`filter_loose`'s result: the solution ``table`` (docs/outputs.md columns; error
    columns when a ``truth`` was given) and the raw ``result`` (FilterResult)."""

    table: "object"
    result: "object"


def filter_loose(imu: ImuData, fixes: GnssFixes, init: InitialState, *, imu_model, lever_arm=(0.0, 0.0, 0.0),
                 estimator: str = "ekf", states: int = 15, output_times=None, truth=None,
                 **options) -> LooseResult:
    """Run a loosely coupled GNSS/INS filter on your own data.

    Parameters
    ----------
    imu : ImuData
        Angle and velocity increments [rad, m/s] in the body frame, times [s] strictly increasing.
    fixes : GnssFixes
        Antenna positions (lat, lon [rad], h [m]) with 1-sigma N/E/D [m], optional NED velocity [m/s].
    init : InitialState
        Initial navigation state (``nav = [q_nb, v_n, lat, lon, h]``, radians) and sigmas, at a time
        inside the IMU data.
    imu_model : ImuErrorModel
        The filter's IMU model (:func:`imu_grade`).
    lever_arm : array_like (3,)
        Antenna position relative to the IMU in the body frame [m].
    estimator : str
        A registered estimator (:func:`mixnav.filters.registry.estimator_names`: ``"ekf"``, ``"robust-adaptive"``,
        ``"sage-husa"``...); ``options`` are its keyword arguments.
    states : int
        Error-state layout: 15, or 21 with scale factors.
    output_times : array_like, optional
        Where to record the solution [s] (default: every fix and every second).
    truth : Trajectory, optional
        When given, the table has error columns against it.
    """
    from .experiment.outputs import solution_table
    from .filters.facade import Filter
    from .ins.error_model import get_layout
    from .ins.imu_model import ImuErrorModel
    from .measurements.loose import LooseGnss
    if not isinstance(imu, ImuData):
        raise ArgumentError(f"expected mixnav.data.ImuData, got {type(imu).__name__}", argument="imu")
    if not isinstance(fixes, GnssFixes):
        raise ArgumentError(f"expected mixnav.data.GnssFixes, got {type(fixes).__name__}", argument="fixes")
    if not isinstance(init, InitialState):
        raise ArgumentError(f"expected mixnav.data.InitialState, got {type(init).__name__}", argument="init")
    if not isinstance(imu_model, ImuErrorModel):
        raise ArgumentError("expected an ImuErrorModel (e.g. mixnav.imu_grade('mems'))", argument="imu_model")
    lever = np.asarray(lever_arm, dtype=float)
    if lever.shape != (3,) or not np.all(np.isfinite(lever)):
        raise ArgumentError(f"must be 3 finite numbers [m] (body frame), got shape {lever.shape}",
                            argument="lever_arm")
    if states not in (15, 21):
        raise ArgumentError(f"a loose filter carries 15 or 21 states, got {states}", argument="states")
    t0, t1 = imu.start_time, float(imu.time[-1])
    if not t0 - 1e-9 <= init.time < t1:
        raise ArgumentError(f"initial time {init.time} s is outside the IMU data [{t0}, {t1}] s", argument="init")
    inside = (fixes.time > init.time) & (fixes.time <= t1)
    if not inside.any():
        raise ArgumentError(f"no fix falls inside the IMU data after the initial time ({init.time}, {t1}] s",
                            argument="fixes")
    layout = get_layout(states)
    interval = options.pop("covariance_interval", 1.0)
    filt = Filter(estimator, layout, imu_model, options, interval)
    res = filt.run(imu, init, [LooseGnss(fixes, lever, layout)],
                   output_times=None if output_times is None else np.asarray(output_times, dtype=float))
    return LooseResult(solution_table(res, truth), res)
