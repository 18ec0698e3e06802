"""A Gaussian-mixture bank as an IMM mode: the mean-carrying bank, the affine map that
gives it the mixed moments, its own predictive density as its score, and the
configuration of such a mode."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import norm

from mixnav.engine import Engine
from mixnav.errors import ArgumentError
from mixnav.filters.ekf import KalmanEstimator
from mixnav.geodesy.earth import radii
from mixnav.filters.gmekf import BankEstimator, GaussianMixtureEkf
from mixnav.filters.imm import ImmEstimator, log_likelihood
from mixnav.ins.error_model import get_layout
from mixnav.ins.strapdown import StrapdownMotion
from mixnav.measurements.base import Rows
from mixnav.measurements.kinds import kind_code
from mixnav.measurements.loose import LooseGnss
from mixnav.noise.mixture import BankMixtures, StandardMixture

#: a multipath-like position noise (standardised) and a two-component process noise
_POSITION = StandardMixture((0.8, 0.2), (0.0, 3.0), (1.0, 9.0))
_PROCESS = StandardMixture((0.5, 0.5), (0.0, 0.0), (0.5, 1.5))


@pytest.fixture(scope="module")
def loose():
    from mixnav.config.loader import load_scenario
    from mixnav.sim.scenario import simulate
    sc, src, _ = load_scenario("loose-demo")
    return sc, simulate(sc, 3, src)


def _gnss(sc, sim, lay):
    return LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)


def _bank(n=4, N=3, seed=0):
    """A mean-carrying bank of N random components in n states, ready to use."""
    rng = np.random.default_rng(seed)
    b = BankEstimator(BankMixtures(), max_components=8, carry_mean=True)
    b.n, b.na, b.nc, b.ic = n, n, 0, n
    b.lw = np.log(rng.dirichlet(np.ones(N)))
    b.X = rng.normal(size=(N, n))
    A = rng.normal(size=(N, n, n))
    b.Pb = A @ A.transpose(0, 2, 1) + 0.2 * np.eye(n)
    b.Qw, b.Qw_pending, b.mean_scale = np.zeros((n, n)), False, 1.0
    b.counts = {}
    return b


def test_set_moments_gives_the_bank_exactly_the_mixed_moments():
    """The affine map x_c -> x0 + A (x_c - m), P_c -> A P_c A^T with A = L0 Lm^-1 moves the
    merged mean to x0 and the merged covariance to A Pm A^T = P0 (closed form), keeps the
    weights, and keeps the shape: the standardised component means L^-1 (x_c - m) are the
    same before and after."""
    rng = np.random.default_rng(4)
    b = _bank()
    m, Pm = b.moments()
    w = np.exp(b.lw)
    # the merged moments are the mixture's (law of total variance), computed here in numpy
    np.testing.assert_allclose(m, w @ b.X)
    d = b.X - m
    np.testing.assert_allclose(Pm, np.einsum("c,cij->ij", w, b.Pb) + (w[:, None] * d).T @ d, atol=1e-12)
    shape_before = np.linalg.solve(np.linalg.cholesky(Pm), d.T).T
    x0 = rng.normal(size=4)
    B = rng.normal(size=(4, 4))
    P0 = B @ B.T + 0.5 * np.eye(4)
    lw_before = b.lw.copy()
    b.set_moments(x0, P0)
    m2, P2 = b.moments()
    np.testing.assert_allclose(m2, x0, atol=1e-12)
    np.testing.assert_allclose(P2, P0, atol=1e-11)
    np.testing.assert_array_equal(b.lw, lw_before)
    shape_after = np.linalg.solve(np.linalg.cholesky(P2), (b.X - m2).T).T
    np.testing.assert_allclose(shape_after, shape_before, atol=1e-10)
    assert all(np.linalg.eigvalsh(P).min() > 0 for P in b.Pb)


def test_set_moments_moves_the_white_noise_held_for_the_split():
    """With white process noise held apart until the next split (moments() counts it with
    the mixture's mean scale), the map applies to it too, so the moments after the split
    are the ones set."""
    b = _bank()
    b.Qw = 0.3 * np.eye(4)
    b.Qw[0, 1] = b.Qw[1, 0] = 0.1
    b.Qw_pending, b.mean_scale = True, 1.0
    x0, P0 = np.arange(4.0), np.diag([2.0, 3.0, 4.0, 5.0])
    b.set_moments(x0, P0)
    m, P = b.moments()
    np.testing.assert_allclose(m, x0, atol=1e-12)
    np.testing.assert_allclose(P, P0, atol=1e-11)


def test_a_bank_that_cannot_be_factorised_collapses_to_the_mixed_gaussian():
    b = _bank()
    b.set_moments(np.ones(4), np.diag([1.0, 1.0, 0.0, 1.0]))   # P0 singular: no factor
    assert b.counts["mode_collapsed"] == 1 and len(b.lw) == 1
    np.testing.assert_array_equal(b.X[0], np.ones(4))


def test_bank_score_is_its_mixture_density():
    """One row, a two-component noise mixture, a two-component bank: the score is
    sum_c w_c sum_l pi_l N(z; h x_c + mu_l sigma, h P_c h + v_l sigma^2), computed with
    scipy; with Gaussian noise and one component it is log_likelihood() (the EKF modes')."""
    kc = kind_code("position")
    for mix in (_POSITION, StandardMixture.gaussian()):
        b = _bank(N=2, seed=7)
        b.mixtures = BankMixtures({"position": mix})
        b.tables = b._tables_for(b.mixtures)
        b.proc_logw, b.proc_scale = np.zeros(1), np.ones(1)
        H = np.array([[0.5, 0.0, 1.0, 0.0]])
        z, r = np.array([2.0]), np.array([0.7])
        rows = Rows(z, H, r, np.array([kc]), None)
        w = np.exp(b.lw)
        want = 0.0
        for c in range(2):
            s = (H @ b.Pb[c] @ H.T)[0, 0]
            for pi, mu, v in zip(mix.weights, mix.means, mix.scales):
                want += w[c] * pi * norm.pdf(z[0], (H @ b.X[c])[0] + mu * np.sqrt(r[0]), np.sqrt(s + v * r[0]))
        assert b.log_likelihood(rows) == pytest.approx(np.log(want), rel=1e-12)
    b = _bank(N=1, seed=8)
    b.tables = b._tables_for(BankMixtures())
    b.proc_logw, b.proc_scale = np.zeros(1), np.ones(1)
    H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 2.0]])
    rows = Rows(np.array([0.3, -1.0]), H, np.array([0.5, 2.0]), np.array([kc, kc]), None)
    assert b.log_likelihood(rows) == pytest.approx(log_likelihood(b.X[0], b.Pb[0], rows.z, H, rows.R), rel=1e-12)


def test_mean_carrying_bank_alone_is_the_closed_loop_bank(loose):
    """With the engine alone, the bank that carries its mean (re-centred by the engine after
    feedback) gives the closed-loop bank's numbers: a multipath-like position mixture and a
    two-component process noise (children split at every epoch, reduced to 4)."""
    sc, sim = loose
    lay = get_layout(15)
    mixtures = BankMixtures({"position": _POSITION}, process=_PROCESS)
    gm = GaussianMixtureEkf(lay, sim.imu_model, mixtures, max_components=4)
    ref = gm.run(sim.imu, sim.init, [_gnss(sc, sim, lay)])
    est = BankEstimator(mixtures, max_components=4, carry_mean=True)
    res = Engine(StrapdownMotion(lay, sim.imu_model), est, [_gnss(sc, sim, lay)]).run(sim.imu, sim.init)
    np.testing.assert_allclose(res.nav, ref.nav, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.sigma, ref.sigma, rtol=1e-7)


def test_one_component_bank_mode_is_an_ekf_mode(loose):
    """An IMM of {EKF, one-Gaussian bank} with the same measurement set equals the IMM of
    two EKF modes: the bank's moments, map, score and update reduce to the Kalman filter's.
    Different transition rows, so the mixing is not trivial."""
    sc, sim = loose
    lay = get_layout(15)
    Pi = [[0.9, 0.1], [0.3, 0.7]]
    runs = []
    for second in (KalmanEstimator(carry_mean=True), BankEstimator(BankMixtures(), max_components=1,
                                                                   carry_mean=True)):
        gnss = _gnss(sc, sim, lay)
        imm = ImmEstimator([KalmanEstimator(carry_mean=True), second], [{gnss}, {gnss}], Pi,
                           initial_probabilities=[0.2, 0.8])
        runs.append(Engine(StrapdownMotion(lay, sim.imu_model), imm, [gnss]).run(sim.imu, sim.init))
    a, b = runs
    np.testing.assert_allclose(b.nav, a.nav, rtol=0, atol=1e-8)
    np.testing.assert_allclose(b.sigma, a.sigma, rtol=1e-7)
    np.testing.assert_allclose(b.outputs["mode_probabilities"], a.outputs["mode_probabilities"], atol=1e-9)


def test_a_multipath_mixture_mode_wins_on_biased_fixes(loose):
    """Fixes with a 10 m north offset on a stretch: an IMM of {Gaussian EKF, bank whose
    position noise has a +-offset tail} gives the bank mode the higher probability there
    (its density explains the offset, the Gaussian's does not) and the lower one on clean
    fixes, where its tail costs likelihood."""
    sc, sim = loose
    lay = get_layout(15)
    fixes = sim.fixes
    t = fixes.time
    bad = (t > 200) & (t < 260)
    lla = fixes.lla.copy()
    RM = radii(lla[:, 0])[0]
    lla[bad, 0] += 10.0 / (RM[bad] + lla[bad, 2])
    biased = replace(fixes, lla=lla)
    tail = StandardMixture((0.9, 0.05, 0.05), (0.0, 10.0, -10.0), (1.0, 4.0, 4.0))
    gnss = LooseGnss(biased, np.asarray(sc.gnss.lever_arm, float), lay)
    imm = ImmEstimator([KalmanEstimator(carry_mean=True),
                        BankEstimator(BankMixtures({"position": tail}), max_components=4, carry_mean=True)],
                       [{gnss}, {gnss}], [[0.95, 0.05], [0.05, 0.95]], names=["gauss", "multipath"])
    res = Engine(StrapdownMotion(lay, sim.imu_model), imm, [gnss]).run(sim.imu, sim.init)
    tm, p = res.outputs["mode_times"], res.outputs["mode_probabilities"]
    in_bad = (tm > 205) & (tm < 260)
    clean = (tm > 100) & (tm < 190)
    assert p[in_bad, 1].mean() > 0.8
    assert p[clean, 1].mean() < 0.5


def test_bank_mode_refuses_a_clone():
    est = BankEstimator(BankMixtures(), carry_mean=True)
    lay = get_layout(15)
    from mixnav.ins.imu_model import ImuErrorModel
    motion = StrapdownMotion(lay, ImuErrorModel())
    with pytest.raises(ArgumentError, match="mean-carrying bank"):
        est.init(motion, np.eye(15), 3, np.random.default_rng(0))

