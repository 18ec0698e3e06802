"""Sage-Husa adaptive EKF (one new estimator file on the engine): it learns the
level of a mis-stated measurement noise and leaves a right one alone."""

from dataclasses import replace

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.errors import ArgumentError
from mixnav.experiment.run import solution_table
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.filters.sage_husa import SageHusaEkf
from mixnav.ins.error_model import get_layout
from mixnav.measurements.kinds import POSITION, VELOCITY
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate


@pytest.fixture(scope="module")
def demo():
    sc, src, _ = load_scenario("loose-demo")
    return sc, simulate(sc, 3, src)


def _run(filt, sim, fixes, lever):
    return filt.run(sim.imu, sim.init, [LooseGnss(fixes, lever, filt.layout)])


def _final_scale(res, code):
    o = res.outputs
    return o["sage_husa_scale"][o["sage_husa_kind"] == code][-1]


def test_a_right_noise_keeps_its_scale_near_one(demo):
    sc, sim = demo
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    res = _run(SageHusaEkf(get_layout(15), sim.imu_model, fading=0.99), sim, sim.fixes, lever)
    # The residual form is unbiased for a filter whose R is right: E[u] = 1. With a
    # memory of 1 / (1 - b) = 100 epochs of 3 rows the scale's standard error is
    # about sqrt(2 / 300) = 0.08 per kind; 0.3 is beyond 3.5 of those.
    for code in (POSITION, VELOCITY):
        assert abs(_final_scale(res, code) - 1.0) < 0.3, code
    ekf = _run(ErrorStateEkf(get_layout(15), sim.imu_model), sim, sim.fixes, lever)
    # Then it is as good as the EKF: horizontal RMSE against the truth within 10 %.
    h = [np.sqrt(np.mean(solution_table(r, sim.truth)[["err_n_m", "err_e_m"]].to_numpy() ** 2) * 2)
         for r in (res, ekf)]
    assert abs(h[0] / h[1] - 1.0) < 0.1, h


def test_a_noise_stated_three_times_too_small_is_learned(demo):
    sc, sim = demo
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    f = sim.fixes
    told = replace(f, pos_sigma=f.pos_sigma / 3.0)  # the real noise is 3x what the fixes say
    res = _run(SageHusaEkf(get_layout(15), sim.imu_model, fading=0.99), sim, told, lever)
    ekf = _run(ErrorStateEkf(get_layout(15), sim.imu_model), sim, told, lever)
    # Position variance scale learned: 9 (3^2) within 25 % (standard error about 8 %
    # with 100 epochs of memory, plus the transient of the filter's own errors).
    s = _final_scale(res, POSITION)
    assert 9.0 * 0.75 < s < 9.0 * 1.25, s
    # and the filter is consistent again where the EKF is not: NIS per dof.
    nis_sh = np.mean(res.nis[100:] / res.nis_dim[100:])
    nis_ekf = np.mean(ekf.nis[100:] / ekf.nis_dim[100:])
    assert abs(nis_sh - 1.0) < 0.3 and nis_ekf > 2.0, (nis_sh, nis_ekf)
    assert res.timing["sage_husa_scale_position"] == pytest.approx(s)


def test_bad_settings_name_the_argument(demo):
    _, sim = demo
    with pytest.raises(ArgumentError, match="fading"):
        SageHusaEkf(get_layout(15), sim.imu_model, fading=1.0)
    with pytest.raises(ArgumentError, match="scale0"):
        SageHusaEkf(get_layout(15), sim.imu_model, scale0=0.0)
