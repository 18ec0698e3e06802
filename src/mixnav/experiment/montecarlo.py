"""Monte Carlo experiments: many seeded runs of one scenario, in parallel, resumable.

Output folder of :func:`run_experiment` (every file written atomically)::

    manifest.json          scenario, source, sha256 of the scenario text, mixnav
                           version, runs, seeds, methods
    runs/run_<seed>.parquet  one record per finished run: one row per method with
                           scenario, seed, method, the flat scalar metrics and
                           scenario_sha256 (checked by a resume: _check_records)
                           (``run_<seed>_v<i>.parquet`` and a ``sweep_value``
                           column when the scenario declares a sweep)
    runs/series_<seed>.parquet  the run's per-epoch errors, filter sigmas, NEES
                           and NIS (one row per method and output epoch),
                           written before the record
    results.parquet/.csv   all records concatenated (written last)

A scenario with a ``[sweep]`` table runs every seed once per sweep value
(:func:`mixnav.config.loader.sweep_variants`); the sweep value is a column
of the records and of the aggregates.

Runs execute in this process (``workers=1``), in a local process pool, or on a
Dask cluster (``scheduler="tcp://host:8786"``, needs ``pip install
"mixnav[dask]"``) whose workers share the file system with the caller: each
worker writes its records straight into ``out_dir``. The engine never changes
the numbers: a seed gives the same record wherever it runs.

A run's record file is its only trace, so an interrupted experiment resumes by
running the seeds that have none (``resume=True``). Records hold numbers only
(no solution tables) to stay small for thousands of runs.

Metrics are those of :func:`mixnav.experiment.run.method_metrics`, flattened:
per outage window ``outage<i>_<key>`` (``outage0_horizontal_max_m``...), per scored
segment of the scenario's ``[scoring]`` ``segment_<name>_<key>``
(``segment_multipath_horizontal_max_m``...; its span is in the scenario),
``recoveries_total`` plus ``recoveries_<kind>``. The timing metrics
(:data:`TIMING_METRICS`) are wall-clock measurements and differ between two
executions of the same seed; every other column is reproducible exactly.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from .._version import __version__
from ..errors import ArgumentError, ConfigError
from ..io.atomic import atomic_write_dataframe, atomic_write_json, remove_stale_temporaries
from .parallel import DASK_CONNECT_TIMEOUT_S, DASK_WORKER_WAIT_S  # noqa: F401  (re-exported)
from .parallel import Progress as _Progress
from .parallel import dask_client as _dask_client
from .parallel import die_with_parent as _die_with_parent
from .parallel import dask_map, pool_map
from .parallel import terminate_pool as _terminate_pool

__all__ = ["run_experiment", "aggregate", "paired_comparison", "flatten_metrics", "series_files",
           "write_experiment_outputs",
           "TIMING_METRICS", "ID_COLUMNS"]

#: Columns identifying a record row; every other column is a metric.
ID_COLUMNS = ("scenario", "seed", "method", "sweep_value")
#: Metrics measured with the wall clock: not reproducible from the seed.
TIMING_METRICS = ("epoch_time_mean_us", "update_time_mean_us", "wall_time_s", "learning_time_s", "total_time_s",
                  "online_refit_time_s", "smoother_time_s")

RUNS_DIR = "runs"
MANIFEST = "manifest.json"
#: most runs (seeds x sweep values) one call runs
MAX_RUNS = 100_000
#: what an experiment folder holds (patterns; the output-folder policy reuses only such a folder)
EXPERIMENT_FILES = (MANIFEST, RUNS_DIR, "results.parquet", "results.csv", "summary.csv",
                    "series_summary.parquet", "consistency.csv", "report.html", "*.png")
#: written after the runs: removed before a resume runs anything
_PRODUCTS = ("results.parquet", "results.csv", "summary.csv", "series_summary.parquet",
             "consistency.csv", "report.html")

# Per process: the loaded scenario and its deterministic truth + ideal IMU,
# keyed by (source, sha256 of the text) so an edited file is never mixed in.
_SCENARIOS: dict[str, tuple] = {}
_IDEAL_CACHE: dict[tuple[str, str], tuple] = {}


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _stem(seed: int, variant: int | None) -> str:
    return f"{seed}" if variant is None else f"{seed}_v{variant}"


def _record_path(out_dir: Path, seed: int, variant: int | None = None) -> Path:
    return out_dir / RUNS_DIR / f"run_{_stem(seed, variant)}.parquet"


def _series_path(out_dir: Path, seed: int, variant: int | None = None) -> Path:
    return out_dir / RUNS_DIR / f"series_{_stem(seed, variant)}.parquet"


# ---------------------------------------------------------------- one run

def _is_scalar(v) -> bool:
    return isinstance(v, (bool, int, float, str, np.integer, np.floating, np.bool_))


def _scalar(v):
    return v.item() if isinstance(v, np.generic) else v


def flatten_metrics(m: dict) -> dict:
    """The scalar view of one method's metrics (see the module docstring)."""
    out = {}
    for k, v in m.items():
        if k == "outages":
            for i, w in enumerate(v):
                for kk, vv in w.items():
                    if _is_scalar(vv):
                        out[f"outage{i}_{kk}"] = _scalar(vv)
        elif k == "segments":
            for name, seg in v.items():
                for kk, vv in seg.items():
                    if _is_scalar(vv) and kk not in ("start_s", "end_s"):
                        out[f"segment_{name}_{kk}"] = _scalar(vv)
        elif k == "recoveries":
            out["recoveries_total"] = int(sum(int(x) for x in v.values()))
            for kk, vv in v.items():
                out[f"recoveries_{kk}"] = int(vv)
        elif _is_scalar(v):
            out[k] = _scalar(v)
        elif isinstance(v, dict):
            for kk, vv in v.items():
                if _is_scalar(vv):
                    out[f"{k}_{kk}"] = _scalar(vv)
        # other non-scalars (lists, arrays) are left out
    return out


def _load(scenario: str, expect_sha: str | None = None):
    """(variants, source, sha, sweep) of ``scenario``, loaded once per process.

    ``variants`` is ``[(sweep_value, Scenario), ...]`` (one entry, the
    scenario itself with a NaN value, when it has no sweep); ``sweep`` is
    its :class:`~mixnav.config.scenario_schema.SweepConfig` or None. Without ``expect_sha`` the file is
    always read again (the caller wants its current text); with it, the
    cached copy serves while it matches.
    """
    from ..config.loader import load_scenario, sweep_variants
    hit = _SCENARIOS.get(scenario)
    if hit is None or expect_sha is None or hit[2] != expect_sha:
        sc, source, text = load_scenario(scenario)
        hit = _SCENARIOS[scenario] = (sweep_variants(sc, text, source), source, _sha256(text),
                                      sc.sweep)
    if expect_sha is not None and hit[2] != expect_sha:
        raise ConfigError("the scenario file changed while the experiment was running "
                          f"(sha256 {hit[2][:12]}..., expected {expect_sha[:12]}...)", file=hit[1])
    return hit


def _ideal(sc, source: str, sha: str):
    from ..sim.scenario import truth_and_ideal_imu
    # keyed by what the truth depends on, so sweep variants share it when they can
    key = (source, sha, sc.trajectory.model_dump_json(), sc.imu.rate,
           None if sc.vehicle is None else sc.vehicle.model_dump_json(),
           None if sc.installation is None else sc.installation.model_dump_json())
    if key not in _IDEAL_CACHE:
        _IDEAL_CACHE[key] = truth_and_ideal_imu(sc, source)
    return _IDEAL_CACHE[key]


#: Solution-table columns kept in the per-run series (when present).
SERIES_PREFIXES = ("err_", "sig_", "nees_")


def _series(name: str, res, table: pd.DataFrame) -> pd.DataFrame:
    """Per-epoch errors, sigmas, NEES and NIS of one method (see the module docstring)."""
    cols = ["time_s"] + [c for c in table.columns if c.startswith(SERIES_PREFIXES)]
    out = table[cols + ["gnss_used", "in_outage"]].copy()
    out.insert(0, "method", name)
    # NIS of the update at each output epoch where one was applied (every
    # measurement epoch is an output epoch; checked, else NIS is left out)
    nis = np.full(len(out), np.nan)
    dof = np.full(len(out), np.nan)
    used = out["gnss_used"].to_numpy(bool)
    if len(res.nis) == int(used.sum()):
        nis[used], dof[used] = res.nis, res.nis_dim
    out["nis"], out["nis_dim"] = nis, dof
    return out


def _compute_run(scenario: str, sha: str, seed: int, variant: int | None = None):
    """The record (one row per method) and the series of one seeded run."""
    from .run import method_metrics, run_scenario, solution_table
    variants, source, sha, _ = _load(scenario, sha)
    value, sc = variants[0 if variant is None else variant]
    out = run_scenario(sc, source, seed, ideal=_ideal(sc, source, sha))
    rows, series = [], []
    for name, res in out.results.items():
        table = solution_table(res, out.sim.truth, out.sim.outages)
        row = {"scenario": sc.scenario.name, "seed": int(seed), "method": name}
        if variant is not None:
            row["sweep_value"] = value
        rows.append({**row, **flatten_metrics(method_metrics(res, table, out.sim.outages, out.sim.gnss_bias,
                                                             sc.scored_segments)),
                     "scenario_sha256": sha})   # provenance: checked by a resume
        series.append(_series(name, res, table))
    return pd.DataFrame(rows), pd.concat(series, ignore_index=True)


def _run_and_write(scenario: str, sha: str, seed: int, out_dir: str,
                   variant: int | None = None) -> int:
    """Worker task: compute one run, write its series, then its record; returns the seed.

    The record is written last: its presence marks a finished run.
    """
    try:
        rec, series = _compute_run(scenario, sha, seed, variant)
    except BaseException as exc:
        where = "" if variant is None else f" (sweep variant {variant})"
        exc.add_note(f"while running seed {seed}{where} of scenario {scenario}")
        raise
    atomic_write_dataframe(_series_path(Path(out_dir), seed, variant), series)
    atomic_write_dataframe(_record_path(Path(out_dir), seed, variant), rec)
    return seed


def _worker_init(scenario: str, sha: str) -> None:
    _die_with_parent()
    _load(scenario, sha)


# ---------------------------------------------------------------- experiment

def _remove_products(out_dir: Path) -> None:
    for name in _PRODUCTS:
        (out_dir / name).unlink(missing_ok=True)
    for png in out_dir.glob("*.png"):
        png.unlink(missing_ok=True)


_RECORD_NAME = re.compile(r"^run_(\d+)(?:_v(\d+))?\.parquet$")
_SERIES_NAME = re.compile(r"^series_(\d+)(?:_v(\d+))?\.parquet$")


def _readable_parquet(path: Path):
    """The table in ``path``, or None when it is missing, truncated or not Parquet."""
    try:
        return pd.read_parquet(path)
    except Exception:   # pyarrow raises several types for a damaged file  # noqa: BLE001
        return None


def _record_problem(df, scenario_name, sha, seed, variant, value, methods) -> str | None:
    """Why a stored record does not belong to this experiment, or None."""
    if df is None:
        return "unreadable (truncated or not Parquet)"
    need = {"scenario", "seed", "method"}
    if not need <= set(df.columns):
        return f"has no {', '.join(sorted(need - set(df.columns)))} column"
    if "scenario_sha256" not in df.columns:
        return "has no scenario_sha256 (written before records carried it)"
    if set(df["scenario_sha256"].astype(str)) != {sha}:
        return f"was run with another scenario text (sha256 {str(df['scenario_sha256'].iloc[0])[:12]}...)"
    if set(df["scenario"].astype(str)) != {scenario_name}:
        return f"is of scenario {sorted(set(df['scenario'].astype(str)))}"
    if set(pd.to_numeric(df["seed"], errors="coerce")) != {seed}:
        return f"holds seeds {sorted(set(df['seed']))}, not {seed}"
    held = sorted(df["method"].astype(str))
    # the configured methods, each once, plus what they add ("<name>-smoothed")
    if not (set(methods) <= set(held) and len(set(held)) == len(held)
            and all(h in methods or any(h.startswith(m + "-") for m in methods) for h in held)):
        return f"holds methods {held}, not those of the scenario {sorted(methods)}"
    if variant is not None:
        v = pd.to_numeric(df.get("sweep_value"), errors="coerce")
        if v is None or not np.allclose(v.to_numpy(float), value):
            return f"is not of sweep value {value:g}"
    return None


def _check_records(out_dir: Path, scenario_name: str, sha: str, methods: list[str], variants,
                   sweep, seeds: set[int]) -> set[tuple]:
    """Check every stored record and series file against this experiment.

    A record that is unreadable, from another scenario text, of another seed,
    method set or sweep value, or whose series file is missing or unreadable,
    is removed with its series and its run redone (returned as a task); each
    is reported on stderr. A file of ``runs/`` that is not a record or series
    of a seed of this experiment is refused (ConfigError naming it).
    """
    runs_dir = out_dir / RUNS_DIR
    if not runs_dir.is_dir():
        return set()
    redo = set()
    for f in sorted(runs_dir.iterdir()):
        if f.name.startswith(".") and f.name.endswith(".tmp") or not os.path.lexists(f):
            continue   # a killed writer's temporary file, or a series removed with its record
        m = _RECORD_NAME.match(f.name) or _SERIES_NAME.match(f.name)
        if m is None or not f.is_file():
            raise ConfigError(f"{f} is not a run record or series of mixnav; remove it (or use "
                              "another folder)", file=str(f))
        seed, variant = int(m.group(1)), None if m.group(2) is None else int(m.group(2))
        if seed not in seeds or (variant is None) != (sweep is None) or \
                (variant is not None and variant >= len(variants)):
            raise ConfigError(f"{f.name} is not part of this experiment (seeds {min(seeds)}..{max(seeds)}"
                              f"{', no sweep' if sweep is None else f', {len(variants)} sweep values'}); "
                              "remove it, or use another folder", file=str(f))
        if not f.name.startswith("run_"):
            if not _record_path(out_dir, seed, variant).exists():
                f.unlink()   # a series without its record: an interrupted run, redone if asked for
            continue
        value = None if variant is None else variants[variant][0]
        problem = _record_problem(_readable_parquet(f), scenario_name, sha, seed, variant, value, methods)
        series = _series_path(out_dir, seed, variant)
        if problem is None:
            try:
                import pyarrow.parquet as pq
                pq.read_metadata(series)
            except Exception:  # noqa: BLE001
                problem = "has no readable series file " + series.name
        if problem is not None:
            print(f"warning: {f}: {problem}; the run is redone", file=sys.stderr, flush=True)
            f.unlink()
            series.unlink(missing_ok=True)
            redo.add((seed, variant))
    return redo


def _read_records(out_dir: Path) -> pd.DataFrame:
    files = sorted((out_dir / RUNS_DIR).glob("run_*.parquet"))
    if not files:
        return pd.DataFrame(columns=list(ID_COLUMNS))
    df = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
    keys = ["sweep_value", "seed", "method"] if "sweep_value" in df.columns else ["seed", "method"]
    return df.sort_values(keys, kind="stable").reset_index(drop=True)


def run_experiment(scenario: str, runs: int, out_dir: Path, workers: int | None = None,
                   resume: bool = False, seeds_from: int = 0, progress: bool = True,
                   scheduler: str | None = None, overwrite: bool = False) -> pd.DataFrame:
    """Run every method of ``scenario`` over seeds ``seeds_from .. seeds_from + runs - 1``.

    Parameters
    ----------
    scenario : str
        Shipped scenario name or path of a ``.toml`` file.
    runs : int
        Number of seeded runs (>= 1).
    out_dir : Path
        Output folder (layout in the module docstring).
    workers : int or None
        Worker processes (default ``os.cpu_count()``); 1 runs in this process
        without a pool.
    resume : bool
        Continue an experiment in ``out_dir``: run only the seeds without a
        record file. Refused when the scenario text differs from the
        manifest's. Without ``resume`` a folder that already holds an
        experiment is refused too (records of other seeds would be mixed in).
    seeds_from : int
        First seed (>= 0).
    progress : bool
        Report progress on stderr.
    scheduler : str or None
        Address of a Dask scheduler (``"tcp://127.0.0.1:8786"``): the runs
        are submitted to its workers instead of a local pool (``workers`` is
        then not used). The workers must import the same mixnav and see
        ``out_dir`` (and a scenario given as a path) at the same path: they
        write the record files themselves. The connection is made only when
        some seed still needs a run, before anything is written.

    overwrite : bool
        Clear ``out_dir`` first when it holds another experiment or anything
        else (the output-folder policy, :mod:`mixnav.io.outdir`).

    Returns
    -------
    pandas.DataFrame
        Every record in ``out_dir/runs`` (also those of earlier resumed
        calls), sorted by seed and method; also written to
        ``results.parquet`` and ``results.csv``.

    Raises
    ------
    ArgumentError
        Bad ``runs``/``workers``/``seeds_from``/``scheduler``/``out_dir``, or
        ``resume`` with ``overwrite`` (it names the argument), or more than
        :data:`MAX_RUNS` runs in one call.
    ConfigError
        An unknown or invalid scenario (from the loader), an ``out_dir`` that does not
        match, ``distributed`` not installed, or a scheduler that cannot be
        reached within :data:`DASK_CONNECT_TIMEOUT_S` (or has no worker).
    """
    # the Python argument is named (mixnav.cli says it as the option the user wrote)
    if isinstance(runs, bool) or not isinstance(runs, (int, np.integer)) or runs < 1:
        raise ArgumentError(f"must be a positive integer, got {runs!r}", argument="runs")
    if workers is None:
        workers = os.cpu_count() or 1
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ArgumentError(f"must be a positive integer, got {workers!r}", argument="workers")
    if isinstance(seeds_from, bool) or not isinstance(seeds_from, (int, np.integer)) or seeds_from < 0:
        raise ArgumentError(f"must be a non-negative integer, got {seeds_from!r}", argument="seeds_from")
    if int(seeds_from) + int(runs) - 1 > 2**63 - 1:   # seeds are stored as 64-bit integers
        raise ArgumentError(f"{seeds_from} with {runs} runs goes beyond the largest seed, 2**63 - 1",
                            argument="seeds_from")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler.strip()):
        raise ArgumentError(f"must be a Dask scheduler address such as 'tcp://127.0.0.1:8786', got {scheduler!r}",
                            argument="scheduler")
    if resume and overwrite:
        raise ArgumentError("continues the experiment in out_dir and overwrite clears it: pass one of the two",
                            argument="resume")
    if "\x00" in str(out_dir):
        raise ArgumentError("holds a NUL byte", argument="out_dir")
    variants, source, sha, sweep = _load(scenario)  # unknown scenario: the loader's ConfigError
    sc = variants[0][1]
    out_dir = Path(out_dir)
    if int(runs) * len(variants) > MAX_RUNS:
        raise ArgumentError(f"{runs} asks for {int(runs) * len(variants)} runs; at most {MAX_RUNS} per call "
                            "(continue with resume and a larger number of runs)", argument="runs")
    seeds = [int(seeds_from) + i for i in range(int(runs))]
    methods = [m.name for m in sc.methods]
    # (seed, variant) of every run asked for; variant None when there is no sweep
    tasks = [(s, v) for s in seeds
             for v in ([None] if sweep is None else range(len(variants)))]

    manifest_path = out_dir / MANIFEST
    old_seeds: list[int] = []
    if manifest_path.is_file() and not overwrite:
        if not resume:
            raise ConfigError("folder already holds an experiment; pass resume (--resume) to "
                              "continue it or choose another folder", file=str(out_dir))
        import json
        try:
            old = json.loads(manifest_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"cannot read {MANIFEST}: {exc}", file=str(out_dir)) from None
        if old.get("scenario_sha256") != sha:
            raise ConfigError(
                f"cannot resume: the experiment in this folder was run with scenario "
                f"'{old.get('scenario')}' ({old.get('source')}, sha256 "
                f"{str(old.get('scenario_sha256'))[:12]}...), not with {source} (sha256 "
                f"{sha[:12]}...)", file=str(out_dir))
        old_seeds = [int(s) for s in old.get("seeds", [])]
    elif not resume and not overwrite and (out_dir / RUNS_DIR).is_dir() and \
            any((out_dir / RUNS_DIR).glob("run_*.parquet")):
        raise ConfigError("folder holds run records but no manifest; remove them or choose "
                          "another folder", file=str(out_dir))
    from ..io.outdir import check_out_dir, clear_folder, write_marker
    try:
        out_dir, state = check_out_dir(out_dir, "experiment", overwrite, protect=[source],
                                       extra_ok=EXPERIMENT_FILES)
    except ArgumentError as exc:
        raise ConfigError(exc.message) from None
    if state == "clear":
        clear_folder(out_dir)
        old_seeds = []
    todo_redo = _check_records(out_dir, sc.scenario.name, sha, methods, variants, sweep,
                               set(old_seeds) | set(seeds)) if state == "same" else set()
    if state == "same":
        _remove_products(out_dir)   # an interrupted resume never leaves old results beside new records
    out_dir.mkdir(parents=True, exist_ok=True)
    write_marker(out_dir, "experiment", False)
    tasks = tasks + sorted(todo_redo - set(tasks), key=lambda t: (t[0], -1 if t[1] is None else t[1]))

    # Connect before writing anything: an unreachable scheduler leaves no trace.
    client = None
    if scheduler is not None and any(not _record_path(out_dir, *t).exists() for t in tasks):
        client = _dask_client(scheduler.strip())
    try:
        return _run_tasks(scenario, sc, sweep, source, sha, tasks, methods, old_seeds, out_dir,
                          workers, progress, client)
    finally:
        if client is not None:
            client.close()


def _run_tasks(scenario, sc, sweep, source, sha, tasks, methods, old_seeds, out_dir, workers,
               progress, client) -> pd.DataFrame:
    """Write the manifest, run the tasks without a record, collect the records."""
    all_seeds = sorted(set(old_seeds) | {s for s, _ in tasks})
    manifest = {"scenario": sc.scenario.name, "source": source, "scenario_sha256": sha,
                "mixnav_version": __version__, "runs": len(all_seeds), "seeds": all_seeds,
                "methods": methods}
    if sweep is not None:
        manifest["sweep"] = {"name": sweep.name, "values": list(sweep.values)}
    atomic_write_json(out_dir / MANIFEST, manifest)
    runs_dir = out_dir / RUNS_DIR
    runs_dir.mkdir(parents=True, exist_ok=True)
    for folder in (out_dir, runs_dir):   # left by a writer killed earlier (never a live one's)
        remove_stale_temporaries(folder)
    todo = [t for t in tasks if not _record_path(out_dir, *t).exists()]

    bar = _Progress(len(todo), progress)
    try:
        if client is not None and todo:
            _run_dask(client, scenario, sha, todo, out_dir, bar)
        elif workers == 1 or len(todo) <= 1:
            try:
                for s, v in todo:
                    _run_and_write(scenario, sha, s, str(out_dir), v)
                    bar.advance()
            except BaseException:
                # the write here was cut off: an interrupt inside tempfile can leave its file
                remove_stale_temporaries(runs_dir)
                raise
        elif todo:
            _run_pool(scenario, sha, todo, out_dir, min(workers, len(todo)), bar)
    finally:
        bar.close()

    df = _read_records(out_dir)
    atomic_write_dataframe(out_dir / "results.parquet", df)
    atomic_write_dataframe(out_dir / "results.csv", df)
    return df


def _run_pool(scenario: str, sha: str, todo: list[tuple], out_dir: Path, workers: int,
              bar: _Progress) -> None:
    # finished records stay on disk: the experiment can be resumed. A worker ended in the
    # middle of an atomic write leaves its temporary file: removed after the pool ends
    pool_map(_run_and_write, [(scenario, sha, s, str(out_dir), v) for s, v in todo], workers, bar,
             initializer=_worker_init, initargs=(scenario, sha), terminate=_terminate_pool,
             on_abort=lambda ended: remove_stale_temporaries(out_dir / RUNS_DIR, ended))


def _task_scenario(scenario: str) -> str:
    """``scenario`` as a worker in another folder can load it (absolute path of a file)."""
    p = Path(scenario)
    return str(p.resolve()) if p.suffix == ".toml" or p.exists() else scenario


def _run_dask(client, scenario: str, sha: str, todo: list[tuple], out_dir: Path,
              bar: _Progress) -> None:
    # finished records stay on disk: an interrupted experiment can be resumed
    import uuid
    task_scenario, target = _task_scenario(scenario), str(Path(out_dir).resolve())
    tag = uuid.uuid4().hex[:8]
    dask_map(client, _run_and_write, [(task_scenario, sha, s, target, v) for s, v in todo], bar,
             keys=[f"mixnav-run-{tag}-{_stem(s, v)}" for s, v in todo])


def series_files(out_dir: Path) -> tuple[list[Path], list[float] | None]:
    """The series files of the finished runs in ``out_dir`` and, for a sweep,
    the sweep value of each (from the manifest); ``(files, None)`` otherwise.

    A run counts as finished when its record exists (the series is written
    before it), so an interrupted run's lone series is left out.
    """
    import json
    import re
    out_dir = Path(out_dir)
    man = json.loads((out_dir / MANIFEST).read_text(encoding="utf-8"))
    values = man.get("sweep", {}).get("values")
    files, vals = [], []
    for rec in sorted((out_dir / RUNS_DIR).glob("run_*.parquet")):
        stem = rec.name[len("run_"):-len(".parquet")]
        f = out_dir / RUNS_DIR / f"series_{stem}.parquet"
        if not f.exists():
            continue  # a record from before series were written
        files.append(f)
        m = re.search(r"_v(\d+)$", stem)
        if values is not None and m is not None:
            vals.append(float(values[int(m.group(1))]))
    return files, (vals if values is not None else None)


def write_experiment_outputs(scenario: str, results: pd.DataFrame, out_dir: Path, figures: bool = True) -> dict:
    """Summaries and report of an experiment folder after :func:`run_experiment`.

    Writes ``summary.csv`` (:func:`aggregate`), ``series_summary.parquet``
    (per-epoch RMS errors, sigmas, NEES, NIS over runs), ``consistency.csv``
    and ``report.html`` with its PNG figures (``figures=False``: the tables alone,
    :func:`~.mc_report.write_experiment_report`). Returns the tables written
    (``summary``, ``series``, ``consistency``).
    """
    from ..config.loader import resolve
    from .mc_report import write_experiment_report
    from .mc_series import consistency_table, summarise_series
    out_dir = Path(out_dir)
    variants, _, _, sweep = _load(scenario)
    sc = variants[0][1]
    summary = aggregate(results)
    atomic_write_dataframe(out_dir / "summary.csv", summary)
    files, values = series_files(out_dir)
    series = summarise_series(files, values)
    consistency = consistency_table(series)
    if not series.empty:
        atomic_write_dataframe(out_dir / "series_summary.parquet", series)
    if not consistency.empty:
        atomic_write_dataframe(out_dir / "consistency.csv", consistency)
    write_experiment_report(out_dir, scenario, results, summary, config_text=resolve(scenario)[0],
                            series=series, consistency=consistency,
                            outages=[tuple(o) for o in sc.gnss.outages],
                            sweep_name=None if sweep is None else sweep.name,
                            headline=sc.scenario.report_table,
                            segments=[g for g, _, _ in sc.scored_segments], figures=figures)
    from ..io.outdir import write_marker
    write_marker(out_dir, "experiment", True, [p.name for p in out_dir.iterdir()])
    return {"summary": summary, "series": series, "consistency": consistency}


# ---------------------------------------------------------------- statistics

def _metric_columns(results: pd.DataFrame) -> list[str]:
    return [c for c in results.columns if c not in ID_COLUMNS
            and pd.api.types.is_numeric_dtype(results[c])]


def _ci95(x: np.ndarray) -> tuple[float, float, float]:
    """Mean, std (ddof 1) and half width of the 95 % t confidence interval of the mean."""
    from scipy import stats
    n = len(x)
    mean = float(np.mean(x)) if n else math.nan
    if n < 2:
        return mean, math.nan, math.nan
    std = float(np.std(x, ddof=1))
    return mean, std, float(stats.t.ppf(0.975, n - 1) * std / math.sqrt(n))


def aggregate(results: pd.DataFrame) -> pd.DataFrame:
    """Per method and metric: n, mean, std, 95 % CI of the mean, median.

    Parameters
    ----------
    results : pandas.DataFrame
        Records as returned by :func:`run_experiment` (column ``method`` plus
        numeric metric columns; ``seed`` and ``scenario`` are ignored).

    Returns
    -------
    pandas.DataFrame
        Long format, one row per (method, metric): ``method, metric, n,
        mean, std, ci95_low, ci95_high, ci95_half, median``; with a leading
        ``sweep_value`` column (one block per value) when the results have
        one. NaNs are left out of ``n``; the CI uses the t distribution with
        ``n - 1`` degrees of freedom (NaN when ``n < 2``).
    """
    if "method" not in results.columns:
        raise ConfigError("results table has no 'method' column")
    rows = []
    metrics = _metric_columns(results)
    sweep = "sweep_value" in results.columns
    keys = ["sweep_value", "method"] if sweep else ["method"]
    for key, g in results.groupby(keys, sort=True):
        ident = dict(zip(keys, key))
        for metric in metrics:
            x = g[metric].to_numpy(dtype=float)
            x = x[np.isfinite(x)]
            mean, std, half = _ci95(x)
            rows.append({**ident, "metric": metric, "n": int(len(x)), "mean": mean,
                         "std": std, "ci95_low": mean - half, "ci95_high": mean + half,
                         "ci95_half": half, "median": float(np.median(x)) if len(x) else math.nan})
    return pd.DataFrame(rows, columns=keys + ["metric", "n", "mean", "std", "ci95_low",
                                              "ci95_high", "ci95_half", "median"])


def paired_comparison(results: pd.DataFrame, metric: str, a: str, b: str,
                      sweep_value: float | None = None) -> dict:
    """Compare methods ``a`` and ``b`` on ``metric`` over the seeds both have.

    With a sweep (a ``sweep_value`` column) give the ``sweep_value`` to
    compare at; without it the pairs are taken over every (value, seed).

    Returns
    -------
    dict
        ``metric, a, b, n`` (common seeds with finite values of both),
        ``mean_a, mean_b, mean_diff`` (a - b), ``ci95_low, ci95_high`` of
        the mean difference (t distribution), ``t_statistic`` and
        ``p_value`` of the two-sided paired t-test (scipy.stats.ttest_rel).

    Raises
    ------
    ConfigError
        Unknown metric or method, a (seed, method) pair present twice, or
        fewer than 2 common seeds.
    """
    from scipy import stats
    for col in ("seed", "method"):
        if col not in results.columns:
            raise ConfigError(f"results table has no '{col}' column")
    if metric not in results.columns:
        raise ConfigError(f"unknown metric '{metric}'; known: {', '.join(_metric_columns(results))}")
    known = sorted(results["method"].unique())
    for m in (a, b):
        if m not in known:
            raise ConfigError(f"unknown method '{m}'; known: {', '.join(map(str, known))}")
    sub = results[results["method"].isin([a, b])]
    index = ["seed"]
    if "sweep_value" in sub.columns:
        if sweep_value is not None:
            sub = sub[np.isclose(sub["sweep_value"].to_numpy(float), float(sweep_value))]
            if sub.empty:
                raise ConfigError(f"no results at sweep value {sweep_value:g}")
        else:
            index = ["sweep_value", "seed"]
    if sub.duplicated(index + ["method"]).any():
        raise ConfigError("results hold a (seed, method) pair more than once "
                          "(several scenarios mixed?)")
    wide = sub.pivot_table(index=index, columns="method", values=metric,
                           aggfunc="first", dropna=False).astype(float)
    wide = wide[np.isfinite(wide[a]) & np.isfinite(wide[b])]
    n = len(wide)
    if n < 2:
        raise ConfigError(f"paired comparison of '{a}' and '{b}' on '{metric}' needs at least 2 "
                          f"common seeds, found {n}")
    xa, xb = wide[a].to_numpy(), wide[b].to_numpy()
    mean_d, _, half = _ci95(xa - xb)
    t = stats.ttest_rel(xa, xb)
    return {"metric": metric, "a": a, "b": b, "n": n, "mean_a": float(xa.mean()),
            "mean_b": float(xb.mean()), "mean_diff": mean_d, "ci95_low": mean_d - half,
            "ci95_high": mean_d + half, "t_statistic": float(t.statistic),
            "p_value": float(t.pvalue)}
