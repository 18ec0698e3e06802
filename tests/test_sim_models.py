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


# --------------------------------------------------------------------------
# white noise held per interval (imu.white_noise_hold, P2's epoch-level W_k)
# --------------------------------------------------------------------------
NOISE_ONLY = ImuErrorModel(arw=np.deg2rad(0.2) / 60, vrw=30e-6 * 9.80665)


def _recording(process):
    """A white_noise callable that samples ``process`` and keeps what it drew."""
    drawn = []

    def white(g, times, c):
        x = process.sample(times, c, g)
        drawn.append((np.asarray(times).copy(), x))
        return x
    return white, drawn


def test_without_a_hold_the_noise_is_the_per_sample_one_as_before(static_imu):
    # the per-sample path written out independently: four per-run draws, then one
    # standard normal (n, 3) block for the gyros and one for the accelerometers
    _, ideal = static_imu
    model = ImuErrorModel(gyro_bias=1e-5, accel_bias=1e-3, gyro_scale=1e-3, accel_scale=2e-3,
                          arw=NOISE_ONLY.arw, vrw=NOISE_ONLY.vrw)
    imu, _ = corrupt(ideal, model, np.random.default_rng(7))
    g = np.random.default_rng(7)
    bg, ba, sg, sa = (g.standard_normal(3) * s for s in (1e-5, 1e-3, 1e-3, 2e-3))
    n = len(ideal)
    sdt = np.sqrt(ideal.dt)[:, None]
    ng, na = g.standard_normal((n, 3)), g.standard_normal((n, 3))
    np.testing.assert_array_equal(imu.dtheta, (1 + sg) * ideal.dtheta + bg * ideal.dt[:, None]
                                  + ng * model.arw * sdt)
    np.testing.assert_array_equal(imu.dvel, (1 + sa) * ideal.dvel + ba * ideal.dt[:, None]
                                  + na * model.vrw * sdt)


def _zero_increments(ideal):
    """The static IMU's time grid with zero increments: measured = the injected noise."""
    z = np.zeros_like(ideal.dtheta)
    return type(ideal)(ideal.time, ideal.dt, z, z.copy())


@pytest.mark.parametrize("hold", [1.0, 0.7])   # 0.7 s: 600 s leaves a last interval of 0.1 s
def test_held_noise_is_constant_per_interval_and_integrates_to_the_draw(static_imu, hold):
    from mixnav.ins.imu_model import hold_intervals
    from mixnav.noise.processes import Mixture
    zero = _zero_increments(static_imu[1])
    white, drawn = _recording(Mixture([0.1, 0.9], [0.25, 1.0]))
    imu, _ = corrupt(zero, NOISE_ONLY, np.random.default_rng(3), white_noise=white, hold=hold)
    (t_g, x_g), (t_a, x_a) = drawn
    k, ends, length = hold_intervals(zero, hold)
    n_int = int(np.ceil(600.0 / hold - 1e-9))
    assert len(t_g) == n_int and np.array_equal(t_g, t_a) and np.array_equal(t_g, ends)
    # the process is sampled at the interval ends, on the grid t0 + (k+1) T
    np.testing.assert_allclose(t_g[:-1], hold * np.arange(1, n_int), atol=1e-9)
    assert t_g[-1] == pytest.approx(600.0)
    assert length[:-1] == pytest.approx(hold) and length[-1] == pytest.approx(600.0 - hold * (n_int - 1))
    first = np.searchsorted(k, np.arange(n_int))
    for got, x, s in ((imu.dtheta, x_g, NOISE_ONLY.arw), (imu.dvel, x_a, NOISE_ONLY.vrw)):
        rate = got / zero.dt[:, None]
        # one rate value per interval: every sample equals its interval's first sample
        np.testing.assert_allclose(rate, rate[first][k], rtol=1e-12, atol=0)
        # the noise integrated over interval k is x_k s sqrt(L_k) (L_k = T but the last)
        sums = np.stack([np.bincount(k, weights=got[:, j]) for j in range(3)], axis=1)
        np.testing.assert_allclose(sums, x * s * np.sqrt(length)[:, None], rtol=1e-12, atol=0)


def test_held_gaussian_noise_has_the_variance_of_the_filters_q_per_interval(static_imu):
    # default N(0, 1) multiplier held 1 s: each 1 s sum of angle (velocity) noise has variance
    # ARW^2 T (VRW^2 T). 5 seeds x 600 intervals x 3 axes = 9000 sums: the sd of a
    # variance estimate is sqrt(2 / 9000) = 1.5 %, so 6 % is 4 sd.
    from mixnav.ins.imu_model import hold_intervals
    zero = _zero_increments(static_imu[1])
    k, _, _ = hold_intervals(zero, 1.0)
    sg, sa = [], []
    for seed in range(5):
        imu, _ = corrupt(zero, NOISE_ONLY, np.random.default_rng(seed), hold=1.0)
        for out, d in ((sg, imu.dtheta), (sa, imu.dvel)):
            out.append(np.stack([np.bincount(k, weights=d[:, j]) for j in range(3)], axis=1))
    assert np.var(np.concatenate(sg)) == pytest.approx(NOISE_ONLY.arw ** 2 * 1.0, rel=0.06)
    assert np.var(np.concatenate(sa)) == pytest.approx(NOISE_ONLY.vrw ** 2 * 1.0, rel=0.06)


def test_held_ar1_gives_the_coloured_epoch_noise_of_p2(static_imu):
    # AR(1) coefficient 0.7 with a mixture innovation, held 1 s: the epoch sums of every
    # channel are that AR(1) (P2 eq. 6), so least squares recovers 0.7. Per channel
    # (599 pairs) the standard error is sqrt((1 - 0.49) / 599) = 0.029; the mean over the
    # 6 independent channels has 0.012, and 0.05 is 4 of it. Per-sample draws would give
    # epoch sums that are nearly white (0.7^100 between samples an epoch apart).
    from mixnav.ins.imu_model import hold_intervals
    from mixnav.noise.ar import fit_ar1
    from mixnav.noise.processes import AR1, Mixture
    zero = _zero_increments(static_imu[1])
    proc = AR1(0.7, innovation=Mixture([0.1, 0.9], [0.25, 1.0]))
    k, _, _ = hold_intervals(zero, 1.0)
    psi = {}
    for hold in (1.0, None):
        white = lambda g, times, c: proc.sample(times, c, g)  # noqa: E731
        imu, _ = corrupt(zero, NOISE_ONLY, np.random.default_rng(11), white_noise=white, hold=hold)
        sums = [np.stack([np.bincount(k, weights=d[:, j]) for j in range(3)], axis=1)
                for d in (imu.dtheta, imu.dvel)]
        psi[hold] = fit_ar1(np.concatenate(sums, axis=1)).psi
    assert psi[1.0].mean() == pytest.approx(0.7, abs=0.05)
    # per sample: the epoch sums are white up to O(0.7^100) and edge terms; se 0.017 per mean
    assert abs(psi[None].mean()) < 0.07


@pytest.mark.parametrize("hold", [0.0, -1.0, 0.015, 0.0101, 601.0, float("nan")])
def test_bad_hold_is_refused(static_imu, hold):
    from mixnav.errors import ConfigError
    _, ideal = static_imu
    with pytest.raises(ConfigError, match="white_noise_hold"):
        corrupt(ideal, NOISE_ONLY, np.random.default_rng(0), hold=hold)
