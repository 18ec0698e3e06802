"""The IMM estimator (M9, P4 eqs. 6-16): closed-form mixing, reductions to one filter,
the likelihood of the same rows under every mode, and argument errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from mixnav.engine import Engine
from mixnav.errors import ArgumentError, ConfigError
from mixnav.filters.ekf import KalmanEstimator
from mixnav.filters.imm import ImmEstimator, combine, log_likelihood, mix
from mixnav.markov import check_transition
from mixnav.ins.error_model import get_layout
from mixnav.ins.strapdown import StrapdownMotion
from mixnav.measurements.loose import LooseGnss
from mixnav.measurements.vehicle import NonHolonomic


@pytest.fixture(scope="module")
def loose():
    from mixnav.config.loader import load_scenario
    from mixnav.sim.scenario import simulate
    sc, src, _ = load_scenario("loose-demo")
    return sc, simulate(sc, 2, src)


def _random_modes(rng, r=3, n=5):
    mu = rng.dirichlet(np.ones(r))
    Pi = rng.dirichlet(np.ones(r), size=r)
    xs = rng.normal(size=(r, n))
    A = rng.normal(size=(r, n, n))
    Ps = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(n)
    return mu, Pi, xs, Ps


def test_mixing_preserves_the_combined_mean_and_covariance():
    """Mixing redistributes the mixture without changing it: with c = mu Pi the mixed
    modes combined with weights c have the mean and covariance of the modes combined with
    mu (the law of total expectation and variance over the previous mode)."""
    rng = np.random.default_rng(1)
    for _ in range(5):
        mu, Pi, xs, Ps = _random_modes(rng)
        c, x0, P0 = mix(mu, Pi, xs, Ps)
        np.testing.assert_allclose(c, mu @ Pi)
        np.testing.assert_allclose(c.sum(), 1.0)
        x_a, P_a = combine(mu, xs, Ps)
        x_b, P_b = combine(c, x0, P0)
        np.testing.assert_allclose(x_b, x_a, atol=1e-12)
        np.testing.assert_allclose(P_b, P_a, atol=1e-12)
        # and each mixed mode is the mixture of the previous modes with weights mu_{i|j}
        w = Pi[:, 0] * mu / c[0]
        np.testing.assert_allclose(combine(w, xs, Ps)[0], x0[0])
        np.testing.assert_allclose(combine(w, xs, Ps)[1], P0[0])


def test_compiled_cycle_is_the_numpy_reference():
    """The compiled mixing-and-scoring kernel equals mix() and log_likelihood() (the readable
    reference), including a mode that cannot be entered (its column of Pi zero)."""
    from mixnav.filters._imm_kernels import imm_combine, imm_mix_score
    rng = np.random.default_rng(4)
    for zero_col in (False, True):
        mu, Pi, xs, Ps = _random_modes(rng, r=3, n=7)
        if zero_col:
            Pi[:, 2] = 0.0
            Pi /= Pi.sum(1, keepdims=True)
        H = rng.normal(size=(4, 7))
        R = np.diag(rng.uniform(0.5, 2, 4))
        z = rng.normal(size=4)
        x0, P0, logl = np.empty((3, 7)), np.empty((3, 7, 7)), np.empty(3)
        c = imm_mix_score(mu, Pi, xs, Ps, z, H, R, x0, P0, logl)
        c_ref, x0_ref, P0_ref = mix(mu, Pi, xs, Ps)
        np.testing.assert_allclose(c, c_ref, atol=1e-14)
        np.testing.assert_allclose(x0, x0_ref, atol=1e-12)
        np.testing.assert_allclose(P0, P0_ref, atol=1e-12)
        np.testing.assert_allclose(logl, [log_likelihood(x0[j], P0[j], z, H, R) for j in range(3)], rtol=1e-12)
        P = np.empty((7, 7))
        x = imm_combine(mu, xs, Ps, P)
        np.testing.assert_allclose(x, combine(mu, xs, Ps)[0], atol=1e-12)
        np.testing.assert_allclose(P, combine(mu, xs, Ps)[1], atol=1e-12)


def test_log_likelihood_is_scipys_gaussian_density():
    rng = np.random.default_rng(2)
    n, m = 6, 3
    x = rng.normal(size=n)
    A = rng.normal(size=(n, n))
    P = A @ A.T + np.eye(n)
    H = rng.normal(size=(m, n))
    R = rng.uniform(0.5, 2.0, m)
    z = rng.normal(size=m)
    ref = multivariate_normal(H @ x, H @ P @ H.T + np.diag(R)).logpdf(z)
    assert log_likelihood(x, P, z, H, R) == pytest.approx(ref, rel=1e-12)
    assert log_likelihood(x, P, z, H, np.diag(R)) == pytest.approx(ref, rel=1e-12)


def _gnss_engine(sim, sc, estimator, extra=()):
    lay = get_layout(15)
    gnss = LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)
    motion = StrapdownMotion(lay, sim.imu_model)
    return Engine(motion, estimator, [gnss, *extra]), gnss, lay


@pytest.mark.parametrize("Pi", [[[0.5, 0.5], [0.5, 0.5]], [[0.9, 0.1], [0.3, 0.7]]])
def test_identical_modes_are_the_single_filter(loose, Pi):
    """Two identical modes (same estimator, same measurement set): whatever the transition
    matrix, the IMM is the EKF (mixing identical Gaussians gives them back)."""
    sc, sim = loose
    ekf = _gnss_engine(sim, sc, KalmanEstimator())[0].run(sim.imu, sim.init)
    lay = get_layout(15)
    gnss = LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)
    imm = ImmEstimator([KalmanEstimator(carry_mean=True), KalmanEstimator(carry_mean=True)], [{gnss}, {gnss}], Pi,
                       initial_probabilities=[0.3, 0.7], transition_interval=None)
    res = Engine(StrapdownMotion(lay, sim.imu_model), imm, [gnss]).run(sim.imu, sim.init)
    np.testing.assert_allclose(res.nav, ekf.nav, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.sigma, ekf.sigma, rtol=1e-9)
    p = res.outputs["mode_probabilities"]
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-12)


class _Deaf(ImmEstimator):
    """An IMM whose second mode's likelihood is forced to zero."""

    def weigh(self, logl):
        logl[1] = -np.inf
        return logl


def test_a_mode_with_zero_likelihood_leaves_the_other_filter(loose):
    """Mode 0 uses the GNSS, mode 1 the GNSS and NHC (at the GNSS times, so the IMU is split
    at the same instants as the EKF's). With mode 1's likelihood forced to zero its
    probability is zero after the first epoch, mode 0 never mixes it in, and the IMM is the
    GNSS-only EKF; mode 1 still runs (its own updates, re-started from mode 0)."""
    sc, sim = loose
    ekf = _gnss_engine(sim, sc, KalmanEstimator())[0].run(sim.imu, sim.init)
    lay = get_layout(15)
    gnss = LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)
    nhc = NonHolonomic(sim.fixes.time, lay, sigma=0.3)
    imm = _Deaf([KalmanEstimator(carry_mean=True), KalmanEstimator(carry_mean=True)], [{gnss}, {gnss, nhc}],
                [[0.95, 0.05], [0.05, 0.95]])
    res = Engine(StrapdownMotion(lay, sim.imu_model), imm, [gnss, nhc]).run(sim.imu, sim.init)
    np.testing.assert_allclose(res.nav, ekf.nav, rtol=0, atol=1e-9)
    p = res.outputs["mode_probabilities"]
    assert np.all(p[:, 1] == 0.0) and np.all(p[:, 0] == 1.0)
    # the modes did differ: mode 1 took NHC updates
    assert np.abs(imm.children[1].P - imm.children[0].P).max() > 1e-6


def test_transition_matrix_and_sets_are_checked():
    with pytest.raises(ArgumentError, match="row 1 sums to"):
        check_transition([[0.9, 0.1], [0.2, 0.7]])
    with pytest.raises(ArgumentError, match=r"entry \[0\]\[1\] is negative"):
        check_transition([[1.1, -0.1], [0.2, 0.8]])
    with pytest.raises(ArgumentError, match="shape"):
        check_transition([[1.0, 0.0]])
    k = KalmanEstimator(carry_mean=True)
    with pytest.raises(ArgumentError, match="mode 1 has no measurements"):
        ImmEstimator([k, KalmanEstimator(carry_mean=True)], [{object()}, set()], np.eye(2))
    with pytest.raises(ArgumentError, match="does not carry its own mean"):
        ImmEstimator([KalmanEstimator(), k], [{1}, {2}], np.eye(2))
    with pytest.raises(ArgumentError, match="eigenvalues"):   # anti-sticky: no fractional power
        ImmEstimator([k, KalmanEstimator(carry_mean=True)], [{1}, {2}], [[0.2, 0.8], [0.8, 0.2]])
    ImmEstimator([k, KalmanEstimator(carry_mean=True)], [{1}, {2}], [[0.2, 0.8], [0.8, 0.2]],
                 transition_interval=None)


def test_fractional_transition_is_the_one_second_matrix_over_time():
    """Applied per time, Pi^(0.5) twice is Pi (10 epochs of 0.1 s make one second's switching)."""
    from mixnav.filters.imm import _FractionalPower
    Pi = np.array([[0.99, 0.01], [0.05, 0.95]])
    pw = _FractionalPower(Pi, "transition")
    np.testing.assert_allclose(pw(0.5) @ pw(0.5), Pi, atol=1e-12)
    np.testing.assert_allclose(np.linalg.matrix_power(pw(0.1), 10), Pi, atol=1e-12)
    np.testing.assert_allclose(pw(0.0), np.eye(2), atol=1e-12)


IMM_METHOD = '''
[[methods]]
name = "imm"
type = "loose-ekf"
states = 21
covariance_interval = "1 s"
estimator = "imm"
aiding = ["nhc", "odometer"]
estimate = ["odometer_scale"]
[methods.imm]
transition = [[0.98, 0.02], [0.05, 0.95]]
[[methods.imm.modes]]
name = "gnss"
measurements = ["gnss", "nhc", "odometer"]
[[methods.imm.modes]]
name = "dead-reckoning"
measurements = ["nhc", "odometer"]
'''


def _vehicle_demo_with(tmp_path, method_text, keep_methods=False):
    from mixnav.config.loader import load_scenario
    _, _, text = load_scenario("vehicle-demo")
    if not keep_methods:
        head, _, rest = text.partition("[[methods]]")
        aiding = rest[rest.index("[aiding]"):rest.index("[[methods]]", rest.index("[aiding]"))]
        text = head + aiding
    p = tmp_path / "imm.toml"
    p.write_text(text + method_text)
    return p


def test_imm_from_a_scenario_file(tmp_path):
    """vehicle-demo with an IMM of "GNSS + NHC + odometer" and "NHC + odometer" modes: the
    probabilities are outputs (columns, metrics, figure) and sum to one; in the outages no
    epoch tells the modes apart (both use NHC and the odometer), so they relax to the
    stationary distribution of the transition matrix (0.02 / 0.07 = 0.286 for the second
    mode: 0.28-0.29 measured after 60 s); the IMM keeps the aided filters' accuracy in the
    outages (1.9 m against the GNSS-only EKF's 16.7 m: asserted below a third of it)."""
    from mixnav.api import run_scenario
    p = _vehicle_demo_with(tmp_path, IMM_METHOD, keep_methods=True)
    r = run_scenario(str(p))
    t = r.solutions["imm"]
    cols = ["p_mode_gnss", "p_mode_dead-reckoning"]
    np.testing.assert_allclose(t[cols].sum(axis=1), 1.0, atol=1e-12)
    end_of_outage = t[(t.time_s > 325) & (t.time_s < 330)]
    np.testing.assert_allclose(end_of_outage["p_mode_dead-reckoning"], 0.02 / 0.07, atol=0.01)
    assert t.loc[~t.in_outage, "p_mode_gnss"].mean() > 0.7
    assert r.metrics.loc["imm", "horizontal_max_m"] < r.metrics.loc["ekf", "horizontal_max_m"] / 3
    m = r.write(tmp_path / "out")
    assert set(m["methods"]["imm"]["mode_probability_mean"]) == {"gnss", "dead-reckoning"}
    from mixnav.experiment.metrics import METRIC_KEYS_DOC
    assert set(m["methods"]["imm"]) - {"outages"} <= set(METRIC_KEYS_DOC)      # every key documented
    assert (tmp_path / "out" / "mode_probabilities.png").exists()


@pytest.mark.parametrize("change, key, message", [
    ("transition = [[0.98, 0.02], [0.05, 0.9]]", "methods[0].imm.transition", "row 1 sums to"),
    ("transition = [[1.02, -0.02], [0.05, 0.95]]", "methods[0].imm.transition", "negative"),
    ("transition = [[1.0]]", "methods[0].imm", "2 x 2"),
    ('measurements = ["nhc", "odometer"]\n', "methods[0].imm.modes[1].measurements", None),
])
def test_imm_config_errors_name_the_key(tmp_path, change, key, message):
    from mixnav.config.loader import load_scenario
    text = IMM_METHOD
    if change.startswith("transition"):
        text = text.replace("transition = [[0.98, 0.02], [0.05, 0.95]]", change)
    else:   # the second mode with no measurements
        text = text[::-1].replace(change[::-1], "measurements = []\n"[::-1], 1)[::-1]
    p = _vehicle_demo_with(tmp_path, text)
    with pytest.raises(ConfigError) as e:
        load_scenario(str(p))
    assert e.value.key.startswith(key), (e.value.key, str(e.value))
    if message:
        assert message in str(e.value)


def test_imm_mode_must_use_the_methods_aiding(tmp_path):
    from mixnav.config.loader import load_scenario
    p = _vehicle_demo_with(tmp_path, IMM_METHOD.replace('aiding = ["nhc", "odometer"]', 'aiding = ["nhc"]'))
    with pytest.raises(ConfigError, match="odometer"):
        load_scenario(str(p))


def test_em_imm_mode_from_config(tmp_path):
    """An "em-bias" mode reads its [em] table; its bias is an output (solution columns
    bias_n/e/d_m); a window with fewer samples than the two components, or an [em] table
    on a plain mode, is a ConfigError naming the key."""
    from mixnav.api import run_scenario
    from mixnav.config.loader import load_scenario
    em = IMM_METHOD.replace('name = "gnss"\nmeasurements = ["gnss", "nhc", "odometer"]',
                            'name = "gnss"\nmeasurements = ["gnss", "nhc", "odometer"]\nestimator = "em-bias"\n'
                            '[methods.imm.modes.em]\nwindow = "30 s"\nmin_samples = 10\nmin_separation = "4 m"')
    r = run_scenario(str(_vehicle_demo_with(tmp_path, em)))
    t = r.solutions["imm"]
    assert {"bias_n_m", "bias_e_m", "bias_d_m", "p_mode_gnss"} <= set(t.columns)
    imm = r.results["imm"]
    assert len(imm.outputs["bias_times"]) == int((imm.outputs["bias_times"] > 0).sum()) > 100
    bad = em.replace("min_samples = 10", "min_samples = 1")
    with pytest.raises(ConfigError) as e:
        load_scenario(str(_vehicle_demo_with(tmp_path, bad)))
    assert e.value.key == "methods[0].imm.modes[0].em.min_samples", e.value.key
    bad = em.replace('estimator = "em-bias"\n', "")
    with pytest.raises(ConfigError, match=r"\[em\] table needs"):
        load_scenario(str(_vehicle_demo_with(tmp_path, bad)))


def test_mode_probabilities_follow_a_simulated_switch():
    """vehicle-demo with the GNSS noise switched from 1.5 m to 15 m between 440 and 540 s: the
    IMM of "GNSS + NHC + odometer" and "NHC + odometer" moves its probability to the second
    mode inside the window and back after it (measured mean 0.18 before, 0.76 inside from
    460 s, 0.14 after; asserted: inside at least 0.5 and three times before and after)."""
    from dataclasses import replace
    from mixnav.config.loader import load_scenario
    from mixnav.geodesy.frames import displace
    from mixnav.ins.error_model import StateLayout
    from mixnav.measurements.vehicle import Odometer
    from mixnav.sim.scenario import simulate
    sc, src, _ = load_scenario("vehicle-demo")
    sim = simulate(sc, 1, src)
    fx = sim.fixes
    bad = (fx.time >= 440) & (fx.time <= 540)
    off = np.zeros((len(fx.time), 3))
    off[bad] = np.random.default_rng(5).normal(0, 15, (bad.sum(), 3))
    lay = StateLayout("v", ["gyro_scale", "accel_scale"])
    mnt = np.asarray(sc.installation.imu_misalignment, float)
    gnss = LooseGnss(replace(fx, lla=displace(fx.lla, off)), np.asarray(sc.gnss.lever_arm, float), lay)
    nhc = NonHolonomic(np.arange(sim.init.time + 1, sim.imu.time[-1], 1.0), lay, mnt, sigma=(0.2, 0.1))
    odo = Odometer(sim.odometer, lay, mnt, np.asarray(sc.odometer.lever_arm, float), scale=0.005)
    imm = ImmEstimator([KalmanEstimator(carry_mean=True), KalmanEstimator(carry_mean=True)],
                       [{gnss, nhc, odo}, {nhc, odo}], [[0.98, 0.02], [0.05, 0.95]], names=["gnss", "dr"])
    res = Engine(StrapdownMotion(lay, sim.imu_model), imm, [gnss, nhc, odo]).run(sim.imu, sim.init)
    t, p = res.outputs["mode_times"], res.outputs["mode_probabilities"]
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-12)
    mean = lambda a, b: p[(t >= a) & (t < b), 1].mean()   # noqa: E731
    before, inside, after = mean(100, 430), mean(460, 540), mean(550, 600)
    assert inside > 0.5 and inside > 3 * before and inside > 3 * after, (before, inside, after)


def _hand_epoch():
    """One position fix of two rows, (0.8, -0.3) with variance 0.25 each on the position
    states 6, 7, as a measurement model: ``(fix, H, z, epoch)``, the Epoch at t = 1 s."""
    from mixnav.engine.protocols import Epoch
    from mixnav.measurements.base import MeasurementModel, Rows
    H = np.zeros((2, 15))
    H[0, 6], H[1, 7] = 1.0, 1.0
    z = np.array([0.8, -0.3])

    class Fix(MeasurementModel):
        kinds = ("position",)
        times = np.array([1.0])

        def rows(self, i, nav, w_b, clock=None, memory=None, aux=None):
            return Rows(z, H, np.array([0.25, 0.25]), np.array([0, 0]))

    fix = Fix()
    nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.7, 0.2, 100.0])
    return fix, H, z, Epoch(1.0, 0, fix, nav, np.zeros(3), np.zeros(2), None)


def _init_15(imm):
    from mixnav.ins.imu_model import ImuErrorModel
    imm.init(StrapdownMotion(get_layout(15), ImuErrorModel()), np.eye(15), 0, np.random.default_rng(0))


def test_every_mode_scores_the_same_rows():
    """One epoch by hand: mode 0 uses the model, mode 1 does not. Both are scored on the same
    rows with their own predictive density (scipy's), the probabilities follow P4 eq. 14
    with them, only mode 0 is updated, and the correction is the combined mean."""
    fix, H, z, epoch = _hand_epoch()
    a, b = KalmanEstimator(carry_mean=True), KalmanEstimator(carry_mean=True)
    imm = ImmEstimator([a, b], [{fix}, {object()}], np.eye(2), initial_probabilities=[0.6, 0.4],
                       transition_interval=None)
    _init_15(imm)
    b.P = 4.0 * np.eye(15)                       # mode 1 is less sure
    b.x = np.zeros(15)
    b.x[6] = 0.5
    corr = imm.update(epoch)
    xb = np.zeros(15)
    xb[6] = 0.5
    like = [multivariate_normal(H @ x, H @ P @ H.T + 0.25 * np.eye(2)).pdf(z)
            for x, P in ((np.zeros(15), np.eye(15)), (xb, 4.0 * np.eye(15)))]
    mu = np.array([0.6 * like[0], 0.4 * like[1]])
    mu /= mu.sum()
    np.testing.assert_allclose(imm.mu, mu, rtol=1e-10)
    # mode 0 updated (its P shrank on the observed axes), mode 1 not
    assert a.P[6, 6] < 1.0 and b.P[6, 6] == 4.0
    # the correction is the combined mean, and every mode is re-centred on it
    x0_post = np.zeros(15)
    x0_post[6], x0_post[7] = 0.8 / 1.25, -0.3 / 1.25
    np.testing.assert_allclose(corr.dx, mu[0] * x0_post + mu[1] * xb, atol=1e-12)
    np.testing.assert_allclose(mu[0] * a.x + mu[1] * b.x, 0.0, atol=1e-12)


MIXTURE_MODE = '''
[[methods.imm.modes]]
name = "multipath"
measurements = ["gnss", "nhc", "odometer"]
estimator = "gaussian-mixture"
[methods.imm.modes.mixture]
max_components = 4
[methods.imm.modes.mixture.measurement.position]
weights = [0.9, 0.05, 0.05]
means = [0.0, 10.0, -10.0]
scales = [1.0, 4.0, 4.0]
'''


def test_mixture_mode_from_a_scenario_file(tmp_path):
    """A third mode, a bank with a multipath position tail, from the scenario file: it runs,
    its probability is an output column, the three probabilities sum to one, and on
    Gaussian GNSS noise it is less probable than the Gaussian GNSS mode; a [mixture]
    table on a plain mode, or a coloured one, is a ConfigError naming the mode."""
    from mixnav.api import run_scenario
    from mixnav.config.loader import load_scenario
    text = IMM_METHOD.replace("transition = [[0.98, 0.02], [0.05, 0.95]]",
                              "transition = [[0.96, 0.02, 0.02], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]]")
    r = run_scenario(str(_vehicle_demo_with(tmp_path, text + MIXTURE_MODE)))
    t = r.solutions["imm"]
    cols = ["p_mode_gnss", "p_mode_dead-reckoning", "p_mode_multipath"]
    np.testing.assert_allclose(t[cols].sum(axis=1), 1.0, atol=1e-12)
    # vehicle-demo's GNSS noise is Gaussian: the multipath tail costs the bank likelihood
    assert t.loc[~t.in_outage, "p_mode_multipath"].mean() < t.loc[~t.in_outage, "p_mode_gnss"].mean()
    bad = text + MIXTURE_MODE.replace('estimator = "gaussian-mixture"\n', "")
    with pytest.raises(ConfigError, match=r"\[mixture\] table needs") as e:
        load_scenario(str(_vehicle_demo_with(tmp_path, bad)))
    assert e.value.key.startswith("methods[0].imm.modes[2]"), e.value.key
    bad = text + MIXTURE_MODE + "[methods.imm.modes.mixture.colored]\nprocess = 0.5\n"
    with pytest.raises(ConfigError, match="coloured"):
        load_scenario(str(_vehicle_demo_with(tmp_path, bad)))


class _SlowKalman(KalmanEstimator):
    """A Kalman mode the IMM does not recognise as plain: it takes the general path."""


@pytest.mark.parametrize("absurd", [1e4, 2.0])
def test_compiled_epoch_is_the_general_path(loose, absurd):
    """The fast path for plain Kalman modes (modes stacked, one compiled call per epoch and
    one per prediction) gives the general path's numbers: modes with different sets (GNSS;
    GNSS + NHC at 10 Hz), a non-trivial transition, and with a 2-sigma gate also the
    rejections (counted the same)."""
    sc, sim = loose
    lay = get_layout(15)
    runs = []
    for cls in (KalmanEstimator, _SlowKalman):
        gnss = LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)
        nhc = NonHolonomic(np.arange(sim.init.time + 0.1, sim.imu.time[-1], 0.1), lay, sigma=0.3)
        imm = ImmEstimator([KalmanEstimator(absurd, carry_mean=True), cls(absurd, carry_mean=True)],
                           [{gnss}, {gnss, nhc}], [[0.9, 0.1], [0.2, 0.8]])
        runs.append(Engine(StrapdownMotion(lay, sim.imu_model), imm, [gnss, nhc]).run(sim.imu, sim.init))
        assert imm._fast == (cls is KalmanEstimator)
    fast, slow = runs
    np.testing.assert_allclose(fast.nav, slow.nav, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.sigma, slow.sigma, rtol=1e-9)
    np.testing.assert_allclose(fast.outputs["mode_probabilities"], slow.outputs["mode_probabilities"], atol=1e-10)
    assert fast.recoveries == slow.recoveries
    if absurd == 2.0:
        assert fast.recoveries["rejected_absurd"] > 0


@pytest.mark.parametrize("cls", [KalmanEstimator, _SlowKalman])
def test_most_probable_output_feeds_back_the_likeliest_mode(cls):
    """output = "most-probable": the correction is the likeliest mode's posterior mean (not
    the combination), that mode ends at zero after re-centring, and the recorded covariance
    is its own; on both the compiled and the general path."""
    fix, H, z, epoch = _hand_epoch()
    a, b = cls(carry_mean=True), cls(carry_mean=True)
    imm = ImmEstimator([a, b], [{fix}, {object()}], np.eye(2), initial_probabilities=[0.3, 0.7],
                       transition_interval=None, output="most-probable")
    _init_15(imm)
    b.P = 4.0 * np.eye(15)
    b.x = np.zeros(15)
    b.x[6] = 3.0                                  # mode 1 far from the fix: mode 0 wins
    corr = imm.update(epoch)
    assert imm.mu[0] > imm.mu[1]
    x0_post = np.zeros(15)
    x0_post[6], x0_post[7] = 0.8 / 1.25, -0.3 / 1.25
    np.testing.assert_allclose(corr.dx, x0_post, atol=1e-12)
    np.testing.assert_allclose(a.x, 0.0, atol=1e-12)
    np.testing.assert_allclose(b.x[6], 3.0 - x0_post[6], atol=1e-12)
    np.testing.assert_allclose(imm.covariance(), a.P)
    with pytest.raises(ArgumentError, match="most-probable"):
        ImmEstimator([a, b], [{fix}, {fix}], np.eye(2), output="best")
