"""The notebook API gives what the command and the classes give, and names bad arguments."""

import json
from dataclasses import replace

import numpy as np
import pytest

import mixnav
from mixnav.config import load_scenario
from mixnav.errors import ArgumentError, DataError
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate


@pytest.fixture(scope="module")
def demo():
    sc, src, _ = load_scenario("loose-demo")
    return sc, simulate(sc, 4, src)


def test_run_scenario_metrics_are_those_of_the_command(tmp_path):
    run = mixnav.run_scenario("tdcp-demo", seed=2)
    written = run.write(tmp_path)
    on_disk = json.loads((tmp_path / "metrics.json").read_text())["methods"]
    assert set(run.metrics.index) == set(on_disk) == set(written["methods"])
    for name, m in on_disk.items():
        for key in ("horizontal_rmse_m", "vertical_max_m", "nees_pos_mean", "nis_mean_per_dof"):
            assert run.metrics.loc[name, key] == pytest.approx(m[key], rel=1e-12), (name, key)
    assert set(run.solutions) == set(on_disk) and "err_n_m" in run.solutions["tdcp"]


def test_filter_loose_is_the_filter_called_directly(demo):
    sc, sim = demo
    res = mixnav.filter_loose(sim.imu, sim.fixes, sim.init, imu_model=sim.imu_model, lever_arm=sc.gnss.lever_arm)
    lay = get_layout(15)
    direct = ErrorStateEkf(lay, sim.imu_model).run(sim.imu, sim.init,
                                                   [LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm), lay)])
    np.testing.assert_array_equal(res.result.nav, direct.nav)
    np.testing.assert_array_equal(res.table["lat_deg"], np.degrees(direct.nav[:, 7]))


def test_bad_inputs_name_the_argument(demo):
    sc, sim = demo
    ok = dict(imu_model=sim.imu_model, lever_arm=sc.gnss.lever_arm)
    with pytest.raises(ArgumentError) as e:
        mixnav.filter_loose(sim.imu, sim.fixes, sim.init, imu_model=sim.imu_model, lever_arm=[1.0, 2.0])
    assert e.value.argument == "lever_arm"
    with pytest.raises(ArgumentError) as e:
        mixnav.filter_loose(sim.imu, sim.fixes, sim.init, imu_model="mems", lever_arm=sc.gnss.lever_arm)
    assert e.value.argument == "imu_model"
    late = replace(sim.fixes, time=sim.fixes.time + 1e5)
    with pytest.raises(ArgumentError) as e:
        mixnav.filter_loose(sim.imu, late, sim.init, **ok)
    assert e.value.argument == "fixes"
    with pytest.raises(ArgumentError, match="unknown estimator"):
        mixnav.filter_loose(sim.imu, sim.fixes, sim.init, estimator="kalman", **ok)
    with pytest.raises(DataError, match="radians"):
        replace(sim.fixes, lla=np.degrees(sim.fixes.lla))
    with pytest.raises(DataError, match="increase strictly: sample 5"):
        t = sim.imu.time.copy()
        t[5] = t[4]
        replace(sim.imu, time=t)
    with pytest.raises(DataError, match="radians"):
        nav = sim.init.nav.copy()
        nav[7] = 34.4  # degrees
        replace(sim.init, nav=nav)
    with pytest.raises(ArgumentError, match="unknown IMU grade"):
        mixnav.imu_grade("consumer")
