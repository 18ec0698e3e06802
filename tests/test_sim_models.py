"""IMU error injection, GNSS fix simulation and the clock block: seeded statistics and closed forms."""

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.geodesy.frames import ned_displacement
from mixnav.ins._error_kernels import discretize, error_dynamics
from mixnav.ins.error_model import ClockModel, get_layout, process_noise
from mixnav.ins.imu_model import GRADES, ImuErrorModel, corrupt
from mixnav.measurements.loose import antenna_lla
from mixnav.sim.gnss import GnssFixModel, simulate_fixes
from mixnav.sim.scenario import truth_and_ideal_imu
from mixnav.sim.trajectory import InitialState, MotionSegment, generate


@pytest.fixture(scope="module")
def static_imu():
    return generate([MotionSegment("static", 600.0)], InitialState((0.6, 2.0, 0.0), 0.0, (0, 0, 0)), 100.0)


def test_white_noise_and_scale_factor(static_imu):
    truth, ideal = static_imu
    model = ImuErrorModel(arw=np.deg2rad(0.3) / 60, vrw=100e-6 * 9.80665, gyro_scale=0.01, accel_scale=0.01)
    imu, draw = corrupt(ideal, model, np.random.default_rng(1))
    dt = 0.01
    # the noise increments have variance ARW^2 dt (60 000 samples: 1 % sd of a
    # variance estimate is 0.6 %, so 3 % is 5 sd)
    noise_g = imu.dtheta - (1 + draw.gyro_scale) * ideal.dtheta
    noise_a = imu.dvel - (1 + draw.accel_scale) * ideal.dvel
    np.testing.assert_allclose(noise_g.var(0), model.arw ** 2 * dt, rtol=0.03)
    np.testing.assert_allclose(noise_a.var(0), model.vrw ** 2 * dt, rtol=0.03)
    assert np.all(draw.gyro_scale != 0)


def test_turn_on_bias_is_drawn_per_run_with_its_sigma(static_imu):
    truth, ideal = static_imu
    short = type(ideal)(ideal.time[:10], ideal.dt[:10], ideal.dtheta[:10], ideal.dvel[:10])
    model = ImuErrorModel.from_datasheet({}, grade="tactical")
    draws = np.array([corrupt(short, model, np.random.default_rng(s))[1].gyro_bias for s in range(2000)])
    # sd of a standard-deviation estimate from 6000 draws: 0.9 %; allow 4 %
    assert draws.std() == pytest.approx(model.gyro_bias, rel=0.04)
    assert abs(draws.mean()) < 4 * model.gyro_bias / np.sqrt(draws.size)


def test_gauss_markov_bias_has_its_steady_state_sigma(static_imu):
    truth, ideal = static_imu
    model = ImuErrorModel(gyro_bias_instability=1e-4, gyro_bias_tau=10.0)
    vals = []
    for s in range(40):
        imu, _ = corrupt(ideal, model, np.random.default_rng(s))
        bias = (imu.dtheta - ideal.dtheta) / ideal.dt[:, None]
        vals.append(bias[::2000])  # samples 20 s apart: nearly independent (tau 10 s)
    vals = np.concatenate(vals)
    assert vals.std() == pytest.approx(1e-4, rel=0.06)  # ~3600 samples: sd 1.2 %


def test_grades_parse():
    for grade in GRADES:
        m = ImuErrorModel.from_datasheet({}, grade=grade)
        assert m.arw > 0 and m.gyro_bias > 0 and m.vrw > 0


def test_fixes_hold_lever_arm_noise_and_outages():
    sc, src, _ = load_scenario("loose-demo")
    truth, _ = truth_and_ideal_imu(sc, src)
    lever = np.array([0.5, 0.2, -1.0])
    model = GnssFixModel(rate=1.0, pos_sigma=np.array([1.5, 1.5, 3.0]), vel_sigma=np.array([0.05, 0.05, 0.1]),
                         lever_arm=lever, outages=((300.0, 360.0),))
    fixes = simulate_fixes(truth, model, np.random.default_rng(2))
    assert not np.any((fixes.time >= 300) & (fixes.time < 360))
    assert len(fixes) == 600 - 60
    k = np.searchsorted(truth.time, fixes.time)
    ant = np.array([antenna_lla(np.concatenate([truth.q_nb[i], truth.v_n[i], truth.lla[i]]), lever) for i in k])
    d = ned_displacement(fixes.lla, ant)
    # noise about the antenna (not the IMU) with the configured sigma:
    # 540 samples, sd of a sd estimate 3 %; allow 15 %
    np.testing.assert_allclose(d.std(0), [1.5, 1.5, 3.0], rtol=0.15)
    assert np.all(np.abs(d.mean(0)) < 4 * np.array([1.5, 1.5, 3.0]) / np.sqrt(540))


def test_clock_block_of_phi_and_q_is_the_two_state_closed_form():
    lay = get_layout(17)
    clock = ClockModel(q_bias=0.2, q_drift=0.05)
    qc, tau, _ = process_noise(lay, ImuErrorModel(), clock)
    F = np.empty((17, 17))
    nav = np.array([1.0, 0, 0, 0, 10.0, 0, 0, 0.6, 2.0, 0.0])
    error_dynamics(F, nav, np.array([0, 0, -9.8]), np.zeros(3), np.zeros(3), np.eye(3), lay.as_array(), tau)
    phi, qd, tmp = np.empty((3, 17, 17))
    T = 0.8
    discretize(F, qc, T, phi, qd, tmp)
    c = lay.clk
    np.testing.assert_allclose(phi[c:c + 2, c:c + 2], [[1, T], [0, 1]], atol=1e-15)
    qb, qdr = clock.q_bias, clock.q_drift
    np.testing.assert_allclose(qd[c:c + 2, c:c + 2],
                               [[qb * T + qdr * T ** 3 / 3, qdr * T ** 2 / 2], [qdr * T ** 2 / 2, qdr * T]],
                               rtol=1e-12)
