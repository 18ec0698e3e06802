"""Odometry + pseudorange datasets (kind = "odometry-gnss"): config, process, outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mixnav.config import load_dataset
from mixnav.errors import ConfigError

from .conftest import DATA_DIR, data_file

SHIPPED = "smartloc-berlin"


def _config(tmp_path, text):
    p = tmp_path / "ds.toml"
    p.write_text(text)
    return str(p)


BASE = """
[dataset]
name = "x"
kind = "odometry-gnss"
data_dir = "{data}"
[odometry]
format = "smartloc"
file = "Berlin_Potsdamer_Platz_Input.txt"
[pseudoranges]
format = "smartloc"
file = "Berlin_Potsdamer_Platz_Input.txt"
"""


@pytest.mark.parametrize("extra, key", [
    ('[[methods]]\nname = "u"\nestimator = "imm"\n', "methods"),   # strapdown only
    ('[[methods]]\nname = "e"\nestimator = "ekf"\n[[methods]]\nname = "e"\nestimator = "robust-adaptive"\n',
     "methods"),
    ('[alignment]\nwindow = "10 m"\n[[methods]]\nname = "e"\n', "alignment.window"),
    ('[pseudoranges2]\nx = 1\n[[methods]]\nname = "e"\n', "pseudoranges2"),
    ('[odometry2]\n[[methods]]\nname = "e"\n', "odometry2"),
])
def test_bad_configs_name_the_key(tmp_path, extra, key):
    with pytest.raises(ConfigError) as exc:
        load_dataset(_config(tmp_path, BASE.format(data=tmp_path) + extra))
    assert exc.value.key.startswith(key), exc.value


def test_bad_estimator_option_names_the_key(tmp_path):
    data_file("smartloc-berlin", "Berlin_Potsdamer_Platz_Input.txt")
    from mixnav.experiment.vehicle_process import process_vehicle
    text = BASE.format(data=DATA_DIR / "smartloc-berlin") + ('[[methods]]\nname = "m"\nestimator = "epoch-mixture"\n'
                                                            '[methods.options]\nlos_weight = 1.5\n')
    ds, source, _ = load_dataset(_config(tmp_path, text))
    with pytest.raises(ConfigError) as exc:
        process_vehicle(ds, source)
    assert exc.value.key == "methods[0].options.los_weight"


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    data_file("smartloc-berlin", "Berlin_Potsdamer_Platz_GT.txt")
    from mixnav.experiment.vehicle_process import process_vehicle, write_vehicle
    ds, source, text = load_dataset(SHIPPED)
    vo = process_vehicle(ds, source)
    out = tmp_path_factory.mktemp("sl") / "out"
    metrics = write_vehicle(out, vo, config_text=text)
    return vo, metrics, out


def test_shipped_smartloc_runs_every_method_with_a_map(shipped):
    vo, metrics, out = shipped
    names = [m.name for m in vo.dataset.methods]
    assert set(names) <= set(metrics["methods"])
    for f in ("report.html", "trajectory.png", "horizontal_error.png", "metrics.json"):
        assert (out / f).is_file()
    assert json.loads((out / "metrics.json").read_text())["dataset"] == SHIPPED
    # causal start: the filters begin at the end of the alignment window, not before
    assert abs(metrics["start_s"] - 20.0) < 0.5
    # the per-row mixture's NIS is high here (delays treated as zero-mean): warned, with the
    # causes of a run without an INS
    assert any("'mixture'" in w for w in metrics["warnings"])
    assert not any("IMU" in w or "lever arm" in w for w in metrics["warnings"]), metrics["warnings"]
    from mixnav.experiment.metrics import METRIC_KEYS_DOC
    for name, m in metrics["methods"].items():
        prefixes = tuple(k.split("<")[0] for k in METRIC_KEYS_DOC if "<" in k)    # templated keys
        undocumented = {k for k in set(m) - {"outages"} - set(METRIC_KEYS_DOC) if not k.startswith(prefixes)}
        assert not undocumented, (name, undocumented)
        assert np.isfinite(m["horizontal_rmse_m"]) and m["n_epochs"] > 1000
        if "wall_time_s" in m:
            assert m["wall_time_s"] < 10.0          # issue 21: about 2 s per method on this machine class


def test_the_mixture_filters_beat_the_ekf_on_smartloc(shipped):
    """The whole-epoch mixture is better than the Gaussian EKF on the urban drive, and its
    smoothed solution better still (numbers in benchmarks/results/smartloc.md). Causal, from
    20 s: 6.59 m RMSE, p95 10.1, max 11.2 m (with the C/N0 bands chosen from the data, issue
    34; the bounds were set 10 % above the 6.53 / 10.2 / 11.5 m before them, so a regression
    fails) and stay below libRSF's online estimate on the same span and epochs, 8.01 m
    (benchmarks/results/smartloc_start_sweep.md, start 0 s; its p95 12.9 and max 14.4 m are
    over its own span from 0 s). Smoothed RMSE 5.27 m, bound 5.8 m."""
    _, metrics, _ = shipped
    m = metrics["methods"]
    em, ems = m["epoch-mixture"], m["epoch-mixture-smoothed"]
    assert em["horizontal_rmse_m"] <= 7.2 and em["horizontal_p95_m"] <= 11.2 and em["horizontal_max_m"] <= 12.7, em
    assert ems["horizontal_rmse_m"] <= 5.8, ems
    assert m["epoch-mixture"]["horizontal_rmse_m"] < 0.85 * m["ekf"]["horizontal_rmse_m"]
    assert m["epoch-mixture-smoothed"]["horizontal_rmse_m"] < m["epoch-mixture"]["horizontal_rmse_m"]
    assert m["epoch-mixture-smoothed"]["horizontal_max_m"] < m["ekf"]["horizontal_max_m"]


def test_api_process_dataset_smartloc(shipped, tmp_path):
    from mixnav import api
    r = api.process_dataset(SHIPPED)
    written = r.write(tmp_path / "api")
    assert (tmp_path / "api" / "trajectory.png").is_file() and set(written["methods"]) == set(r.solutions)
    _, metrics, _ = shipped
    assert set(r.solutions) == set(metrics["methods"])
    got = float(r.metrics.loc["epoch-mixture", "horizontal_rmse_m"])
    assert got == pytest.approx(metrics["methods"]["epoch-mixture"]["horizontal_rmse_m"], rel=1e-12)


@pytest.mark.parametrize("start, key", [('"-5 s"', "alignment.start"), ('"5 m"', "alignment.start")])
def test_bad_alignment_start_names_the_key(tmp_path, start, key):
    with pytest.raises(ConfigError) as exc:
        load_dataset(_config(tmp_path, BASE.format(data=tmp_path) + f'[alignment]\nstart = {start}\n'
                             '[[methods]]\nname = "e"\n'))
    assert exc.value.key.startswith(key), exc.value


def test_alignment_start_discards_the_data_before_it(tmp_path):
    """``[alignment] start``: the run is the one of a recording that began then (issue 34):
    the track window is the 20 s after it, the filters start at its end; a start past the
    data names the key."""
    data_file("smartloc-berlin", "Berlin_Potsdamer_Platz_GT.txt")
    from mixnav.experiment.vehicle_process import discard_before, process_vehicle, read_vehicle
    text = BASE.format(data=DATA_DIR / "smartloc-berlin") + ('[reference]\nformat = "smartloc"\n'
                                                            'file = "Berlin_Potsdamer_Platz_GT.txt"\n'
                                                            '[alignment]\nstart = "60 s"\n'
                                                            '[[methods]]\nname = "e"\n')
    ds, source, _ = load_dataset(_config(tmp_path, text))
    vo = process_vehicle(ds, source)
    assert 79.5 < vo.init.time < 80.5
    assert vo.checks["pseudorange_epochs"] < 0.8 * 1400
    inputs = read_vehicle(ds, source, DATA_DIR / "smartloc-berlin")
    cut = discard_before(inputs, 60.0)
    assert cut.inc.time[0] - cut.inc.dt[0] >= 60.0 - 1e-6 and cut.epochs.time[0] > 60.0
    assert cut.odometry.time[0] >= 60.0 - 1e-6 and len(cut.reference.time) == len(inputs.reference.time)
    assert cut.epochs.start[-1] == len(cut.epochs.pseudorange)
    # the rows kept are the rows of the epochs kept
    e0 = int(np.searchsorted(inputs.epochs.time, cut.epochs.time[0]))
    np.testing.assert_array_equal(cut.epochs.pseudorange, inputs.epochs.pseudorange[inputs.epochs.start[e0]:])
    assert discard_before(inputs, 0.0) is inputs
    late = ds.model_copy(update={"alignment": ds.alignment.model_copy(update={"start": 400.0})})
    with pytest.raises(ConfigError) as exc:
        process_vehicle(late, source)
    assert exc.value.key == "alignment.start"


def test_track_window_end_waits_for_the_distance():
    """``[alignment] min_distance``: the window ends at ``window`` or, later, where the odometry
    has counted the distance (closed form on a car parked 10 s, then 5 m/s); never reached:
    a ConfigError naming the key."""
    from mixnav.experiment.vehicle_process import track_window_end
    from mixnav.motion.dead_reckoning import odometry_increments
    t = np.arange(0.0, 60.0 + 1e-9, 0.1)
    speed = np.where(t <= 10.0, 0.0, 5.0)
    inc = odometry_increments(t, speed, np.zeros_like(t))
    assert track_window_end(inc, 20.0) == pytest.approx(20.0)
    assert track_window_end(inc, 20.0, 40.0) == pytest.approx(20.0)       # 50 m by 20 s
    assert track_window_end(inc, 20.0, 100.0) == pytest.approx(30.0)      # 10 s parked + 100 m at 5 m/s
    with pytest.raises(ConfigError) as exc:
        track_window_end(inc, 20.0, 300.0, "ds.toml")
    assert exc.value.key == "alignment.min_distance" and "250.0 m" in str(exc.value)


def test_min_distance_moves_the_filter_start(tmp_path):
    """On smartLoc from 120 s (the car crawls there: about 68 m in the 20 s window) a 100 m
    track starts the filters later than the 20 s window; a negative distance names the key."""
    data_file("smartloc-berlin", "Berlin_Potsdamer_Platz_Input.txt")
    from mixnav.experiment.vehicle_process import process_vehicle
    text = BASE.format(data=DATA_DIR / "smartloc-berlin") + ('[alignment]\nstart = "120 s"\nmin_distance = "{d}"\n'
                                                            '[[methods]]\nname = "e"\n')
    starts = {}
    for d in ("0 m", "100 m"):
        ds, source, _ = load_dataset(_config(tmp_path, text.format(d=d)))
        starts[d] = process_vehicle(ds, source).init.time
    assert 139.5 < starts["0 m"] < 140.5
    assert starts["100 m"] > starts["0 m"] + 2.0
    with pytest.raises(ConfigError) as exc:
        load_dataset(_config(tmp_path, text.format(d="-5 m")))
    assert exc.value.key.startswith("alignment.min_distance"), exc.value
