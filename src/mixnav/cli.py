"""The ``mixnav`` command."""

from __future__ import annotations

import signal
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from ._version import __version__
from .errors import ArgumentError, MixnavError

try:   # typer >= 0.2x carries its own click; its usage errors derive from TyperException
    from typer.exceptions import TyperException as _UsageError
except ImportError:   # older typer depends on click and raises click's
    from click.exceptions import ClickException as _UsageError

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_show_locals=False,
                  help="GNSS/INS integrated navigation under non-Gaussian noise.")
err = Console(stderr=True, soft_wrap=True)   # soft wrap: an error stays one line
out = Console()


#: --debug: show the traceback of an error instead of the one-line message
_DEBUG = {"on": False}


def _say(msg: str) -> None:
    err.print("[bold red]error:[/] " + escape(msg), highlight=False, markup=True)


def _fail(exc: Exception) -> None:
    _say(str(exc))
    raise typer.Exit(code=2)


def _terminate(signum, frame):
    # SIGTERM ends the command like Ctrl-C: every clean-up (temporary folders,
    # worker processes, a Dask client) runs on the way out
    _DEBUG["signal"] = signum
    raise KeyboardInterrupt


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning (a GNSS hole, a spike replaced, ...) as one line on stderr."""
    err.print("[bold yellow]warning:[/] " + escape(str(message)), highlight=False)


@contextmanager
def _errors():
    """Every error a user can cause ends in one line and exit status 2 (docs/validation.md);
    an interruption in exit status 130 (Ctrl-C) or 143 (SIGTERM) after the clean-up; an
    unexpected error (a bug) in one line and exit status 3, its traceback with --debug."""
    old = None
    caught = warnings.catch_warnings()
    caught.__enter__()
    warnings.simplefilter("default")
    warnings.showwarning = _show_warning
    try:
        old = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:   # not in the main thread (tests calling the app from a thread)
        pass
    try:
        yield
    except (typer.Exit, typer.Abort, _UsageError):
        raise
    except KeyboardInterrupt:
        sig = _DEBUG.pop("signal", None)
        _say("interrupted" + (" (SIGTERM)" if sig else "") + ": nothing half written was kept")
        raise typer.Exit(code=143 if sig else 130)
    except MixnavError as exc:
        if _DEBUG["on"]:
            raise
        _fail(exc)
    except OSError as exc:
        if _DEBUG["on"]:
            raise
        where = exc.filename if exc.filename is not None else ""
        _say(f"{where}{': ' if where else ''}{exc.strerror or exc}")
        raise typer.Exit(code=2)
    except MemoryError:
        _say("out of memory (a smaller --runs, a shorter scenario or fewer methods may fit)")
        raise typer.Exit(code=2)
    except Exception as exc:  # noqa: BLE001  a bug: one line, the traceback with --debug
        if _DEBUG["on"]:
            raise
        _say(f"internal error ({type(exc).__name__}: {exc}); please report it, with the "
             "traceback that --debug shows")
        raise typer.Exit(code=3)
    finally:
        caught.__exit__(None, None, None)
        if old is not None:
            signal.signal(signal.SIGTERM, old)


def _warn(metrics: dict) -> None:
    """The warnings of a finished run (NIS far above 1, GNSS holes) on stderr, after the table."""
    for w in metrics.get("warnings", []):
        err.print("[bold yellow]warning:[/] " + escape(w), highlight=False)


def _num(m: dict, key: str) -> str:
    """A metric with 3 significant digits, or "-" where the method has none (a smoothed
    method has no forward-pass time per epoch: only its ``smoother_time_s``)."""
    return "-" if m.get(key) is None else f"{m[key]:.3g}"


def _smoother_column(methods: dict) -> list[str]:
    """The ``smoother [s]`` header when some method is smoothed, else nothing."""
    return ["smoother [s]"] if any("smoother_time_s" in m for m in methods.values()) else []


def _version(value: bool):
    if value:
        out.print(f"mixnav {__version__}")
        raise typer.Exit()


@app.callback()
def main(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                      help="Print the version and exit."),
         debug: bool = typer.Option(False, "--debug", help="Show the traceback of an error.")):
    """GNSS/INS integrated navigation under non-Gaussian noise."""
    _DEBUG["on"] = debug


_OVERWRITE = typer.Option(False, "--overwrite",
                          help="Clear --out first when it holds anything but this command's own output.")


@app.command()
def scenarios():
    """List the scenarios shipped with mixnav."""
    from .config import list_datasets, list_scenarios
    from .experiment.methods import ESTIMATORS, METHODS

    t = Table("scenario", "description", title="shipped scenarios (mixnav run)")
    for name, desc in list_scenarios().items():
        t.add_row(name, desc)
    out.print(t)
    d = Table("dataset", "description", title="shipped real-data configs (mixnav process)")
    for name, desc in list_datasets().items():
        d.add_row(name, desc)
    out.print(d)
    m = Table("method type", "what it is", title="methods usable in scenario files")
    for name, desc in METHODS.items():
        m.add_row(name, desc)
    out.print(m)
    e = Table("estimator", "what it is", title="estimators (estimator = ..., on every method type)")
    for name, desc in ESTIMATORS.items():
        e.add_row(name, desc)
    out.print(e)


@app.command()
def run(scenario: str = typer.Argument(..., help="Shipped scenario name or path of a .toml file."),
        out_dir: Path = typer.Option(..., "--out", help="Folder for the solution, metrics, figures and report."),
        seed: int = typer.Option(None, min=0, max=2**63 - 1,
                                 help="Seed of this run (default: the scenario's seed)."),
        overwrite: bool = _OVERWRITE):
    """Simulate one run of a scenario, filter it with every method, write the report."""
    from .config import load_scenario
    from .experiment.run import run_scenario, write_run
    from .io.outdir import check_out_dir

    with _errors():
        sc, source, text = load_scenario(scenario)
        check_out_dir(out_dir, "run", overwrite, [source])   # refused before the work, not after
        with err.status(f"running {sc.scenario.name}"):
            result = run_scenario(sc, source, seed=seed)
            metrics = write_run(out_dir, result, config_text=text, overwrite=overwrite)
    smooth = _smoother_column(metrics["methods"])
    segs = list(metrics.get("segments_s", {}))      # the scenario's [scoring] segments: their maxima
    t = Table("method", "horiz. RMSE [m]", "horiz. max [m]", *(f"{g}: horiz. max [m]" for g in segs),
              "yaw RMSE [deg]", "vel. RMSE [m/s]",
              "time/epoch [us]", *smooth, title=f"{sc.scenario.name} (seed {metrics['seed']})")
    for name, m in metrics["methods"].items():
        t.add_row(name, f"{m['horizontal_rmse_m']:.3g}", f"{m['horizontal_max_m']:.3g}",
                  *(_num(m.get("segments", {}).get(g, {}), "horizontal_max_m") for g in segs),
                  f"{m['yaw_rmse_deg']:.3g}", f"{m['velocity_rmse_mps']:.3g}",
                  _num(m, "epoch_time_mean_us"), *(_num(m, "smoother_time_s") for _ in smooth))
    out.print(t)
    _warn(metrics)
    out.print(f"report: {Path(out_dir) / 'report.html'}")


@app.command()
def process(dataset: str = typer.Argument(..., help="Shipped dataset config name or path of a .toml file."),
            out_dir: Path = typer.Option(..., "--out", help="Folder for the solution, metrics, figures and report."),
            data: Path = typer.Option(None, "--data", help="Folder holding the data files "
                                      "(default: the config's data_dir)."),
            outage_sweep: str = typer.Option(None, "--outage-sweep",
                                             help="Also withhold the GNSS one window of this length at a time "
                                                  "across the recording ('30 s'; default: [evaluation] "
                                                  "outage_sweep) and score every method in each."),
            sweep_step: str = typer.Option(None, "--sweep-step", help="Between the sweep's window starts "
                                           "('10 s'; default: [evaluation] sweep_step, else a third of the window)."),
            sweep_span: tuple[str, str] = typer.Option(None, "--sweep-span", show_default=False,
                                                       help="START END of the sweep's windows ('60 s' '500 s'; "
                                                            "default: from the alignment to the last GNSS epoch)."),
            start_sweep: str = typer.Option(None, "--start-sweep",
                                            help="Also run the whole causal pipeline from start times this far "
                                                 "apart ('30 s'; default: [evaluation] start_sweep; datasets that "
                                                 "align from their own data); --sweep-span gives the first and "
                                                 "last start."),
            sweeps: bool = typer.Option(True, "--sweeps/--no-sweeps",
                                        help="Run the sweeps the dataset's [evaluation] asks for."),
            workers: int = typer.Option(None, "--workers", min=1,
                                        help="Local worker processes of a sweep (default: all cores)."),
            scheduler: str = typer.Option(None, "--scheduler", help="Dask scheduler address (tcp://host:8786) "
                                          "to run a sweep's windows on; needs mixnav[dask]."),
            progress: bool = typer.Option(True, "--progress/--no-progress"),
            overwrite: bool = _OVERWRITE):
    """Run the methods of a dataset config on real recorded data and score them."""
    from .config import load_dataset
    from .experiment.pipelines import pipeline, process as run_pipeline
    from .io.outdir import check_out_dir

    with _errors():
        ds, source, text = load_dataset(dataset)
        check_out_dir(out_dir, "process", overwrite, [source, data])
        ev = getattr(ds, "evaluation", None)
        span = None if not sweep_span or sweep_span[0] is None else sweep_span
        want_starts = start_sweep is not None or (sweeps and ev is not None and ev.start_sweep is not None)
        want = outage_sweep is not None or sweep_step is not None or (span is not None and not want_starts) or \
            (sweeps and ev is not None and ev.outage_sweep is not None)
        with err.status(f"processing {ds.dataset.name}"):
            processed = run_pipeline(ds, source, None if data is None else str(data))
        done = []
        folder = None if data is None else str(data)
        if want:
            from .experiment.sweep import run_outage_sweep
            with _as_options(window="--outage-sweep", step="--sweep-step", span="--sweep-span"):
                done.append(run_outage_sweep(dataset, outage_sweep, sweep_step, span, data=folder, workers=workers,
                                             scheduler=scheduler, progress=progress))
        if want_starts:
            from .experiment.sweep import run_start_sweep
            with _as_options(step="--start-sweep", span="--sweep-span"):
                done.append(run_start_sweep(dataset, start_sweep, span, data=folder, workers=workers,
                                            scheduler=scheduler, progress=progress))
        with err.status(f"writing {out_dir}"):
            metrics = pipeline(ds, source).write(out_dir, processed, config_text=text, overwrite=overwrite,
                                                 sweeps=done)
    smooth = _smoother_column(metrics["methods"])
    t = Table("method", "horiz. RMSE [m]", "horiz. max [m]", "outage max [m]", "time/epoch [us]", *smooth,
              title=f"{ds.dataset.name}: {metrics['duration_s']:.0f} s in "
                    f"{metrics['read_time_s'] + metrics['filter_time_s']:.2f} s "
                    f"(x{metrics['real_time_factor']:.0f} real time)")
    for name, m in metrics["methods"].items():
        outs = ", ".join(f"{o['horizontal_max_m']:.3g}" for o in m.get("outages", [])) or "-"
        t.add_row(name, _num(m, "horizontal_rmse_m"), _num(m, "horizontal_max_m"), outs,
                  _num(m, "epoch_time_mean_us"),
                  *(_num(m, "smoother_time_s") for _ in smooth))
    out.print(t)
    for sw in done:
        _print_sweep(sw)
    _warn(metrics)
    out.print(f"report: {Path(out_dir) / 'report.html'}")


def _scored_segments(scenario: str) -> list:
    """The ``[scoring]`` segments of an experiment's scenario (as loaded by the experiment)."""
    from .experiment.montecarlo import _load
    return _load(scenario)[0][0][1].scored_segments


@contextmanager
def _as_options(**flags: str):
    """An ArgumentError about a library argument said as the command-line option the user wrote."""
    try:
        yield
    except ArgumentError as exc:
        raise ArgumentError(exc.message, argument=flags.get(exc.argument, exc.argument)) from None


def _print_sweep(sw) -> None:
    st = sw.settings
    if sw.kind == "start_sweep":
        t = Table("method", "median RMSE [m]", "worst [m]", "median, common span [m]", "worst, common span [m]",
                  title=f"start sweep: starts {', '.join(f'{x:g}' for x in st['starts_s'])} s; common span "
                        f"{st['common_span_s'][0]:.0f}-{st['common_span_s'][1]:.0f} s ({st['wall_time_s']:.0f} s)")
        for name, b in sw.summary.items():
            t.add_row(name, f"{b['median_horizontal_rmse_m']:.3g}", f"{b['worst_horizontal_rmse_m']:.3g}",
                      f"{b['median_common_horizontal_rmse_m']:.3g}", f"{b['worst_common_horizontal_rmse_m']:.3g}")
        out.print(t)
        return
    t = Table("method", "median max [m]", "p90 [m]", "worst [m]", "NEES out of band",
              title=f"outage sweep: {st['n_windows']} windows of {st['window_s']:g} s every {st['step_s']:g} s "
                    f"({st['wall_time_s']:.0f} s)")
    for name, b in sw.summary.items():
        share = b.get("share_nees_above_99")
        t.add_row(name, f"{b['median_horizontal_max_m']:.3g}", f"{b['p90_horizontal_max_m']:.3g}",
                  f"{b['worst_horizontal_max_m']:.3g}", "-" if share is None else f"{100 * share:.0f} %")
    out.print(t)


@app.command()
def experiment(scenario: str = typer.Argument(..., help="Shipped scenario name or path of a .toml file."),
               runs: int = typer.Option(..., "--runs", help="Number of seeded Monte Carlo runs."),
               out_dir: Path = typer.Option(..., "--out", help="Folder for the records, results and summary."),
               workers: int = typer.Option(None, "--workers", help="Local worker processes (default: all cores)."),
               resume: bool = typer.Option(False, "--resume", help="Run only the seeds with no record yet."),
               seeds_from: int = typer.Option(0, "--seeds-from", help="First seed."),
               scheduler: str = typer.Option(None, "--scheduler",
                                             help="Dask scheduler address (tcp://host:8786): run there "
                                                  "instead of on local cores; needs mixnav[dask]."),
               progress: bool = typer.Option(True, "--progress/--no-progress"),
               figures: bool = typer.Option(True, "--figures/--no-figures",
                                            help="Draw the report's PNG figures (about 1 s each; without "
                                                 "them report.html holds the tables alone)."),
               overwrite: bool = _OVERWRITE):
    """Run every method of a scenario over N seeded runs on all local cores (or a Dask cluster); keep partial results."""
    from .experiment.montecarlo import run_experiment, write_experiment_outputs

    with _errors(), _as_options(runs="--runs", workers="--workers", seeds_from="--seeds-from",
                                scheduler="--scheduler", out_dir="--out"):
        if resume and overwrite:   # said in the options' own words (the library names its arguments)
            raise ArgumentError("--resume continues the experiment in --out and --overwrite clears it: give one")
        df = run_experiment(scenario, runs, out_dir, workers=workers, resume=resume, seeds_from=seeds_from,
                            progress=progress, scheduler=scheduler, overwrite=overwrite)
        paths = write_experiment_outputs(scenario, df, out_dir, figures=figures)
    summary = paths["summary"]
    sweep = "sweep_value" in summary.columns
    t = Table(*(["sweep"] if sweep else []), "method", "metric", "mean", "95 % CI", "n",
              title=f"{scenario}: {df['seed'].nunique()} runs")
    # and per scored segment of the scenario's [scoring] its maximum horizontal error (the rest is in the report)
    segs = [f"segment_{g}_horizontal_max_m" for g, _, _ in _scored_segments(scenario)]
    shown = summary["metric"].isin(["horizontal_rmse_m", "yaw_rmse_deg", "velocity_rmse_mps",
                                    "epoch_time_mean_us", *segs])
    for _, r in summary[shown & (summary["n"] > 0)].iterrows():  # n = 0: a smoothed method's epoch time
        t.add_row(*([f"{r['sweep_value']:g}"] if sweep else []), r["method"], r["metric"],
                  f"{r['mean']:.4g}", f"+-{r['ci95_half']:.2g}", str(int(r["n"])))
    out.print(t)
    out.print(f"results: {Path(out_dir) / 'results.parquet'}, report: {Path(out_dir) / 'report.html'}")


@app.command()
def tune(dataset: str = typer.Argument(..., help="Shipped dataset config name or path of a .toml file "
                                               "(IMU + GNSS fixes, odometry + pseudoranges, or raw GNSS)."),
         out_dir: Path = typer.Option(..., "--out", help="Folder for tuned.toml, tune.json, report.md, tune.png."),
         budget: int = typer.Option(None, "--budget", help="Candidate settings scored at most (each is --folds "
                                                          "filter runs; at least 1; default 160 for IMU + GNSS "
                                                          "fixes, 96 for odometry + pseudoranges and raw GNSS)."),
         workers: int = typer.Option(None, "--workers", min=1, help="Local worker processes (default: all cores)."),
         scheduler: str = typer.Option(None, "--scheduler", help="Dask scheduler address (tcp://host:8786) to run "
                                                               "the candidates on; needs mixnav[dask]."),
         fix: list[str] = typer.Option(None, "--fix", help="A key kept as the file gives it (repeatable; "
                                                           "docs/tuning.md lists the keys)."),
         span: tuple[str, str] = typer.Option(None, "--span", show_default=False,
                                              help="START END of the part tuned on ('60 s' '300 s'; seconds since "
                                                   "the first IMU sample; default: the whole recording)."),
         window: str = typer.Option("30 s", "--window", help="Length of the cross-validation outages."),
         folds: int = typer.Option(6, "--folds", help="Runs the cross-validation windows (one every half window) "
                                                   "are dealt to (>= 4)."),
         method: str = typer.Option(None, "--method", help="The method tuned (default: the most aided; odometry + "
                                                           "pseudoranges and raw GNSS: the first epoch mixture)."),
         criterion: str = typer.Option(None, "--criterion", help="Odometry + pseudoranges only: 'likelihood' "
                                                                 "(default) or 'withheld-satellites' (docs/tuning.md)."),
         data: Path = typer.Option(None, "--data", help="Folder holding the data files (default: the config's "
                                                        "data_dir)."),
         resume: bool = typer.Option(False, "--resume", help="Reuse the evaluations of an earlier run into --out."),
         progress: bool = typer.Option(True, "--progress/--no-progress"),
         overwrite: bool = _OVERWRITE):
    """Tune a recording's filter from its own data (never its reference): writes tuned.toml and a report."""
    from .experiment.tuning import tune as _tune

    with _errors():
        r = _tune(dataset, out_dir, budget=budget, workers=workers, scheduler=scheduler,
                  data=None if data is None else str(data), fix=fix or (),
                  span=None if not span or span[0] is None else span, window=window, folds=folds, method=method,
                  criterion=criterion, resume=resume, overwrite=overwrite, progress=progress)
    if "nlpd" in r.given:
        t = Table("", "CV mean NLPD", "innovation log-lik./update", "CV median / p90 horizontal max [m]",
                  title=f"{dataset}: {r.runs} filter runs")
        for name, s in (("as given", r.given), ("tuned", r.tuned)):
            t.add_row(name, f"{s['nlpd']:.3f}", f"{s['innovation_ll_per_update']:.3f}",
                      f"{s['cv_median_hmax_m']:.2f} / {s['cv_p90_hmax_m']:.2f}")
    else:
        t = Table("", "criterion (lower is better)", "innovation log-lik./update",
                  title=f"{dataset}: {r.runs} pipeline runs")
        for name, s in (("as given", r.given), ("tuned", r.tuned)):
            t.add_row(name, f"{s['criterion']:.4f}", f"{s['innovation_ll_per_update']:.3f}")
    out.print(t)
    if r.kept_as_given:
        out.print(f"the file as given is kept: {r.kept_as_given}")
    for k, c in r.chosen.items():
        out.print(f"  {k} = {c.get('value', c.get('from_data'))}")
    for k, why in r.not_tuned.items():
        out.print(f"  [dim]{k}: not tuned ({why})[/dim]")
    out.print(f"tuned file: {Path(out_dir) / 'tuned.toml'}, report: {Path(out_dir) / 'report.md'}")


@app.command()
def export(scenario: str = typer.Argument(..., help="Shipped scenario name or path of a .toml file "
                                          "(with [gnss.satellites])."),
           out_dir: Path = typer.Option(..., "--out", help="Folder for the IMU CSV, RINEX files, reference and "
                                        "dataset.toml."),
           seed: int = typer.Option(None, min=0, max=2**63 - 1, help="Seed of this run (default: the scenario's)."),
           start: str = typer.Option("2024-03-13T10:00:00", "--start",
                                     help="GPS time of the simulation's start (YYYY-MM-DDThh:mm:ss)."),
           overwrite: bool = _OVERWRITE):
    """Simulate one run and write it as a recorded dataset: IMU CSV + RINEX 3 obs/nav + reference + dataset.toml."""
    from .config import load_scenario
    from .experiment.export import export_dataset
    from .io.outdir import check_out_dir

    with _errors():
        sc, source, _ = load_scenario(scenario)
        check_out_dir(out_dir, "export", overwrite, [source])
        with err.status(f"exporting {sc.scenario.name}"):
            res = export_dataset(sc, out_dir, seed=seed, start=start, source=source, overwrite=overwrite)
    for role, path in res.files.items():
        out.print(f"{role}: {path}")
    for name, why in res.skipped_methods.items():
        out.print(f"method '{name}' not copied: {why}")
    out.print(f"process it with: mixnav process {res.files['dataset']} --out <folder>")


@app.command()
def diagnose(file: Path = typer.Argument(..., help="CSV or Parquet file holding a residual series."),
             column: str = typer.Option(..., "--column", help="Name of the column to diagnose."),
             out_dir: Path = typer.Option(..., "--out", help="Folder for diagnostics.json and the figures."),
             max_lag: int = typer.Option(None, "--max-lag", min=1,
                                         help="Largest lag of the autocorrelation (default 50, "
                                              "fewer for a shorter series; below the series length)."),
             components: int = typer.Option(None, "--components", min=1,
                                            help="Fit a Gaussian mixture with this many components."),
             overwrite: bool = _OVERWRITE):
    """Is a residual series non-Gaussian and coloured? Q-Q, ACF, normality test, kurtosis, AR(1), mixture."""
    from .experiment.diagnose import diagnose_file

    with _errors():
        result = diagnose_file(file, column, out_dir, max_lag=max_lag, n_components=components,
                               overwrite=overwrite)
    out.print(result["verdict"]["summary"])
    out.print(f"numbers: {Path(out_dir) / 'diagnostics.json'}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
