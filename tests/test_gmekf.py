"""Gaussian-mixture EKF (M3): the bank kernels against independent numpy
implementations, the one-component invariant against the EKF, and the
configuration of M3-M5."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from mixnav.config.loader import load_scenario, resolve
from mixnav.errors import ConfigError
from mixnav.experiment import methods as registry
from mixnav.filters._bank_kernels import bank_epoch, bank_moments, bank_reduce, bank_update
from mixnav.filters._ekf_kernels import ekf_correct_dx
from mixnav.measurements.kinds import KINDS
from mixnav.filters.gmekf import BankMixtures, GaussianMixtureEkf, StandardMixture, learn_mixture
from mixnav.ins.error_model import ClockModel, get_layout
from mixnav.noise.mixture import merge_moments
from mixnav.sim.scenario import simulate


def _bank(rng, N, na, spread=0.3):
    A = rng.standard_normal((N, na, na))
    P = A @ np.swapaxes(A, 1, 2) / na + np.eye(na)
    X = rng.standard_normal((N, na)) * spread
    w = rng.random(N) + 0.2
    return np.log(w / w.sum()), X, P


def _tables(mix: StandardMixture, kind="pseudorange"):
    return BankMixtures({kind: mix}).tables(KINDS)


def test_one_row_equals_explicit_split_and_merge():
    """Children of every component for every noise component, Kalman-updated
    and weighted one by one in numpy, then merged per parent, give the
    kernel's bank (means, covariances, weights)."""
    rng = np.random.default_rng(0)
    N, na = 3, 5
    lw, X, P = _bank(rng, N, na)
    h = rng.standard_normal(na)
    z, r = np.array([0.7]), np.array([0.4])
    mix = StandardMixture((0.2, 0.5, 0.3), (0.0, 1.5, -0.5), (4.0, 1.0, 0.5))
    lw_k, X_k, P_k = lw.copy(), X.copy(), P.copy()
    assert bank_update(lw_k, X_k, P_k, z, h[None, :], r, np.zeros(1, dtype=np.int64), *_tables(mix))
    sig = np.sqrt(r[0])
    for c in range(N):
        ws, ms, Ps = [], [], []
        for pi, mu, v in zip(mix.weights, mix.means, mix.scales):
            R = v * r[0]
            S = h @ P[c] @ h + R
            K = P[c] @ h / S
            e = z[0] - h @ X[c] - mu * sig
            ws.append(np.exp(lw[c]) * pi * norm.pdf(e, scale=np.sqrt(S)))
            ms.append(X[c] + K * e)
            Ps.append(P[c] - np.outer(K, K) * S)
        W, m, C = merge_moments(np.array(ws), np.array(ms), np.array(Ps))
        assert np.exp(lw_k[c]) == pytest.approx(W, rel=1e-12)
        np.testing.assert_allclose(X_k[c], m, rtol=1e-11, atol=1e-13)
        np.testing.assert_allclose(P_k[c], C, rtol=1e-11, atol=1e-13)


def test_single_component_update_equals_the_ekf():
    """M3 with one-component mixtures is the EKF: correction and covariance to 1e-10."""
    rng = np.random.default_rng(1)
    lay = get_layout(17)
    n = lay.n
    _, _, P = _bank(rng, 1, n)
    H = rng.standard_normal((8, n)) * (rng.random((8, n)) < 0.4)
    z, r = rng.standard_normal(8), rng.random(8) + 0.1
    nav = np.array([1.0, 0, 0, 0, 1.0, 2.0, 0.1, 0.6, 1.9, 100.0])
    args = (np.zeros(12), np.zeros(2), lay.as_array())
    P_e, dx_e, nis_e, st_e = ekf_correct_dx(P[0], z, H, r, 1e4, nav.copy(), *args)
    tb = BankMixtures().tables(KINDS)
    st, nis, lw2, X2, P2, dx = bank_epoch(np.zeros(1), np.zeros((1, n)), P.copy(), z, H, r,
                                          np.zeros(8, dtype=np.int64), *tb, 1e4, 1, n)
    assert st == st_e == 0
    np.testing.assert_allclose(dx, dx_e, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P2[0], P_e, rtol=1e-10, atol=1e-12)
    assert nis == pytest.approx(nis_e, rel=1e-10)


def test_reduction_keeps_moments_and_merges_the_closest_pair_first():
    rng = np.random.default_rng(2)
    N, na, n = 9, 6, 6
    lw, X, P = _bank(rng, N, na, spread=2.0)
    X[4] = X[1] + 1e-3  # an obvious pair
    w0, m0, C0 = bank_moments(lw, X, P)
    lw2, X2, P2 = bank_reduce(lw, X, P, 4, n)
    assert len(lw2) == 4
    w2, m2, C2 = bank_moments(lw2, X2, P2)
    np.testing.assert_allclose(m2, m0, atol=1e-12)
    np.testing.assert_allclose(C2, C0, rtol=1e-12, atol=1e-12)
    # one merge: Salmond's distance computed by brute force picks the same pair
    lw1, X1, P1 = bank_reduce(lw, X, P, N - 1, n)
    L = np.linalg.cholesky(C0[:n, :n])
    Y = np.linalg.solve(L, (X - m0)[:, :n].T).T
    D = {(i, j): w0[i] * w0[j] / (w0[i] + w0[j]) * np.sum((Y[i] - Y[j]) ** 2)
         for i in range(N) for j in range(i + 1, N)}
    i, j = min(D, key=D.get)
    assert (i, j) == (1, 4)
    W, m, C = merge_moments(w0[[i, j]], X[[i, j]], P[[i, j]])
    k = int(np.argmin(np.abs(np.exp(lw1) - W)))
    np.testing.assert_allclose(X1[k], m, atol=1e-12)
    np.testing.assert_allclose(P1[k], C, atol=1e-12)


def _runs(name, method_index, mixtures, seed=3, max_components=16, **kw):
    sc, src, _ = load_scenario(name)
    sim = simulate(sc, seed, src)
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    m = sc.methods[method_index]
    ekf, meas = registry.build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0,
                               observations=sim.observations, clock=clock)
    r1 = ekf.run(sim.imu, sim.init, meas)
    _, meas = registry.build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0,
                             observations=sim.observations, clock=clock)
    g = GaussianMixtureEkf(ekf.layout, ekf.imu_model, mixtures, max_components=max_components, clock=clock, **kw)
    return r1, g.run(sim.imu, sim.init, meas)


def test_one_component_gmekf_run_equals_the_ekf_run():
    """Pseudorange + Doppler over the whole tight-demo drive: same solution to round-off."""
    r1, r2 = _runs("tight-demo", 0, BankMixtures())
    np.testing.assert_allclose(r2.nav[:, :7], r1.nav[:, :7], atol=1e-10)
    np.testing.assert_allclose(r2.nav[:, 7:9], r1.nav[:, 7:9], atol=1e-15)   # 1e-15 rad ~ 6 nm
    np.testing.assert_allclose(r2.nav[:, 9], r1.nav[:, 9], atol=1e-9)
    np.testing.assert_allclose(r2.sigma, r1.sigma, rtol=1e-10)
    np.testing.assert_allclose(r2.nis, r1.nis, rtol=1e-9)


def test_identical_process_components_split_and_merge_back_to_the_ekf():
    """Three process-noise components with the same scale: the bank splits into
    identical children every epoch and the reduction merges them back, so the
    solution is the EKF's (exercises split, weights and reduction)."""
    same = StandardMixture((0.2, 0.3, 0.5), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    r1, r2 = _runs("tight-demo", 0, BankMixtures(process=same), max_components=1)
    np.testing.assert_allclose(r2.nav[:, 4:7], r1.nav[:, 4:7], atol=1e-8)
    np.testing.assert_allclose(r2.sigma, r1.sigma, rtol=1e-8)


def test_tdcp_clone_in_the_bank_matches_the_ekf():
    """TDCP with the stochastic clone: the bank carries the clone in every
    component. The augmented covariance is singular right after each clone
    replacement, so batch (EKF) and sequential (bank) updates part at round-off
    and the run agrees to micrometres, not 1e-10 (the single update does,
    test_single_component_update_equals_the_ekf)."""
    r1, r2 = _runs("tdcp-demo", 1, BankMixtures())
    np.testing.assert_allclose(r2.nav[:, 4:7], r1.nav[:, 4:7], atol=1e-6)
    np.testing.assert_allclose(r2.nav[:, 9], r1.nav[:, 9], atol=1e-5)
    np.testing.assert_allclose(r2.sigma, r1.sigma, rtol=1e-6)


def test_mixture_bank_is_bounded_and_its_nis_uses_the_model_noise():
    """A two-component process mixture and a pseudorange mixture on tight-demo:
    the bank reaches (kept x process components) = 4 x 2 before each reduction
    and never more; the reported NIS is that of the merged prediction against
    the measurement model's own R, which the simulated (Gaussian) noise
    follows, so its mean per dof is near 1 (+-0.15: 1000 epochs of 6 rows,
    correlated through the state)."""
    mix = StandardMixture((0.1, 0.9), (0.0, 0.0), (1.0, 1.0 / 3.0))
    r1, r2 = _runs("tight-demo", 0, BankMixtures({"pseudorange": mix}, process=StandardMixture(
        (0.5, 0.5), (0.0, 0.0), (0.5, 1.5))), max_components=4)
    assert r2.timing["bank_components_max"] == 8
    assert np.all(np.isfinite(r2.nav)) and np.all(np.isfinite(r2.sigma))
    assert np.mean(r1.nis / r1.nis_dim) == pytest.approx(1.0, abs=0.15)
    assert np.mean(r2.nis / r2.nis_dim) == pytest.approx(1.0, abs=0.15)


def test_learned_mixture_finds_the_gross_errors():
    """VB on P1-sim1 training residuals (standardised by 0.3 m): the 2.5 m gross
    errors (every 20th epoch, +-8.3 sigma) get their own components, and the
    learned mixture's variance is that of the samples."""
    from mixnav.sim.training import training_residuals
    sc, src, _ = load_scenario("P1-sim1")
    tr = training_residuals(sc, 5, ["pseudorange"], 2000, process=False, source=src)
    x = tr["pseudorange"]
    assert len(x) == 2000
    assert np.mean(np.abs(x) > 5) == pytest.approx(1 / 20, abs=0.01)
    mix = learn_mixture(x, "vb")
    mu, w = np.asarray(mix.means), np.asarray(mix.weights)
    out = np.abs(mu) > 5
    assert out.any() and w[out].sum() == pytest.approx(np.mean(np.abs(x) > 5), abs=0.01)
    assert mix.variance() == pytest.approx(np.var(x), rel=0.05)


def _write(tmp_path, text):
    p = tmp_path / "s.toml"
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize("old,new,key", [
    ('estimator = "robust-adaptive"\nrobust = { k0 = 2.5, k1 = 5.0, c = 1.5 }',
     'robust = { k0 = 2.5, k1 = 5.0, c = 1.5 }', "methods[1]"),
    ('robust = { k0 = 2.5, k1 = 5.0, c = 1.5 }', 'robust = { k0 = 5.5, k1 = 5.0, c = 1.5 }', "methods[1].robust"),
    ('measurement.pseudorange = { weights = [0.1, 0.9]', 'measurement.pseudorange = { weights = [0.2, 0.9]',
     "methods[5].mixture.measurement.pseudorange"),
    ('learn = { method = "vb" }', 'learn = { method = "mcmc" }', "methods[4].mixture.learn.method"),
])
def test_bad_method_tables_name_their_key(tmp_path, old, new, key):
    text, _ = resolve("P1-sim1")
    assert old in text
    with pytest.raises(ConfigError) as e:
        load_scenario(_write(tmp_path, text.replace(old, new)))
    assert key in str(e.value)


def _true_mixture_scenario(tmp_path) -> str:
    """P1-sim1 without the gross errors, the EKF against M3 told the true mixture."""
    text, _ = resolve("P1-sim1")
    text = text.replace('''pseudorange_noise = { type = "sum", parts = [
  { type = "mixture", weights = [0.1, 0.9], sigmas = ["0.3 m", "0.17320508 m"] },
  { type = "gross", size = "2.5 m", every = 20 } ] }''',
                        'pseudorange_noise = { type = "mixture", weights = [0.1, 0.9], sigmas = ["0.3 m", "0.17320508 m"] }')
    assert 'type = "gross"' not in text
    head, rest = text.split("[[methods]]", 1)
    blocks = ["[[methods]]" + b for b in rest.split("[[methods]]")]
    keep = [b for b in blocks if 'name = "ekf"' in b or 'name = "gm-true"' in b]
    p = tmp_path / "true-mixture.toml"
    p.write_text(head + "".join(keep))
    return str(p)


def _paired(tmp_path, runs):
    from mixnav.experiment.run import run_scenario, solution_table
    sc, src, _ = load_scenario(_true_mixture_scenario(tmp_path))
    d = {"ekf": [], "gm-true": []}
    for seed in range(runs):
        out = run_scenario(sc, src, seed=seed)
        for name, res in out.results.items():
            t = solution_table(res, out.sim.truth, out.sim.outages)
            d[name].append([np.sqrt(np.mean(t.err_n_m ** 2 + t.err_e_m ** 2)),
                            np.sqrt(np.mean(t.err_pitch_deg ** 2 + t.err_roll_deg ** 2))])
    return np.array(d["ekf"]), np.array(d["gm-true"])


def _assert_not_worse(ekf, gm):
    """Paired: the mean of (M3 - EKF) over runs is below zero or within its
    one-sided 95 % bound of zero (t distribution)."""
    from scipy.stats import t as student
    for j in range(ekf.shape[1]):
        diff = gm[:, j] - ekf[:, j]
        half = student.ppf(0.95, len(diff) - 1) * diff.std(ddof=1) / np.sqrt(len(diff))
        assert diff.mean() - half <= 0.0, (j, diff.mean(), half)


def test_true_mixture_gmekf_is_not_worse_than_the_ekf_12_runs(tmp_path):
    ekf, gm = _paired(tmp_path, 12)
    _assert_not_worse(ekf, gm)
    # and in horizontal position it is better in most runs (it knows the noise is smaller than R)
    assert np.mean(gm[:, 0] < ekf[:, 0]) >= 0.75


@pytest.mark.slow
def test_true_mixture_gmekf_is_not_worse_than_the_ekf_50_runs(tmp_path):
    ekf, gm = _paired(tmp_path, 50)
    _assert_not_worse(ekf, gm)


def test_a_non_finite_bank_raises_instead_of_rejecting_epochs():
    """A NaN in a component's covariance (a bug upstream) is reported as
    non-finite, which the run loop raises, rather than as a not-PD epoch that
    would be rejected and counted quietly every epoch from then on."""
    from mixnav.filters._bank_kernels import _NON_FINITE
    rng = np.random.default_rng(2)
    lw, X, P = _bank(rng, 3, 5)
    P[1, 2, 2] = np.nan
    status = bank_epoch(lw, X, P, np.zeros(1), np.ones((1, 5)), np.ones(1), np.zeros(1, dtype=np.int64),
                        *_tables(StandardMixture.gaussian()), 1e4, 16, 5)[0]
    assert status == _NON_FINITE
