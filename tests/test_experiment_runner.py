"""Monte Carlo experiment runner: reproducibility, resume, statistics, bad input."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from .conftest import reproducible as _reproducible
from scipy import stats

from mixnav.errors import ArgumentError, ConfigError
from mixnav.experiment import montecarlo as mc
from mixnav.experiment.montecarlo import (aggregate, flatten_metrics,
                                          paired_comparison, run_experiment)

SCENARIO = "loose-demo"


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """4 runs in-process (workers=1), seeds 3..6."""
    out = tmp_path_factory.mktemp("serial")
    return out, run_experiment(SCENARIO, 4, out, workers=1, seeds_from=3, progress=False)


def test_record_layout_and_manifest(serial):
    out, df = serial
    assert sorted(p.name for p in (out / "runs").glob("run_*.parquet")) == \
        [f"run_{s}.parquet" for s in (3, 4, 5, 6)]
    assert sorted(p.name for p in (out / "runs").glob("series_*.parquet")) == \
        [f"series_{s}.parquet" for s in (3, 4, 5, 6)]
    assert not list((out / "runs").glob(".*"))  # no temp files left
    man = json.loads((out / "manifest.json").read_text())
    assert man["scenario"] == SCENARIO
    assert man["seeds"] == [3, 4, 5, 6] and man["runs"] == 4
    assert man["methods"] == ["ekf"]
    assert len(man["scenario_sha256"]) == 64 and man["mixnav_version"]
    assert list(df.columns[:3]) == ["scenario", "seed", "method"]
    assert len(df) == 4 and set(df["method"]) == {"ekf"}
    for col in ("horizontal_rmse_m", "yaw_rmse_deg", "epoch_time_mean_us", "nees_pos_mean",
                "outage0_horizontal_max_m", "outage0_horizontal_final_m", "recoveries_total"):
        assert col in df.columns, col
        assert np.isfinite(df[col].to_numpy(dtype=float)).all()
    assert "recoveries" not in df.columns and "outages" not in df.columns
    # different seeds draw different errors
    assert df["horizontal_rmse_m"].nunique() == 4
    pd.testing.assert_frame_equal(pd.read_parquet(out / "results.parquet"), df)
    assert len(pd.read_csv(out / "results.csv")) == 4


def test_workers_1_and_2_give_the_same_numbers(serial, tmp_path):
    _, df1 = serial
    df2 = run_experiment(SCENARIO, 4, tmp_path, workers=2, seeds_from=3, progress=False)
    pd.testing.assert_frame_equal(_reproducible(df1), _reproducible(df2))


def test_resume_recomputes_only_missing_runs(serial, tmp_path, monkeypatch, capsys):
    src, df_full = serial
    # copy the finished experiment, then simulate an interruption
    (tmp_path / "runs").mkdir()
    (tmp_path / "manifest.json").write_bytes((src / "manifest.json").read_bytes())
    for p in (src / "runs").glob("*.parquet"):  # records and their series
        (tmp_path / "runs" / p.name).write_bytes(p.read_bytes())
    (tmp_path / "runs" / "run_4.parquet").unlink()
    (tmp_path / "runs" / "run_6.parquet").unlink()
    (tmp_path / "runs" / ".run_6.parquet.abc.tmp").write_bytes(b"half")  # killed writer
    kept = {s: (tmp_path / "runs" / f"run_{s}.parquet").stat().st_mtime_ns for s in (3, 5)}

    calls = []
    real = mc._compute_run
    monkeypatch.setattr(mc, "_compute_run", lambda *a: calls.append(a[2]) or real(*a))
    df = run_experiment(SCENARIO, 4, tmp_path, workers=1, seeds_from=3, resume=True, progress=True)
    assert sorted(calls) == [4, 6]
    for s, t in kept.items():
        assert (tmp_path / "runs" / f"run_{s}.parquet").stat().st_mtime_ns == t
    assert not list((tmp_path / "runs").glob(".*"))
    pd.testing.assert_frame_equal(_reproducible(df), _reproducible(df_full))
    # the untouched records keep even their timing numbers
    pd.testing.assert_frame_equal(df[df.seed.isin([3, 5])].reset_index(drop=True),
                                  df_full[df_full.seed.isin([3, 5])].reset_index(drop=True))
    # plain progress lines when stderr is not a terminal
    assert "runs done 2/2" in capsys.readouterr().err

    # a complete experiment resumes to nothing
    calls.clear()
    run_experiment(SCENARIO, 4, tmp_path, workers=1, seeds_from=3, resume=True, progress=False)
    assert calls == []


def test_resume_refuses_another_scenario(tmp_path):
    man = {"scenario": "other", "source": "other.toml", "scenario_sha256": "0" * 64, "seeds": [0]}
    (tmp_path / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(ConfigError, match="cannot resume") as exc:
        run_experiment(SCENARIO, 2, tmp_path, workers=1, resume=True, progress=False)
    assert str(tmp_path) in str(exc.value)
    assert not (tmp_path / "runs").exists()


def test_existing_experiment_needs_resume(serial):
    out, _ = serial
    with pytest.raises(ConfigError, match="resume") as exc:
        run_experiment(SCENARIO, 4, out, workers=1, seeds_from=3, progress=False)
    assert str(out) in str(exc.value)


@pytest.mark.parametrize("kw, word", [({"runs": 0}, "runs"), ({"runs": -3}, "runs"),
                                      ({"runs": 2.5}, "runs"), ({"runs": 10 ** 9}, "runs"),
                                      ({"workers": 0}, "workers"), ({"seeds_from": -1}, "seeds_from"),
                                      ({"seeds_from": 2 ** 63 - 1}, "seeds_from"),
                                      ({"resume": True, "overwrite": True}, "resume"),
                                      ({"out_dir": "x\x00y"}, "out_dir")])
def test_bad_input(tmp_path, kw, word):
    # called from Python, the error names the Python argument (the command names its option:
    # tests/test_bad_inputs.py)
    args = {"scenario": SCENARIO, "runs": 2, "out_dir": tmp_path, "workers": 1, "progress": False}
    args.update(kw)
    with pytest.raises(ArgumentError) as exc:
        run_experiment(**args)
    assert exc.value.argument == word and "--" not in str(exc.value)
    assert not (tmp_path / "manifest.json").exists()


def test_unknown_scenario(tmp_path):
    with pytest.raises(ConfigError, match="unknown scenario 'no-such-scenario'"):
        run_experiment("no-such-scenario", 2, tmp_path, workers=1, progress=False)
    assert not (tmp_path / "manifest.json").exists()


def test_flatten_metrics():
    m = {"horizontal_rmse_m": 1.5, "n_epochs": np.int64(600),
         "outages": [{"start_s": 300.0, "end_s": 360.0, "horizontal_max_m": 6.0},
                     {"start_s": 400.0, "end_s": 420.0, "horizontal_max_m": 2.0}],
         "recoveries": {"rejected_absurd": 2, "covariance_repair": 1},
         "some_array": [1, 2, 3]}
    f = flatten_metrics(m)
    assert f == {"horizontal_rmse_m": 1.5, "n_epochs": 600,
                 "outage0_start_s": 300.0, "outage0_end_s": 360.0, "outage0_horizontal_max_m": 6.0,
                 "outage1_start_s": 400.0, "outage1_end_s": 420.0, "outage1_horizontal_max_m": 2.0,
                 "recoveries_total": 3, "recoveries_rejected_absurd": 2,
                 "recoveries_covariance_repair": 1}
    assert type(f["n_epochs"]) is int


def _hand_made():
    a = [1.0, 2.0, 4.0, 7.0, 11.0]
    b = [1.5, 2.0, 3.0, 5.0, 8.0]
    rows = [{"scenario": "s", "seed": i, "method": "a", "err": x, "k": 2 * x} for i, x in enumerate(a)]
    rows += [{"scenario": "s", "seed": i, "method": "b", "err": x, "k": 1.0} for i, x in enumerate(b)]
    rows.append({"scenario": "s", "seed": 9, "method": "b", "err": 100.0, "k": 1.0})  # unpaired
    return pd.DataFrame(rows), np.array(a), np.array(b)


def test_aggregate_matches_closed_form():
    df, a, b = _hand_made()
    agg = aggregate(df)
    assert set(agg["metric"]) == {"err", "k"}  # seed is not a metric
    r = agg[(agg.method == "a") & (agg.metric == "err")].iloc[0]
    n = 5
    mean = a.sum() / n
    std = math.sqrt(((a - mean) ** 2).sum() / (n - 1))
    half = stats.t.ppf(0.975, n - 1) * std / math.sqrt(n)
    assert r["n"] == n
    assert r["mean"] == pytest.approx(5.0)
    assert r["std"] == pytest.approx(std)
    assert r["ci95_low"] == pytest.approx(mean - half)
    assert r["ci95_high"] == pytest.approx(mean + half)
    assert r["median"] == 4.0
    # t quantile with 4 dof, independent of scipy: 2.7764451
    assert r["ci95_half"] == pytest.approx(2.7764451 * std / math.sqrt(5), rel=1e-7)
    rb = agg[(agg.method == "b") & (agg.metric == "k")].iloc[0]
    assert rb["n"] == 6 and rb["std"] == 0 and rb["ci95_half"] == 0


def test_aggregate_single_run_and_nan():
    df = pd.DataFrame({"seed": [0, 1], "method": ["a", "a"], "x": [1.0, np.nan]})
    r = aggregate(df).iloc[0]
    assert r["n"] == 1 and r["mean"] == 1.0 and math.isnan(r["std"]) and math.isnan(r["ci95_low"])


def test_paired_comparison_matches_ttest_rel():
    df, a, b = _hand_made()
    res = paired_comparison(df, "err", "a", "b")
    t = stats.ttest_rel(a, b)
    d = a - b
    half = stats.t.ppf(0.975, 4) * d.std(ddof=1) / math.sqrt(5)
    assert res["n"] == 5
    assert res["mean_diff"] == pytest.approx(d.mean())
    assert res["ci95_low"] == pytest.approx(d.mean() - half)
    assert res["ci95_high"] == pytest.approx(d.mean() + half)
    assert res["p_value"] == pytest.approx(t.pvalue)
    assert res["t_statistic"] == pytest.approx(t.statistic)
    assert res["mean_b"] == pytest.approx(b.mean())  # seed 9 of b is left out


def test_paired_comparison_bad_input():
    df, _, _ = _hand_made()
    with pytest.raises(ConfigError, match="unknown method 'c'"):
        paired_comparison(df, "err", "a", "c")
    with pytest.raises(ConfigError, match="unknown metric 'nope'"):
        paired_comparison(df, "nope", "a", "b")
    with pytest.raises(ConfigError, match="at least 2 common seeds"):
        paired_comparison(df[df.seed <= 0], "err", "a", "b")
    with pytest.raises(ConfigError, match="more than once"):
        paired_comparison(pd.concat([df, df]), "err", "a", "b")


def _no_init(scenario, sha):
    pass


def _killed_while_writing(scenario, sha, seed, out_dir, variant=None):
    """A worker that dies in the middle of an atomic write: its temporary file stays."""
    import os
    from pathlib import Path
    if seed == 1:     # the name an atomic write of this process gives its temporary file
        (Path(out_dir) / mc.RUNS_DIR / f".series_{seed}.parquet.{os.getpid()}.x1y2z3.tmp").write_bytes(b"half")
        os._exit(9)
    import time
    time.sleep(0.2)
    return seed


def test_a_killed_worker_leaves_no_temporary_file(tmp_path, monkeypatch):
    # the CI failure of stop 31: a worker ended mid-write left runs/.series_3.parquet.*.tmp
    # after the command had said "nothing half written was kept"
    from concurrent.futures.process import BrokenProcessPool
    monkeypatch.setattr(mc, "_worker_init", _no_init)
    monkeypatch.setattr(mc, "_run_and_write", _killed_while_writing)
    (tmp_path / mc.RUNS_DIR).mkdir()
    with pytest.raises(BrokenProcessPool):
        mc._run_pool(SCENARIO, "sha", [(0, None), (1, None), (2, None)], tmp_path, 2,
                     mc._Progress(3, False))
    assert not list((tmp_path / mc.RUNS_DIR).iterdir())


def _die_init(scenario, sha):
    mc._die_with_parent()


def _fails_or_sleeps(scenario, sha, seed, out_dir, variant=None):
    import time
    if seed == 0:
        time.sleep(0.5)      # the other worker is inside its long run by then
        raise ValueError("run 0 fails")
    time.sleep(60.0)
    return seed


def test_workers_end_at_the_first_sigterm(tmp_path, monkeypatch):
    """A failed run ends the pool: the other worker, in the middle of a long run, ends at the
    SIGTERM (exit code -15) instead of taking it as its task's exception and going on to the
    next run until SIGKILLed (-9) -- a forked worker inherits the command's SIGTERM handler
    (cli._terminate raises KeyboardInterrupt), which _die_with_parent resets."""
    import signal
    from mixnav import cli
    monkeypatch.setattr(mc, "_worker_init", _die_init)
    monkeypatch.setattr(mc, "_run_and_write", _fails_or_sleeps)
    old = signal.signal(signal.SIGTERM, cli._terminate)    # as under the command line
    codes = []
    real = mc._terminate_pool

    def recording(pool, timeout=5.0):
        procs = list(pool._processes.values())
        manager = pool._executor_manager_thread
        ended = real(pool, timeout)
        # the executor's manager thread reaps the workers too: the thread that loses that
        # race reads no exit code until the other has stored it
        if manager is not None:
            manager.join(10.0)
        codes.extend(p.exitcode for p in procs)
        return ended

    monkeypatch.setattr(mc, "_terminate_pool", recording)
    (tmp_path / mc.RUNS_DIR).mkdir()
    try:
        with pytest.raises(ValueError, match="run 0 fails"):
            mc._run_pool(SCENARIO, "sha", [(0, None), (1, None), (2, None)], tmp_path, 2,
                         mc._Progress(3, False))
    finally:
        signal.signal(signal.SIGTERM, old)
    assert codes and all(c == -signal.SIGTERM for c in codes), codes
