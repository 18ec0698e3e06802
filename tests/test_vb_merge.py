"""Tests of the VB learner's merge moves and k-means initialisation (mixnav.noise.learn.vb).

* oracle: the bound of P1 eq. (29) written term by term (Bishop PRML 10.70-10.77, with
  scipy's Dirichlet and Wishart entropies) equals the kernels' bound, and an empty
  component changes it by the fixed amount the merge rule's documentation states;
* invariants: the bound never decreases within a run and each kept merge raises it;
* seeded statistics: the number of components of well-separated mixtures is recovered in
  every one of 20 seeds, and the issue's example (two nested central components plus a
  10 m outlier component) is fitted as closely as 2000 samples allow.
"""

import math
import warnings

import numpy as np
import pytest
from scipy import stats
from scipy.special import digamma, gammaln, multigammaln, xlogy

from mixnav.noise.learn import ConvergenceWarning, VariationalGaussianMixture
from mixnav.noise.learn import vb as vbmod
from mixnav.noise.mixture import GaussianMixture
from tests.test_learners import _assert_runs_monotone

THREE_1D = GaussianMixture([0.3, 0.4, 0.3], [[-5.0], [0.0], [6.0]], [[[1.0]], [[0.5]], [[1.5]]])
THREE_2D = GaussianMixture([0.3, 0.4, 0.3], [[-5.0, 0.0], [0.0, 4.0], [6.0, -2.0]],
                           [np.eye(2), [[0.5, 0.2], [0.2, 0.8]], 1.5 * np.eye(2)])
# the issue's example: 0.1 N(0, 0.3^2) + 0.9 N(0, 0.3^2 / 3) scaled to 95 %, and 5 % N(10, 1)
ISSUE = GaussianMixture([0.095, 0.855, 0.05], [[0.0], [0.0], [10.0]], [[[0.09]], [[0.03]], [[1.0]]])


def _fit(X, seed, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConvergenceWarning)       # every fit here must converge
        return VariationalGaussianMixture(4, random_state=seed, max_iter=5000, **kw).fit(X)


# --------------------------------------------------------------------------- oracle bound
def _explicit_bound(X, w, resp, params, prior):
    """P1 eq. (29) term by term for any q(Z) = ``resp`` (Bishop PRML eqs. 10.70-10.77)."""
    alpha, beta, m, nu, Winv = params
    alpha0, beta0, m0, nu0, W0inv = prior
    K, d = m.shape
    W = np.linalg.inv(Winv)
    W0 = np.linalg.inv(W0inv)
    e_ln_pi = digamma(alpha) - digamma(alpha.sum())
    e_ln_lam = np.array([np.sum(digamma(0.5 * (nu[k] - np.arange(d)))) + d * math.log(2.0)
                         + np.linalg.slogdet(W[k])[1] for k in range(K)])
    diff = X[:, None, :] - m[None]                                          # (n, K, d)
    maha = np.einsum("nki,kij,nkj->nk", diff, W, diff)
    wr = w[:, None] * resp
    e_lik = 0.5 * np.sum(wr * (e_ln_lam - d * math.log(2 * math.pi) - d / beta - nu * maha))
    e_pz = np.sum(wr * e_ln_pi)
    ln_c0 = gammaln(K * alpha0) - K * gammaln(alpha0)
    e_ppi = ln_c0 + (alpha0 - 1.0) * e_ln_pi.sum()
    ln_b0 = (-0.5 * nu0 * np.linalg.slogdet(W0)[1] - 0.5 * nu0 * d * math.log(2.0) - multigammaln(0.5 * nu0, d))
    dm = m - m0
    e_pml = (0.5 * np.sum(d * math.log(beta0 / (2 * math.pi)) + e_ln_lam - d * beta0 / beta
                          - beta0 * nu * np.einsum("ki,kij,kj->k", dm, W, dm))
             + K * ln_b0 + 0.5 * (nu0 - d - 1) * e_ln_lam.sum()
             - 0.5 * np.sum(nu * np.trace(W0inv @ W, axis1=1, axis2=2)))
    e_qz = np.sum(w[:, None] * xlogy(resp, resp))
    e_qpi = -stats.dirichlet(alpha).entropy()
    e_qml = sum(0.5 * e_ln_lam[k] + 0.5 * d * math.log(beta[k] / (2 * math.pi)) - 0.5 * d
                - stats.wishart(df=nu[k], scale=W[k]).entropy() for k in range(K))
    return e_lik + e_pz + e_ppi + e_pml - e_qz - e_qpi - e_qml


@pytest.mark.parametrize("d", [1, 2])
def test_bound_equals_explicit_eq29_and_empty_component_adds_fixed_amount(d):
    rng = np.random.default_rng(40 + d)
    X = (THREE_1D if d == 1 else THREE_2D).sample(300, rng)
    w = rng.uniform(0.5, 2.0, size=len(X))
    est = VariationalGaussianMixture(3)
    prior = est._resolve_prior(X, w)
    R = rng.uniform(size=(len(X), 3))
    R /= R.sum(axis=1, keepdims=True)
    P = vbmod._m_step(X, w[:, None] * R, prior)
    # (1) the kernels' bound (q(Z) optimal for q(theta) = P) is eq. (29) exactly
    bounds = []
    vbmod._vb_loop_numpy(X, w, P, prior, 0.0, 1, bounds)
    resp = vbmod._responsibilities(X, P)
    assert bounds[0] == pytest.approx(_explicit_bound(X, w, resp, P, prior), rel=1e-10)
    # (2) q(pi) optimal for q(Z) = R (alpha = alpha0 + N_k): adding a component with no
    # responsibility and q(mu, Lambda) = prior changes eq. (29) by
    # c(K + 1) - c(K), c(K) = ln G(K alpha0) - ln G(K alpha0 + N)  (module docstring)
    alpha0, beta0, m0, nu0, W0inv = prior
    P4 = (np.append(P[0], alpha0), np.append(P[1], beta0), np.vstack([P[2], m0]), np.append(P[3], nu0),
          np.concatenate([P[4], W0inv[None]]))
    R4 = np.hstack([R, np.zeros((len(X), 1))])
    N = w.sum()

    def c(k):
        return gammaln(k * alpha0) - gammaln(k * alpha0 + N)

    jump = _explicit_bound(X, w, R4, P4, prior) - _explicit_bound(X, w, R, P, prior)
    assert jump == pytest.approx(c(4) - c(3), rel=1e-8, abs=1e-8)
    assert jump < -math.log(N / 3) + 0.1          # about -ln(N / 3) for alpha0 = 1: not zero


# --------------------------------------------------------------------------- recovery
def _recovered(vb, truth, mean_tol):
    """True if the fit has the truth's number of components, each mean within ``mean_tol``."""
    if len(vb.weights_) != len(truth.weights):
        return False
    dist = np.linalg.norm(vb.means_[:, None, :] - truth.means[None], axis=2)
    return bool(np.all(dist.min(axis=0) < mean_tol) and np.all(dist.min(axis=1) < mean_tol))


@pytest.mark.parametrize("truth", [THREE_1D, THREE_2D], ids=["1d", "2d"])
def test_component_count_recovered_in_every_seed(truth):
    # With the paper's settings (alpha0 = 1, K = 4, prune 1 %) and no merge move about 1 in 10
    # seeds ended with a split duplicate (4 components; measured 8 / 100 in 1-D and in 2-D
    # with the k-means initialisation, more with k-means++ seeding alone).  With the merge
    # move: 100 / 100 in both (seeds 1000-1099); asserted on 20 seeds here.  On these 20
    # seeds merge=False fails seeds 4, 11 (1-D) and 0, 2 (2-D), and init="kmeans++" (seeding
    # without Lloyd iterations) fails 2-D seed 9 (two clusters in one component).
    n_merges = 0
    for seed in range(20):
        X = truth.sample(2000, np.random.default_rng(seed))
        vb = _fit(X, seed)
        # mean tolerance 0.3: the standard error of a mean is sigma / sqrt(600) < 0.05,
        # the shrinkage towards m0 (beta0 = 1) < 0.01
        assert _recovered(vb, truth, 0.3), (seed, vb.weights_, vb.means_)
        np.testing.assert_allclose(np.sort(vb.weights_), np.sort(truth.weights), atol=0.04)
        n_merges += sum(m["accepted"] for m in vb.merges_)
    # the merge move is exercised here (not only the initialisation doing the work):
    # k-means with K = 4 on 3 clusters always splits one of them
    assert n_merges >= 1


def test_merge_finds_split_duplicates_with_larger_k():
    # K = 6 for 2 clusters 3 sigma apart (they overlap): splits are certain, merges must
    # bring the count to 2 without merging the two true components.
    truth = GaussianMixture([0.5, 0.5], [[0.0], [3.0]], [[[1.0]], [[1.0]]])
    for seed in range(10):
        X = truth.sample(2000, np.random.default_rng(seed))
        vb = VariationalGaussianMixture(6, random_state=seed, max_iter=5000).fit(X)
        assert _recovered(vb, truth, 0.3), (seed, vb.means_.ravel())
        off = VariationalGaussianMixture(6, random_state=seed, max_iter=5000, merge=False).fit(X)
        assert off.merges_ == [] and off.merged_at_ == []
        assert vb.lower_bound_ >= off.lower_bound_ - 1e-9 * abs(off.lower_bound_)


@pytest.mark.parametrize("d", [1, 2])
def test_bound_monotone_with_merges(d):
    # same criterion as test_learners._assert_runs_monotone, on fits that do merge: two
    # overlapping components (2 / 2.5 sigma apart), 600 samples, K = 6 (measured 10 / 13 kept
    # merges over the 10 seeds; the evidence at n = 600 often prefers a single component)
    sep = [2.0] if d == 1 else [2.5, 0.0]
    truth = GaussianMixture([0.5, 0.5], [[0.0] * d, sep], [np.eye(d), np.eye(d)])
    merged = 0
    for seed in range(10):
        X = truth.sample(600, np.random.default_rng(70 + seed))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            vb = VariationalGaussianMixture(6, random_state=seed, max_iter=3000, tol=1e-9).fit(X)
        _assert_runs_monotone(vb, seed)
        merged += len(vb.merged_at_)
        for m in vb.merges_:
            assert m["accepted"] == (m["converged"] and m["gain"] > 0)
    assert merged >= 3


# --------------------------------------------------------------------------- the issue's example
def _hellinger_kl(fit, truth):
    """Hellinger distance and KL(truth || fit) of two 1-D mixtures by quadrature on a fine grid."""
    g = np.linspace(-8.0, 20.0, 40001)[:, None]
    p = np.exp(truth.logpdf(g))
    q = np.exp(fit.logpdf(g))
    h = math.sqrt(max(0.0, 1.0 - np.trapezoid(np.sqrt(p * q), g[:, 0])))
    kl = np.trapezoid(p * (truth.logpdf(g) - fit.logpdf(g)), g[:, 0])
    return h, kl


def test_issue_example_outlier_component_and_density():
    # 0.1 N(0, 0.3^2) + 0.9 N(0, 0.3^2 / 3) (scaled to 95 %) + 5 % N(10, 1), 2000 samples,
    # paper settings.  Measured over these 20 seeds: 14 fits with 2 components (one core +
    # the outlier), 6 with 3 (two nested core components + the outlier); one merge of the
    # two core components accepted (seed 8).  The two zero-mean components differing only
    # by a variance ratio of 3 are not identifiable reliably from 2000 samples, so their
    # number is not asserted; what is:
    counts = []
    for seed in range(20):
        X = ISSUE.sample(2000, np.random.default_rng(seed))
        vb = _fit(X, seed)
        counts.append(len(vb.weights_))
        mu = vb.means_[:, 0]
        out = np.abs(mu - 10.0) < 1.0
        # (a) exactly one outlier component, its weight and mean those of the samples it
        # explains (> 5 m: the core's samples are within 2 m of 0 at 6 sigma): the expected
        # weight (alpha0 + N_out) / (K' alpha0 + N) and the mean shrunk towards m0 by
        # beta0 / (beta0 + N_out) ~ 1 % of 9.5 m
        assert out.sum() == 1, (seed, mu)
        far = X[:, 0] > 5.0
        assert abs(vb.weights_[out][0] - far.mean()) < 0.002, seed
        assert abs(mu[out][0] - X[far, 0].mean()) < 0.15, seed
        # (b) the core: total weight, mean and variance of the core components together
        core = ~out
        core_mix = GaussianMixture(vb.weights_[core] / vb.weights_[core].sum(), vb.means_[core],
                                   vb.covariances_[core])
        assert abs(core_mix.mean()[0]) < 0.03
        true_var = (0.095 * 0.09 + 0.855 * 0.03) / 0.95
        assert abs(core_mix.cov()[0, 0] / true_var - 1.0) < 0.2
        # (c) the density: measured Hellinger 0.043-0.068 and KL 0.006-0.018 nats.  Most of it
        # is the outlier component's variance, inflated to 1.7-2.6 by the paper's beta0 = 1
        # (the prior N(m0, Sigma / beta0) on its mean, with m0 ~ 0.5 m the data mean, adds
        # ~(10 - 0.5)^2 / N_out ~ 0.9 to it); the 2-component moment-matched projection of
        # the truth is at Hellinger 0.032, KL 0.006.  Bounds: 0.08 and 0.025.
        h, kl = _hellinger_kl(vb.mixture_, ISSUE)
        assert h < 0.08 and kl < 0.025, (seed, h, kl)
    assert set(counts) <= {2, 3}
    assert counts.count(3) >= 3 and counts.count(2) >= 10          # measured 6 and 14


# --------------------------------------------------------------------------- options
def test_merge_option_and_warm_start():
    X = THREE_1D.sample(1000, np.random.default_rng(3))
    with pytest.raises(ValueError, match="merge"):
        VariationalGaussianMixture(4, merge="yes").fit(X)
    with pytest.raises(ValueError, match="init"):
        VariationalGaussianMixture(4, init="random").fit(X)
    first = VariationalGaussianMixture(6, random_state=0).fit(X)
    assert len(first.merges_) >= 1                                  # "auto": on for a cold fit
    assert VariationalGaussianMixture(6, random_state=0, prune_threshold=0).fit(X).merges_ == []
    X2 = X + 0.01 * np.random.default_rng(4).standard_normal(X.shape)
    warm = VariationalGaussianMixture(6).fit(X2, warm_start_from=first)
    assert warm.merges_ == []                                       # "auto": off after a warm start
    forced = VariationalGaussianMixture(6, merge=True).fit(X2, warm_start_from=first)
    assert len(forced.merges_) >= 1 or len(forced.weights_) == 1


def test_kmeans_init_is_deterministic_and_weighted():
    rng = np.random.default_rng(5)
    X = THREE_2D.sample(900, rng)
    w = rng.uniform(0.5, 2.0, size=900)
    a = vbmod.kmeans_resp(X, 3, np.random.default_rng(1), w)
    b = vbmod.kmeans_resp(X, 3, np.random.default_rng(1), w)
    np.testing.assert_array_equal(a, b)
    # for well-separated clusters Lloyd's iterations end at a fixed point: every sample is
    # assigned to the nearest weighted mean of its cluster
    centres = (a * w[:, None]).T @ X / (a * w[:, None]).sum(axis=0)[:, None]
    nearest = np.argmin(((X[:, None, :] - centres[None]) ** 2).sum(axis=2), axis=1)
    np.testing.assert_array_equal(np.argmax(a, axis=1), nearest)
    # three well-separated clusters, K = 3: one cluster per centre
    assert sorted(np.round(centres[:, 0]).astype(int).tolist()) == [-5, 0, 6]
