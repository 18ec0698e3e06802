"""The outage sweep (mixnav.experiment.sweep): windows, motion, summary, and on drive-0708
the same numbers as processing the dataset with that one window withheld."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import mixnav
from mixnav.cli import app
from mixnav.errors import ConfigError
from mixnav.data import Trajectory
from mixnav.errors import ArgumentError
from mixnav.experiment.metrics import compute_metrics
from mixnav.experiment.sweep import (NEES_POS_99, OUTAGE_SWEEP_COLUMNS, run_outage_sweep, summarize, sweep_windows,
                                     window_motion)
from mixnav.geodesy.frames import ned_to_lla

from .conftest import DATA_DIR

SHIPPED = Path(__file__).resolve().parents[1] / "src" / "mixnav" / "config" / "datasets"


def test_windows_tile_the_span_and_end_inside_it():
    w = sweep_windows(53.0, 543.4, 30.0, 10.0)
    # floor((543.4 - 53 - 30) / 10) + 1 = 47 starts, 10 s apart, each 30 s long
    assert len(w) == 47
    assert w[0] == (53.0, 83.0) and w[-1] == (513.0, 543.0)
    assert all(b - a == 30.0 for a, b in w) and np.allclose(np.diff([a for a, _ in w]), 10.0)
    assert sweep_windows(0.0, 30.0, 30.0, 7.0) == [(0.0, 30.0)]     # the whole span is one window


@pytest.mark.parametrize("first,last,window,step,arg", [(50.0, 70.0, 30.0, 10.0, "window"),
                                                         (0.0, 100.0, 30.0, 0.0, "step"),
                                                         (0.0, 100.0, -5.0, 10.0, "window")])
def test_impossible_windows_name_the_argument(first, last, window, step, arg):
    with pytest.raises(ArgumentError) as e:
        sweep_windows(first, last, window, step)
    assert e.value.argument == arg


def _track(t, n, e):
    lla = ned_to_lla(np.column_stack([n, e, np.zeros_like(n)]), np.array([0.7, -1.8, 1600.0]))
    return Trajectory(time=t, lla=lla, v_n=None, q_nb=None)


def test_window_motion_of_a_stop_then_a_half_circle():
    # 10 s still, then a half circle of radius 20 m at 2 m/s (pi * 20 / 2 = 31.4 s)
    t_still = np.arange(0.0, 10.0, 0.25)
    t_turn = np.arange(10.0, 10.0 + math.pi * 20 / 2 + 1e-9, 0.25)
    ang = (t_turn - 10.0) * 2.0 / 20.0
    t = np.concatenate([t_still, t_turn])
    n = np.concatenate([np.zeros_like(t_still), 20 * np.sin(ang)])
    e = np.concatenate([np.zeros_like(t_still), 20 * (1 - np.cos(ang))])
    m = window_motion(_track(t, n, e), 0.0, t[-1])
    assert m["still_s"] == pytest.approx(10.0, abs=0.26)          # one step of 0.25 s at the hand-over
    arc = 20 * ang[-1]
    assert m["distance_m"] == pytest.approx(arc, rel=1e-3)         # chords of a 20 m circle: -1e-5 relative
    assert m["heading_change_deg"] == pytest.approx(np.degrees(ang[-1]), abs=1.5)   # less the first chord's half


def test_summary_is_the_distribution_of_the_rows():
    rng = np.random.default_rng(3)
    h = rng.lognormal(1.0, 0.8, 40)
    nees = rng.chisquare(3, 40) * 1.5
    rows = pd.DataFrame({"method": ["a"] * 40, "start_s": np.arange(40) * 10.0, "end_s": np.arange(40) * 10.0 + 30,
                         "horizontal_max_m": h, "horizontal_rmse_m": h / 2, "vertical_max_m": h / 5,
                         "nees_pos_mean": nees, "nees_vel_mean": nees})
    b = summarize(rows)["a"]
    assert b["median_horizontal_max_m"] == np.median(h) and b["worst_horizontal_max_m"] == h.max()
    assert b["p90_horizontal_max_m"] == np.percentile(h, 90)
    assert b["worst_window_start_s"] == 10.0 * np.argmax(h)
    assert b["share_nees_above_99"] == np.mean(nees > 11.3448667)
    assert NEES_POS_99 == pytest.approx(11.3448667, rel=1e-7)       # chi2.ppf(0.99, 3)


def test_outage_entries_carry_the_window_nees():
    t = np.arange(0.0, 20.0, 1.0)
    tab = pd.DataFrame({"time_s": t, "err_n_m": t, "err_e_m": 0 * t, "err_d_m": 0 * t,
                        "nees_pos": t ** 2, "nees_vel": np.where(t == 5.0, np.nan, 1.0)})
    o = compute_metrics(tab, [(4.0, 8.0)])["outages"][0]
    assert o["nees_pos_mean"] == np.mean(np.arange(4.0, 9.0) ** 2)
    assert o["nees_vel_mean"] == 1.0       # the declined epoch (NaN) left out, not turned into NaN


# ---------------------------------------------------------------- drive-0708

def _needs_drive():
    if not (DATA_DIR / "drive-0708" / "imu_1934.csv").exists():
        pytest.skip(f"real data not found under {DATA_DIR}")
    return str(DATA_DIR / "drive-0708")


def _one_window_config(tmp_path, window):
    text = (SHIPPED / "drive-0708-aided.toml").read_text()
    text = re.sub(r"^withhold = .*$", f'withhold = [["{window[0]:g} s", "{window[1]:g} s"]]', text, flags=re.M)
    text = text.replace('data_dir = "../shared/data/drive-0708"', f'data_dir = "{_needs_drive()}"')
    p = tmp_path / "one_window.toml"
    p.write_text(text)
    return p


def test_each_row_is_the_dataset_processed_with_that_window_withheld(tmp_path):
    data = _needs_drive()
    res = run_outage_sweep("drive-0708-aided", "30 s", "20 s", ("80 s", "130 s"), data=data, workers=1)
    rows = res.rows
    assert list(rows.columns) == list(OUTAGE_SWEEP_COLUMNS)
    assert sorted(set(rows["start_s"])) == [80.0, 100.0]
    assert list(rows["method"].unique()) == ["ekf", "aided", "aided-smoothed"]
    # the independent route: the shipped file with its withhold replaced, through process_dataset;
    # scored by hand from its solution table (the window and the unaided stretch after it)
    run = mixnav.process_dataset(str(_one_window_config(tmp_path, (100.0, 130.0))))
    for name, sol in run.solutions.items():
        t, used = sol["time_s"].to_numpy(), sol["gnss_used"].to_numpy(bool)
        nxt = t[(t > 130.0) & used][0]
        sel = (t >= 100.0) & (t < nxt)
        h = np.hypot(sol["err_n_m"], sol["err_e_m"]).to_numpy()[sel]
        row = rows[(rows["method"] == name) & (rows["start_s"] == 100.0)].iloc[0]
        assert row["horizontal_max_m"] == pytest.approx(h.max(), rel=1e-12)
        assert row["horizontal_rmse_m"] == pytest.approx(np.sqrt(np.mean(h ** 2)), rel=1e-12)
        assert row["nees_pos_mean"] == pytest.approx(np.nanmean(sol["nees_pos"].to_numpy()[sel]), rel=1e-12)
    # what the car did: moving in both windows, by the reference
    assert (rows["distance_m"] > 50).all()


def test_workers_give_the_rows_of_one_process():
    data = _needs_drive()
    kw = dict(data=data, window="30 s", step="30 s", span=("60 s", "150 s"))
    one = mixnav.outage_sweep("drive-0708-aided", workers=1, **kw)
    two = mixnav.outage_sweep("drive-0708-aided", workers=2, **kw)
    pd.testing.assert_frame_equal(one, two, check_exact=True)


def test_bad_sweep_requests_name_the_option(tmp_path):
    data = _needs_drive()
    with pytest.raises(ArgumentError) as e:
        mixnav.outage_sweep("drive-0708-aided", "600 s", data=data, workers=1)
    assert e.value.argument == "window"
    with pytest.raises(ArgumentError) as e:
        mixnav.outage_sweep("drive-0708-aided", "30 s", "0 s", data=data, workers=1)
    assert e.value.argument == "step"
    with pytest.raises(ArgumentError) as e:
        mixnav.outage_sweep("drive-0708-aided", "30 s", "10 s", ("0 s", "100 s"), data=data, workers=1)
    assert e.value.argument == "span"                     # before the alignment (52 s)
    with pytest.raises(ConfigError) as e:                  # raw GNSS alone: no IMU to coast on
        mixnav.outage_sweep("android-static", "30 s")
    assert "evaluation.outage_sweep" in str(e.value)
    with pytest.raises(ArgumentError) as e:
        mixnav.outage_sweep("drive-0708-plain", data=data)   # no window and no [evaluation] key
    assert e.value.argument == "window"


def test_process_writes_the_sweep_beside_its_outputs(tmp_path):
    data = _needs_drive()
    out = tmp_path / "out"
    r = CliRunner().invoke(app, ["process", "drive-0708-aided", "--out", str(out), "--data", data,
                                 "--outage-sweep", "30 s", "--sweep-step", "30 s", "--sweep-span", "60 s", "150 s",
                                 "--workers", "1", "--no-progress"])
    assert r.exit_code == 0, r.output
    rows = pd.read_csv(out / "outage_sweep.csv")
    m = json.loads((out / "metrics.json").read_text())
    assert m["outage_sweep"]["n_windows"] == 3 and len(rows) == 9
    for name, block in summarize(rows).items():
        for k, v in block.items():
            # the CSV keeps 10 significant digits (io.atomic), metrics.json every bit
            assert m["methods"][name]["outage_sweep"][k] == pytest.approx(v, rel=1e-9)
    assert (out / "outage_sweep.png").exists() and "outage sweep" in (out / "report.html").read_text()
    r = CliRunner().invoke(app, ["process", "drive-0708-aided", "--out", str(tmp_path / "o2"), "--data", data,
                                 "--outage-sweep", "30 s", "--sweep-step", "0 s", "--workers", "1"])
    assert r.exit_code != 0 and "step" in r.output and not (tmp_path / "o2").exists()


# ---------------------------------------------------------------- the start sweep (smartloc-berlin)

def _needs_smartloc():
    if not (DATA_DIR / "smartloc-berlin" / "Berlin_Potsdamer_Platz_Input.txt").exists():
        pytest.skip(f"real data not found under {DATA_DIR}")
    return str(DATA_DIR / "smartloc-berlin")


def test_a_start_is_the_dataset_run_from_there(tmp_path):
    from mixnav.experiment.sweep import START_SWEEP_COLUMNS, run_start_sweep, summarize_starts
    data = _needs_smartloc()
    res = run_start_sweep("smartloc-berlin", "60 s", ("0 s", "60 s"), data=data, workers=1)
    rows = res.rows
    assert list(rows.columns) == list(START_SWEEP_COLUMNS) and sorted(set(rows["start_s"])) == [0.0, 60.0]
    # the independent route: the shipped file with [alignment] start = "60 s", through process_dataset
    text = (SHIPPED / "smartloc-berlin.toml").read_text().replace('window = "20 s"', 'window = "20 s"\nstart = "60 s"')
    text = text.replace('data_dir = "../shared/data/smartloc-berlin"', f'data_dir = "{data}"')
    (tmp_path / "late.toml").write_text(text)
    run = mixnav.process_dataset(str(tmp_path / "late.toml"))
    common = res.settings["common_span_s"][0]
    assert common == rows["filter_start_s"].max() and common >= 80.0        # 60 s + the 20 s track window
    for name, sol in run.solutions.items():
        row = rows[(rows["method"] == name) & (rows["start_s"] == 60.0)].iloc[0]
        h = np.hypot(sol["err_n_m"], sol["err_e_m"]).to_numpy()
        assert row["horizontal_rmse_m"] == pytest.approx(np.sqrt(np.mean(h ** 2)), rel=1e-12)
        assert row["common_horizontal_rmse_m"] == pytest.approx(
            np.sqrt(np.mean(h[sol["time_s"].to_numpy() >= common] ** 2)), rel=1e-12)
    s = summarize_starts(rows)["ekf"]
    e = rows[rows["method"] == "ekf"]["horizontal_rmse_m"].to_numpy()
    assert s["median_horizontal_rmse_m"] == np.median(e) and s["worst_horizontal_rmse_m"] == e.max()


def test_bad_start_sweeps_name_the_option():
    data = _needs_smartloc()
    with pytest.raises(ArgumentError) as e:
        mixnav.start_sweep("smartloc-berlin", "0 s", data=data, workers=1)
    assert e.value.argument == "step"
    with pytest.raises(ArgumentError) as e:
        mixnav.start_sweep("smartloc-berlin", "30 s", ("0 s", "400 s"), data=data, workers=1)
    assert e.value.argument == "span"
    with pytest.raises(ConfigError) as e:      # an INS dataset aligns on its GNSS fixes: an outage sweep suits it
        mixnav.start_sweep("drive-0708-aided", "30 s")
    assert "evaluation.start_sweep" in str(e.value)


def test_evaluation_keys_are_validated_and_used(tmp_path):
    from mixnav.config import load_dataset
    text = (SHIPPED / "drive-0708-plain.toml").read_text()      # no [evaluation] of its own
    bad = tmp_path / "bad.toml"
    bad.write_text(text + '\n[evaluation]\noutage_sweep = "30 s"\nsweep_span = ["300 s", "100 s"]\n')
    with pytest.raises(ConfigError) as e:
        load_dataset(str(bad))
    assert "evaluation" in str(e.value) and "before it starts" in str(e.value)
    bad.write_text(text + '\n[evaluation]\noutage_sweep = "30"\n')
    with pytest.raises(ConfigError) as e:
        load_dataset(str(bad))
    assert "evaluation.outage_sweep" in str(e.value)
    ok = tmp_path / "ok.toml"
    ok.write_text(text.replace('data_dir = "../shared/data/drive-0708"', f'data_dir = "{_needs_drive()}"')
                  + '\n[evaluation]\noutage_sweep = "30 s"\nsweep_step = "45 s"\nsweep_span = ["60 s", "150 s"]\n')
    res = run_outage_sweep(str(ok), workers=1)
    assert res.settings["window_s"] == 30.0 and res.settings["step_s"] == 45.0
    assert sorted(set(res.rows["start_s"])) == [60.0, 105.0]


def test_every_pipeline_writes_sweeps():
    """The CLI hands every pipeline's write the sweeps it ran (none for most): each accepts them."""
    import inspect

    from mixnav.experiment.pipelines import PIPELINES
    for key, p in PIPELINES.items():
        assert "sweeps" in inspect.signature(p.write).parameters, key


def test_a_phone_start_sweep_restarts_the_filters(tmp_path):
    """gnss-raw: a start moves the filters' start to the first SPP fix at or after it
    ([motion] start); each run is scored from there, the SPP's epochs too."""
    from mixnav.experiment.sweep import run_start_sweep
    d = DATA_DIR / "android-static"
    if not d.is_dir():
        pytest.skip(f"real data not found at {d}")
    res = run_start_sweep("android-static-filters", "60 s", ("0 s", "60 s"), data=str(d), workers=1)
    text = (SHIPPED / "android-static-filters.toml").read_text().replace('step = "1 s"', 'step = "1 s"\nstart = "60 s"')
    text = text.replace('data_dir = "../shared/data/android-static"', f'data_dir = "{d}"')
    (tmp_path / "late.toml").write_text(text)
    run = mixnav.process_dataset(str(tmp_path / "late.toml"))
    late = res.rows[res.rows["start_s"] == 60.0].set_index("method")
    t0 = late["filter_start_s"].iloc[0]
    assert 60.0 <= t0 < 62.0                                # the first fix at or after 60 s
    for name in ("spp", "ekf", "epoch-mixture"):
        sol = run.solutions[name]
        h = np.hypot(sol["err_n_m"], sol["err_e_m"]).to_numpy()
        keep = (sol["time_s"].to_numpy() >= t0) & np.isfinite(h)
        assert late.loc[name, "horizontal_rmse_m"] == pytest.approx(np.sqrt(np.mean(h[keep] ** 2)), rel=1e-12)
    assert np.isnan(run.solutions["ekf"]["err_n_m"].to_numpy()[run.solutions["ekf"]["time_s"].to_numpy() < t0]).all()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('start = "60 s"', 'start = "900 s"'))
    with pytest.raises(ConfigError) as e:
        mixnav.process_dataset(str(bad))
    assert "motion.start" in str(e.value)


def test_an_impossible_evaluation_key_is_named_as_the_key(tmp_path):
    """A span read from [evaluation] that the recording cannot hold is said as
    evaluation.sweep_span of the file, not as an option the user did not give."""
    data = _needs_drive()
    text = (SHIPPED / "drive-0708-plain.toml").read_text().replace('data_dir = "../shared/data/drive-0708"',
                                                              f'data_dir = "{data}"')
    p = tmp_path / "late.toml"
    p.write_text(text + '\n[evaluation]\noutage_sweep = "30 s"\nsweep_span = ["60 s", "900 s"]\n')
    with pytest.raises(ConfigError) as e:
        run_outage_sweep(str(p), workers=1)
    assert e.value.key == "evaluation.sweep_span" and str(p.name) in str(e.value)
    with pytest.raises(ArgumentError) as e:                 # given as an argument: said as the argument
        run_outage_sweep(str(p), span=("60 s", "900 s"), workers=1)
    assert e.value.argument == "span"
