"""GaussianMixture: a naive scipy oracle, sampling moments, exact merges."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from mixnav.noise.mixture import GaussianMixture, MixtureError, merge_moments


def random_mixture(rng, k=4, d=3):
    w = rng.dirichlet(np.ones(k))
    mu = rng.normal(scale=2.0, size=(k, d))
    a = rng.normal(size=(k, d, d))
    P = a @ np.swapaxes(a, 1, 2) + 0.3 * np.eye(d)
    return GaussianMixture(w, mu, P)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_logpdf_matches_a_naive_scipy_sum(rng, d):
    gm = random_mixture(rng, 5, d)
    x = rng.normal(scale=3.0, size=(200, d))
    naive = np.log(sum(w * multivariate_normal(m, P).pdf(x)
                       for w, m, P in zip(gm.weights, gm.means, gm.covariances)))
    np.testing.assert_allclose(gm.logpdf(x), naive.reshape(-1), rtol=0, atol=1e-12)


def test_far_tails_stay_finite_in_log_space():
    gm = GaussianMixture([0.5, 0.5], [[0.0], [1.0]], [[[1e-4]], [[1e-4]]])
    lp = gm.logpdf(np.array([[50.0]]))
    assert np.isfinite(lp).all() and lp[0] < -1e6


def test_sampling_moments(rng):
    gm = random_mixture(rng, 3, 2)
    x = gm.sample(400_000, np.random.default_rng(3))
    # sd of a sample mean ~ sqrt(P/n) ~ 0.005 here; 5e-2 on the covariance
    np.testing.assert_allclose(x.mean(0), gm.mean(), atol=0.03)
    np.testing.assert_allclose(np.cov(x.T), gm.cov(), rtol=0.02, atol=0.02)


def test_merge_keeps_mean_and_covariance_exactly(rng):
    gm = random_mixture(rng, 12, 3)
    for k in (8, 3, 1):
        r = gm.reduce(k)
        assert r.n_components == k
        np.testing.assert_allclose(r.mean(), gm.mean(), atol=1e-12)
        np.testing.assert_allclose(r.cov(), gm.cov(), atol=1e-11)
    W, m, P = merge_moments(gm.weights, gm.means, gm.covariances)
    np.testing.assert_allclose(m, gm.mean(), atol=1e-12)
    np.testing.assert_allclose(P, gm.cov(), atol=1e-12)


def test_reduction_merges_the_closest_pair_first():
    # two near-identical components and one far away: the near pair merges
    gm = GaussianMixture([0.3, 0.3, 0.4], [[0.0], [0.01], [10.0]], np.ones((3, 1, 1)))
    r = gm.reduce(2)
    np.testing.assert_allclose(sorted(r.means[:, 0]), [0.005, 10.0], atol=1e-12)


def test_prune_renormalises_and_keeps_the_largest():
    gm = GaussianMixture([0.005, 0.995], [[0.0], [1.0]], np.ones((2, 1, 1)))
    p = gm.prune(0.01)
    assert p.n_components == 1 and p.weights[0] == 1.0
    assert gm.prune(0.999).n_components == 1


def test_marginal(rng):
    gm = random_mixture(rng, 3, 3)
    m = gm.marginal([0, 2])
    np.testing.assert_allclose(m.cov(), gm.cov()[np.ix_([0, 2], [0, 2])], atol=1e-12)


@pytest.mark.parametrize("args,words", [
    (([0.5, 0.6], [[0.0], [1.0]], np.ones((2, 1, 1))), "sum to"),
    (([-0.1, 1.1], [[0.0], [1.0]], np.ones((2, 1, 1))), "negative"),
    (([0.5, 0.5], [[0.0], [1.0]], [[[1.0]], [[-1.0]]]), "component 1 is not positive definite"),
    (([0.5, 0.5], [[0.0], [np.nan]], np.ones((2, 1, 1))), "finite"),
    (([1.0], [[0.0, 1.0]], np.ones((1, 1, 1))), "shapes disagree"),
])
def test_invalid_parameters_are_named(args, words):
    with pytest.raises(MixtureError, match=words):
        GaussianMixture(*args)


def test_sampling_needs_an_explicit_generator():
    gm = GaussianMixture([1.0], [[0.0]], [[[1.0]]])
    with pytest.raises(TypeError, match="Generator"):
        gm.sample(3, 42)
