"""The mixture learners are complete scikit-learn estimators (clone, predict,
predict_proba, score_samples, score, sample), checked against oracles."""

import numpy as np
import pytest
import sklearn.base
from scipy import stats
from sklearn.exceptions import NotFittedError

from mixnav.noise.learn import EMGaussianMixture, GibbsGaussianMixture, VariationalGaussianMixture

LEARNERS = [
    lambda: EMGaussianMixture(n_components=2, random_state=0),
    lambda: VariationalGaussianMixture(n_components=2, random_state=0),
    lambda: GibbsGaussianMixture(n_components=2, n_samples=300, random_state=0),
]


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(5)
    labels = rng.random(2000) < 0.3
    x = np.where(labels, rng.normal(4.0, 0.5, 2000), rng.normal(-1.0, 1.0, 2000))
    return x, labels


@pytest.mark.parametrize("make", LEARNERS)
def test_clone_gives_an_equal_unfitted_estimator(make, data):
    est = make().set_params(n_components=3)
    est.fit(data[0])
    c = sklearn.base.clone(est)
    assert type(c) is type(est) and c.get_params() == est.get_params() and c.n_components == 3
    with pytest.raises(NotFittedError):
        c.predict(data[0])


@pytest.mark.parametrize("make", LEARNERS)
def test_densities_and_responsibilities_against_scipy(make, data):
    x, labels = data
    est = make().fit(x)
    w, mu, var = est.weights_, est.means_[:, 0], est.covariances_[:, 0, 0]
    comp = np.array([wk * stats.norm.pdf(x, m, np.sqrt(v)) for wk, m, v in zip(w, mu, var)]).T  # (n, K)
    np.testing.assert_allclose(est.score_samples(x), np.log(comp.sum(1)), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(est.predict_proba(x), comp / comp.sum(1, keepdims=True), rtol=1e-9, atol=1e-12)
    assert est.score(x) == pytest.approx(np.mean(np.log(comp.sum(1))))
    pred = est.predict(x)
    np.testing.assert_array_equal(pred, np.argmax(est.predict_proba(x), axis=1))
    # well separated (5 sigma): the components are the two populations, in some order
    right = pred == np.argmax(mu)
    assert max(np.mean(right == labels), np.mean(right != labels)) > 0.99


@pytest.mark.parametrize("make", LEARNERS)
def test_sampling_is_reproducible_and_has_the_mixture_moments(make, data):
    est = make().fit(data[0])
    a, la = est.sample(20000, random_state=3)
    b, lb = est.sample(20000, random_state=3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(la, lb)
    gm = est.mixture_
    # mean within 4 standard errors (sd of the mixture about 2.3, n = 20000: 0.016)
    sd = np.sqrt(gm.cov()[0, 0])
    assert abs(a.mean() - gm.mean()[0]) < 4 * sd / np.sqrt(len(a))
    assert abs(a.var() / gm.cov()[0, 0] - 1) < 0.05
    assert abs(np.mean(la == 0) - est.weights_[0]) < 4 * np.sqrt(0.25 / len(a))
