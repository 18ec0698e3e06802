"""Coloured-noise Gaussian-mixture EKF (M6, paper P2): the augmented split
against a numpy oracle, the M6 = M3 invariant at zero coefficients, the
differenced measurement (NIS of differenced rows, consistency under AR(1)
noise), and its configuration."""

from __future__ import annotations

import numpy as np
import pytest

from mixnav.config.loader import load_scenario, resolve
from mixnav.errors import ArgumentError, ConfigError
from mixnav.experiment import methods as registry
from mixnav.filters.colored import N_W, ColoredBankEstimator, ColoredMixtureEkf, colored_split, fit_coefficient
from mixnav.filters.gmekf import BankMixtures, GaussianMixtureEkf, StandardMixture
from mixnav.ins.error_model import ClockModel
from mixnav.measurements.differenced import STATIONARY, DifferencedMeasurement
from mixnav.sim.scenario import simulate


def test_colored_split_equals_the_augmented_transition():
    """X' = A X, P' = A P A^T + c_j [[Q, Q], [Q, Q]] with A = [[I, Psi], [0, Psi]]
    on the 9 coloured states, written out with dense matrices."""
    rng = np.random.default_rng(1)
    n, nc, N = 12, 3, 2
    na = n + N_W + nc
    A0 = rng.standard_normal((N, na, na))
    P = A0 @ np.swapaxes(A0, 1, 2) / na + np.eye(na)
    X = rng.standard_normal((N, na))
    lw = np.log([0.3, 0.7])
    B = rng.standard_normal((N_W, N_W))
    Q = B @ B.T
    psi = rng.uniform(-0.95, 0.95, N_W)
    log_wj, cj = np.log([0.25, 0.75]), np.array([0.5, 2.0])
    lw2, X2, P2 = colored_split(lw, X, P, Q, log_wj, cj, psi, n)
    A = np.eye(na)
    A[:N_W, n:n + N_W] = np.diag(psi)
    A[n:n + N_W, n:n + N_W] = np.diag(psi)
    G = np.zeros((na, N_W))
    G[:N_W] = np.eye(N_W)
    G[n:n + N_W] = np.eye(N_W)
    for c in range(N):
        for j in range(2):
            o = 2 * c + j
            assert lw2[o] == pytest.approx(lw[c] + log_wj[j], abs=1e-15)
            np.testing.assert_allclose(X2[o], A @ X[c], atol=1e-14)
            np.testing.assert_allclose(P2[o], A @ P[c] @ A.T + cj[j] * G @ Q @ G.T, atol=1e-12)


def _tight_demo(seed=3, text=None, tmp_path=None):
    if text is None:
        sc, src, _ = load_scenario("tight-demo")
    else:
        p = tmp_path / "s.toml"
        p.write_text(text)
        sc, src, _ = load_scenario(str(p))
    sim = simulate(sc, seed, src)
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    tight = [m for m in sc.methods if m.type == "tight-ekf"][0]

    def models():
        return registry.build(tight.model_copy(update={"estimator": "ekf", "mixture": None}), sim.imu_model,
                              sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0,
                              observations=sim.observations, clock=clock)
    return sim, clock, models


def test_zero_coefficients_equal_the_gaussian_mixture_ekf():
    """P2's invariant: with H = Psi = 0 M6 is M3. Both carry a pseudorange
    mixture and a two-component process mixture (so the bank splits and
    reduces every epoch); M6 also carries the AR(1) process states and the
    differencing clone, whose zero coefficients must leave the solution as is."""
    sim, clock, models = _tight_demo()
    mix = BankMixtures({"pseudorange": StandardMixture((0.1, 0.9), (0.0, 0.0), (1.0, 1.0 / 3.0))},
                       process=StandardMixture((0.5, 0.5), (0.0, 0.0), (0.5, 1.5)))
    ekf, meas = models()
    r3 = GaussianMixtureEkf(ekf.layout, ekf.imu_model, mix, max_components=4, clock=clock).run(
        sim.imu, sim.init, meas)
    _, meas = models()
    psi = {"pseudorange": 0.0, "range_rate": 0.0}
    dm = [DifferencedMeasurement(m, ekf.layout, psi) for m in meas]
    assert dm[0].clone_size == 14          # lever arm and Doppler: att, vel, pos, bg, clock
    m6 = ColoredMixtureEkf(ekf.layout, ekf.imu_model, mix, psi_process=0.0, psi_measurement=psi,
                           max_components=4, clock=clock, augment=True)
    r6 = m6.run(sim.imu, sim.init, dm)
    assert m6.estimator.process_steps > 500 and m6.estimator.nw == N_W
    np.testing.assert_allclose(r6.nav[:, :7], r3.nav[:, :7], atol=1e-10)
    np.testing.assert_allclose(r6.nav[:, 7:9], r3.nav[:, 7:9], atol=1e-15)
    np.testing.assert_allclose(r6.nav[:, 9], r3.nav[:, 9], atol=1e-9)
    np.testing.assert_allclose(r6.sigma, r3.sigma, rtol=1e-10)
    np.testing.assert_allclose(r6.nis, r3.nis, rtol=1e-9)


_AR = '''pseudorange_noise = { type = "ar1", coefficient = PSI, sigma = "3 m" }
range_rate_noise = { type = "ar1", coefficient = PSI, sigma = "0.1 m/s" }'''


def _coloured_tight_demo(psi: float) -> str:
    """tight-demo with AR(1) Gaussian pseudorange and range-rate noise whose
    innovation sigma is what the filters are told (3 m, 0.1 m/s)."""
    text, _ = resolve("tight-demo")
    old = 'outages = [{ window = ["300 s", "360 s"], keep = 3 }]'
    assert old in text
    return text.replace(old, _AR.replace("PSI", str(psi)))


def _nees_nis(res, sim):
    from mixnav.experiment.run import solution_table
    t = solution_table(res, sim.truth, sim.outages)
    return float(np.nanmean(t.nees_pos)), float(np.mean(res.nis / res.nis_dim))


def test_differencing_whitens_ar1_measurement_noise(tmp_path):
    """M1 with the differenced measurement under AR(1) noise (psi = 0.9): the
    differenced rows are white with the innovation variance the filter is
    told, so NIS per dof averages 1 and position NEES is near its 3 dof; the
    plain EKF, which takes the coloured noise as white, is overconfident
    (NEES many times 3). Tolerance: 3 seeds x ~590 epochs of ~16 rows, NIS per
    dof within 0.1 of 1 (its sampling sd here is ~0.02, the rest is the
    linearisation and the stationary start); NEES within [1.5, 5] (epochs are
    strongly correlated, so the time average over one drive varies by tens of
    per cent)."""
    text = _coloured_tight_demo(0.9)
    for seed in range(3):
        sim, clock, models = _tight_demo(seed, text, tmp_path)
        ekf, meas = models()
        nees_w, _ = _nees_nis(ekf.run(sim.imu, sim.init, meas), sim)
        ekf, meas = models()
        dm = [DifferencedMeasurement(m, ekf.layout, {"pseudorange": 0.9, "range_rate": 0.9}) for m in meas]
        nees, nis = _nees_nis(ekf.run(sim.imu, sim.init, dm), sim)
        assert nis == pytest.approx(1.0, abs=0.1), seed
        assert 1.5 < nees < 5.0, seed
        assert nees_w > 4 * nees, seed


def test_differencing_rows_and_kinds():
    """Rows of satellites seen at the previous epoch are differenced (kind
    codes as given), new ones are not (kind + STATIONARY, variance r / (1 - psi^2))."""
    sim, clock, models = _tight_demo()
    ekf, meas = models()
    dm = DifferencedMeasurement(meas[0], ekf.layout, {"pseudorange": 0.5})
    nav, w = sim.init.nav.copy(), np.zeros(3)
    z0, H0, r0, k0, _ = dm.rows(1, nav, w, np.zeros(2))
    assert np.all(k0 >= STATIONARY)                                 # nothing remembered yet
    np.testing.assert_allclose(r0[k0 == STATIONARY], 9.0 / 0.75)     # pseudorange: 3 m, psi 0.5
    np.testing.assert_allclose(r0[k0 == STATIONARY + 1], 0.01)       # range rate: white
    mem = dm.remember(1, nav, w, np.zeros(2))
    zi, Hi, ri = meas[0].measure(2, nav, w, np.zeros(2))
    z, H, r, k, _ = dm.rows(2, nav, w, np.zeros(2), mem)
    ch1 = meas[0].row_channels(1, len(z0))
    ch2 = meas[0].row_channels(2, len(z))
    common = np.isin(ch2, ch1)
    assert np.all(k[common] < STATIONARY) and np.all(k[~common] >= STATIONARY)
    pr = common & (k == 0)
    zp = {c: v for c, v in zip(ch1, z0)}
    np.testing.assert_allclose(z[pr], zi[pr] - 0.5 * np.array([zp[c] for c in ch2[pr]]))
    n = ekf.layout.n
    np.testing.assert_array_equal(H[:, :n], Hi)
    assert np.all(H[~common, n:] == 0.0)
    assert np.all(np.abs(H[pr, n:]).sum(axis=1) > 0.0)


def test_fit_coefficient_recovers_the_ar1():
    rng = np.random.default_rng(0)
    x = np.zeros((3000, 8))
    for k in range(1, 3000):
        x[k] = 0.8 * x[k - 1] + rng.standard_normal(8)
    assert fit_coefficient(x) == pytest.approx(0.8, abs=0.02)   # sd of the median ~0.004


@pytest.mark.parametrize("psi", [1.0, -1.2, float("nan")])
def test_non_stationary_coefficients_are_refused(psi):
    sim, clock, models = _tight_demo()
    ekf, meas = models()
    with pytest.raises(ArgumentError, match="psi"):
        DifferencedMeasurement(meas[0], ekf.layout, {"pseudorange": psi})
    with pytest.raises(ArgumentError, match="psi"):
        ColoredMixtureEkf(ekf.layout, ekf.imu_model, BankMixtures(), psi_process=psi)


_M6 = '''
[[methods]]
name = "m6"
type = "tight-ekf"
states = 17
estimator = "gaussian-mixture"
[methods.mixture]
learn = { method = "vb", observables = ["pseudorange", "range_rate"], process = false }
colored = { measurement = { pseudorange = "fit", range_rate = 0.3 }, channels = { "pseudorange:3" = 0.5 } }
'''


def _m6_scenario(tmp_path, extra=_M6, psi=0.9):
    p = tmp_path / "m6.toml"
    p.write_text(_coloured_tight_demo(psi) + extra)
    return str(p)


def test_scenario_fits_the_coefficient_and_learns_the_whitened_mixture(tmp_path):
    """'fit' recovers the simulated AR(1) coefficient from the training series;
    the mixture is learned from the whitened series, so it describes the white
    driving noise (unit variance in units of the told sigma), not the coloured
    noise (variance 1 / (1 - 0.81) = 5.3)."""
    from mixnav.experiment.run import _training
    sc, src, _ = load_scenario(_m6_scenario(tmp_path))
    training = _training(sc, 0, src)
    sim = simulate(sc, 0, src)
    f, meas = registry.build(sc.methods[-1], sim.imu_model, None, np.zeros(3), src, len(sc.methods) - 1,
                             observations=sim.observations, clock=ClockModel(), training=training, seed=0)
    assert isinstance(f.estimator or f.make_estimator(), ColoredBankEstimator)
    assert isinstance(meas[0], DifferencedMeasurement) and not f.can_smooth
    assert f.psi_measurement[0] == pytest.approx(0.9, abs=0.03)  # 167 epochs x 12 channels
    assert f.psi_measurement[1] == 0.3
    assert meas[0].psi_channels == {3: 0.5}
    pr = f.mixtures.measurement["pseudorange"]
    assert pr.variance() == pytest.approx(1.0, abs=0.15)
    assert f.learning_time_s > 0


@pytest.mark.parametrize("old, new, key", [
    ('type = "tight-ekf"\nstates = 17\nestimator = "gaussian-mixture"', 'type = "tdcp-ekf"\nstates = 17\n'
     'estimator = "gaussian-mixture"', "methods[2].type"),
    ('range_rate = 0.3', 'range_rate = 1.0', "methods[2].mixture.colored.measurement.range_rate"),
    ('"pseudorange:3"', '"pseudorange-3"', "methods[2].mixture.colored.channels.pseudorange-3"),
    ('colored = {', 'colored = { process = "often", ', "methods[2].mixture.colored.process"),
])
def test_bad_colored_tables_name_their_key(tmp_path, old, new, key):
    text = _M6.replace(old, new)
    assert text != _M6
    with pytest.raises(ConfigError) as e:
        sc, src, _ = load_scenario(_m6_scenario(tmp_path, text))
        from mixnav.experiment.run import run_scenario
        run_scenario(sc, src, seed=0)
    assert key in str(e.value)


def _held_ar1_noise(psi, dt, T=1.0):
    """IMU white-noise multipliers that are an AR(1) process held over each
    ``T`` (written here independently of the simulator's option): the noise
    integrated over epoch k is ``x_k ARW sqrt(T)`` with ``x_k = psi x_{k-1} + N(0, 1)``."""
    from scipy.signal import lfilter

    def noise(rng, times, c):
        n = len(times)
        k = np.ceil(np.arange(1, n + 1) * dt / T - 1e-9).astype(int) - 1
        w = rng.standard_normal((k[-1] + 1, c))
        x = np.empty_like(w)
        x[0] = w[0] / np.sqrt(1.0 - psi ** 2)
        x[1:], _ = lfilter([1.0], [1.0, -psi], w[1:], axis=0, zi=(psi * x[0])[None, :])
        return x[k] * np.sqrt(dt / T)
    return noise


def test_process_augmentation_follows_coloured_imu_noise(monkeypatch):
    """tight-demo with the IMU's white noise coloured at the epoch level
    (psi = 0.9, innovation = the datasheet noise): M6 told psi is consistent
    (velocity NEES near its 3 dof) and more accurate in velocity than the EKF,
    which takes the noise as white and is overconfident. Tolerances: 2 seeds,
    NEES averaged over ~600 correlated epochs: [1.5, 5]; measured 3.4 (M6)
    and 34 (EKF), RMSE 0.07 against 0.15 m/s."""
    import mixnav.sim.scenario as simsc
    from mixnav.experiment.run import solution_table
    orig = simsc.corrupt
    monkeypatch.setattr(simsc, "corrupt", lambda imu, model, rng, white_noise=None, hold=None:
                        orig(imu, model, rng, white_noise=_held_ar1_noise(0.9, 0.01)))
    for seed in range(2):
        sim, clock, models = _tight_demo(seed)
        f, meas = models()
        t1 = solution_table(f.run(sim.imu, sim.init, meas), sim.truth, sim.outages)
        f, meas = models()
        m6 = ColoredMixtureEkf(f.layout, f.imu_model, BankMixtures(), psi_process=0.9, clock=clock)
        t6 = solution_table(m6.run(sim.imu, sim.init, [DifferencedMeasurement(m, f.layout, {}) for m in meas]),
                            sim.truth, sim.outages)
        nees1, nees6 = np.nanmean(t1.nees_vel), np.nanmean(t6.nees_vel)
        assert 1.5 < nees6 < 5.0, seed
        assert nees1 > 4 * nees6, seed
        rms = [np.sqrt(np.mean(t.err_vn_mps ** 2 + t.err_ve_mps ** 2)) for t in (t1, t6)]
        assert rms[1] < 0.75 * rms[0], seed


def test_ar_coefficient_over_fractional_and_whole_steps():
    """A fitted coefficient may be slightly negative (white noise); a step of a
    non-integer number of intervals must not turn it into NaN."""
    from mixnav.filters.colored import ar_coefficient
    psi = np.array([0.9, -0.02, 0.0, -0.5])
    np.testing.assert_allclose(ar_coefficient(psi, 1.0 + 1e-9), psi)
    np.testing.assert_allclose(ar_coefficient(psi, 2.0), psi ** 2)
    half = ar_coefficient(psi, 0.5)
    assert np.all(np.isfinite(half))
    np.testing.assert_allclose(half, np.sign(psi) * np.sqrt(np.abs(psi)))


def test_differencing_serves_the_loose_model(tmp_path):
    """Loose coupling with AR(1) position and velocity noise per axis (psi = 0.8,
    innovation sigmas what the filter is told): the differenced EKF's NIS per
    dof averages 1 (within 0.1; ~540 epochs of 6 rows, the first epoch after
    the outage undifferenced) and it is far less overconfident than the EKF
    that takes the noise as white (measured: NIS/dof 0.99 against 2.3,
    position NEES 2.7 against 61)."""
    from mixnav.experiment.run import solution_table
    text, _ = resolve("loose-demo")
    old = 'velocity_sigma = ["0.05 m/s", "0.05 m/s", "0.1 m/s"]\n'
    assert text.count(old) == 1
    text = text.replace(old, old + 'position_noise = { type = "ar1", coefficient = 0.8, sigma = ["1.5 m", "1.5 m", "3 m"] }\n'
                        'velocity_noise = { type = "ar1", coefficient = 0.8, sigma = ["0.05 m/s", "0.05 m/s", "0.1 m/s"] }\n')
    p = tmp_path / "loose.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    sim = simulate(sc, 0, src)
    m = sc.methods[0]

    def run(diff):
        f, meas = registry.build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0)
        if diff:
            meas = [DifferencedMeasurement(x, f.layout, {"position": 0.8, "velocity": 0.8}) for x in meas]
            assert meas[0].clone_size == 12              # att, vel, pos, bg (lever arm)
        r = f.run(sim.imu, sim.init, meas)
        t = solution_table(r, sim.truth, sim.outages)
        return float(np.mean(r.nis / r.nis_dim)), float(np.nanmean(t.nees_pos))
    nis_w, nees_w = run(False)
    nis_d, nees_d = run(True)
    assert nis_d == pytest.approx(1.0, abs=0.1)
    assert nees_d < 6.0 and nees_w > 2 * nees_d, (nees_w, nees_d)
