"""Monte Carlo runner on a real Dask cluster, unreachable schedulers, and a killed run."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from .conftest import reproducible as _reproducible

from mixnav.errors import ArgumentError, ConfigError
from mixnav.experiment.montecarlo import run_experiment

SCENARIO = "loose-demo"
SRC = Path(__file__).resolve().parents[1] / "src"


@pytest.fixture(scope="module")
def local3(tmp_path_factory):
    """3 runs in-process (workers=1), seeds 0..2: the reference table."""
    out = tmp_path_factory.mktemp("local3")
    return run_experiment(SCENARIO, 3, out, workers=1, progress=False)


@pytest.fixture(scope="module")
def cluster():
    """A real scheduler and two worker processes on loopback."""
    distributed = pytest.importorskip("distributed")
    # the worker processes must import this checkout of mixnav
    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(SRC), old) if p)
    try:
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      host="127.0.0.1", dashboard_address=None) as c:
            yield c
    finally:
        if old is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = old


def test_dask_cluster_gives_the_local_numbers(cluster, local3, tmp_path):
    df = run_experiment(SCENARIO, 3, tmp_path, scheduler=cluster.scheduler_address,
                        progress=False)
    assert sorted(p.name for p in (tmp_path / "runs").glob("run_*.parquet")) == \
        [f"run_{s}.parquet" for s in (0, 1, 2)]
    assert not list((tmp_path / "runs").glob(".*"))
    pd.testing.assert_frame_equal(_reproducible(df), _reproducible(local3))
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "results.parquet"), df)


def test_dask_resume_runs_only_missing_seeds(cluster, local3, tmp_path):
    run_experiment(SCENARIO, 2, tmp_path, workers=1, progress=False)  # seeds 0, 1 locally
    kept = (tmp_path / "runs" / "run_0.parquet").stat().st_mtime_ns
    df = run_experiment(SCENARIO, 3, tmp_path, resume=True, scheduler=cluster.scheduler_address,
                        progress=False)
    assert (tmp_path / "runs" / "run_0.parquet").stat().st_mtime_ns == kept
    pd.testing.assert_frame_equal(_reproducible(df), _reproducible(local3))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:1", "free-port"])
def test_unreachable_scheduler_fails_fast(tmp_path, address):
    pytest.importorskip("distributed")
    if address == "free-port":
        address = f"tcp://127.0.0.1:{_free_port()}"
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match="cannot connect to the Dask scheduler") as exc:
        run_experiment(SCENARIO, 2, tmp_path, scheduler=address, progress=False)
    elapsed = time.perf_counter() - t0
    assert address in str(exc.value)
    assert elapsed < 10, f"took {elapsed:.1f} s"
    assert not (tmp_path / "manifest.json").exists()  # nothing written


def test_bad_scheduler_argument(tmp_path):
    with pytest.raises(ArgumentError, match="scheduler") as exc:
        run_experiment(SCENARIO, 2, tmp_path, scheduler="", progress=False)
    assert exc.value.argument == "scheduler"
    assert not (tmp_path / "manifest.json").exists()


def test_missing_distributed_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails
    with pytest.raises(ConfigError, match=r'pip install "mixnav\[dask\]"'):
        run_experiment(SCENARIO, 2, tmp_path, scheduler="tcp://127.0.0.1:8786", progress=False)
    assert not (tmp_path / "manifest.json").exists()


def test_killed_experiment_resumes_to_the_uninterrupted_table(tmp_path):
    out, fresh_dir = tmp_path / "killed", tmp_path / "fresh"
    runs = 8
    code = ("from mixnav.experiment.montecarlo import run_experiment; "
            f"run_experiment({SCENARIO!r}, {runs}, {str(out)!r}, workers=1, progress=False)")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(SRC), env.get("PYTHONPATH")) if p)
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 40
        while len(list((out / "runs").glob("run_*.parquet"))) < 2:
            if proc.poll() is not None:
                pytest.fail(f"experiment ended early: {proc.stderr.read().decode()[-2000:]}")
            if time.monotonic() > deadline:
                pytest.fail("no 2 records after 40 s")
            time.sleep(0.005)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL

    records = sorted((out / "runs").glob("run_*.parquet"))
    assert 2 <= len(records) < runs, "the kill came too late to interrupt anything"
    # every record is whole: it reads back with the expected seed
    for p in records:
        rec = pd.read_parquet(p)
        assert len(rec) >= 1 and set(rec["seed"]) == {int(p.stem.split("_")[1])}
    # only atomic-writer temp files may be left besides them
    others = [p.name for p in (out / "runs").iterdir()
              if p not in records and not p.name.startswith("series_")]
    assert all(n.startswith((".run_", ".series_")) and n.endswith(".tmp") for n in others), others
    assert not (out / "results.parquet").exists()

    df = run_experiment(SCENARIO, runs, out, workers=1, resume=True, progress=False)
    assert not list((out / "runs").glob(".*"))  # the resume removed the stray temp files
    assert sorted(p.name for p in (out / "runs").glob("run_*")) == \
        sorted(f"run_{s}.parquet" for s in range(runs))
    # a seed's series is written before its record: every record has its series
    assert {p.name[len("series_"):] for p in (out / "runs").glob("series_*")} >= \
        {p.name[len("run_"):] for p in (out / "runs").glob("run_*")}
    fresh = run_experiment(SCENARIO, runs, fresh_dir, workers=1, progress=False)
    pd.testing.assert_frame_equal(_reproducible(df), _reproducible(fresh))
