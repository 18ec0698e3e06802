"""Seeded statistical checks of mixnav.noise.processes.

Tolerances are a few standard errors of the estimator (computed in each test
from closed forms), so a correct implementation fails with negligible
probability and, the seeds being fixed, the outcome is deterministic anyway.
"""

import numpy as np
import pytest
from scipy import linalg as sla

from mixnav.config.noise_spec import from_config
from mixnav.errors import ArgumentError, ConfigError
from mixnav.noise.mixture import GaussianMixture
from mixnav.noise.processes import (AR1, BiasSegments, Gaussian, GrossErrors, Mixture, Outages, Sum,
                                    VarianceProfile)
from mixnav.units import LENGTH, VELOCITY


def _acf(x, lags):
    x = x - x.mean(axis=0)
    return np.array([np.sum(x[k:] * x[:len(x) - k]) / np.sum(x * x) for k in lags])


# --- AR(1) -------------------------------------------------------------------
def test_ar1_autocorrelation_and_stationary_variance():
    psi, sigma, n, c = 0.9, 0.3, 50_000, 4
    x = AR1(psi, sigma).sample(np.arange(n), c, np.random.default_rng(1))
    lags = np.array([1, 2, 5, 10])
    for j in range(c):
        r = _acf(x[:, j], lags)
        # Bartlett's variance of the sample ACF of an AR(1) at lag k
        var_r = ((1 + psi**2) * (1 - psi**(2 * lags)) / (1 - psi**2) - 2 * lags * psi**(2 * lags)) / n
        assert np.all(np.abs(r - psi**lags) < 4 * np.sqrt(var_r))
    # sigma is the INNOVATION sd: stationary variance sigma^2 / (1 - psi^2)
    v_true = sigma**2 / (1 - psi**2)
    assert AR1(psi, sigma).variance == pytest.approx(v_true)
    # var of the sample variance of an AR(1): 2 v^2 (1 + psi^2) / (1 - psi^2) / n, pooled over c
    se = np.sqrt(2 * v_true**2 * (1 + psi**2) / (1 - psi**2) / (n * c))
    assert abs(x.var(axis=0).mean() - v_true) < 4 * se


def test_ar1_stationary_start():
    # x_0 must already have the stationary variance (not start at zero)
    psi, sigma, c = 0.95, 1.0, 40_000
    x = AR1(psi, sigma).sample(np.arange(3), c, np.random.default_rng(2))
    v_true = sigma**2 / (1 - psi**2)
    se = v_true * np.sqrt(2 / c)                       # sd of a Gaussian sample variance
    assert abs(x[0].var() - v_true) < 4 * se
    assert abs(x[2].var() - v_true) < 4 * se


def test_ar1_per_channel_coefficients():
    psi = np.array([0.2, 0.8, -0.5])
    x = AR1(psi, [1.0, 2.0, 0.5]).sample(np.arange(40_000), 3, np.random.default_rng(3))
    r1 = np.array([_acf(x[:, j], [1])[0] for j in range(3)])
    assert np.allclose(r1, psi, atol=0.02)            # sd of r1 <= sqrt(1/n) = 0.005
    with pytest.raises(ValueError, match="n_channels"):
        AR1(psi, 1.0).sample(np.arange(10), 2, np.random.default_rng(0))


@pytest.mark.parametrize("psi", [
    [[0.5, 0.3], [-0.2, 0.7]],                        # real eigenvalues
    [[0.6, -0.5], [0.5, 0.6]],                        # complex pair 0.6 +- 0.5i
    [[0.8, 0.4, 0.0], [0.0, 0.8, 0.4], [0.1, 0.0, 0.3]],
])
def test_matrix_ar1_covariance_solves_lyapunov(psi):
    psi = np.array(psi)
    c = psi.shape[0]
    sig = np.linspace(0.5, 1.5, c)
    proc = AR1(psi, sig)
    p_true = sla.solve_discrete_lyapunov(psi, np.diag(sig**2))
    assert np.allclose(proc.stationary_covariance(), p_true)
    n = 100_000
    x = proc.sample(np.arange(n), c, np.random.default_rng(4))
    p_hat = np.cov(x.T)
    # correlation time of these processes is < ~10 epochs: effective n >~ 5000,
    # so the relative error of a covariance entry is ~ sqrt(2/5000) = 2 %; allow 8 %
    scale = np.sqrt(np.outer(np.diag(p_true), np.diag(p_true)))
    assert np.all(np.abs(p_hat - p_true) < 0.08 * scale)
    # lag-1 cross-covariance E[x_k x_{k-1}^T] = Psi P
    c1 = (x[1:] - x.mean(0)).T @ (x[:-1] - x.mean(0)) / (n - 1)
    assert np.all(np.abs(c1 - psi @ p_true) < 0.08 * scale)


def test_matrix_ar1_stationary_start():
    psi = np.array([[0.6, -0.5], [0.5, 0.6]])
    proc = AR1(psi, [1.0, 0.5])
    rng = np.random.default_rng(5)
    x0 = np.array([proc.sample([0.0], 2, rng)[0] for _ in range(4000)])
    # sd of a sample covariance entry ~ sqrt(2/4000) * scale = 2.2 %; allow 10 %
    p = proc.stationary_covariance()
    assert np.all(np.abs(np.cov(x0.T) - p) < 0.1 * np.sqrt(np.outer(np.diag(p), np.diag(p))))


def test_ar1_with_mixture_innovation():
    inn = Mixture([0.9, 0.1], [0.5, 3.0])
    psi, n = 0.7, 200_000
    proc = AR1(psi, innovation=inn)
    assert proc.variance == pytest.approx(inn.variance / (1 - psi**2))
    x = proc.sample(np.arange(n), 1, np.random.default_rng(6))[:, 0]
    assert abs(_acf(x, [1])[0] - psi) < 0.01               # Bartlett sd ~ 0.0016
    assert abs(x.var() / proc.variance - 1) < 0.05         # heavy tails: rel. sd ~ 1 %
    # the innovation x_k - psi x_{k-1} is the mixture itself: heavy tailed
    w = x[1:] - psi * x[:-1]
    kurt = np.mean((w - w.mean())**4) / w.var()**2 - 3
    assert abs(kurt - inn.excess_kurtosis) < 0.15 * inn.excess_kurtosis


@pytest.mark.parametrize("coef", [1.0, 1.5, -1.2, [0.5, 1.1], [[0.9, 0.5], [0.5, 0.9]]])
def test_non_stationary_ar1_is_refused(coef):
    # [[0.9, 0.5], [0.5, 0.9]] has eigenvalue 1.4 although each entry is < 1
    with pytest.raises(ArgumentError, match="grows without bound"):
        AR1(coef, 1.0)


def test_ar1_needs_exactly_one_driving_noise():
    with pytest.raises(ArgumentError, match="exactly one"):
        AR1(0.5)
    with pytest.raises(ArgumentError, match="exactly one"):
        AR1(0.5, 1.0, innovation=Gaussian(1.0))
    with pytest.raises(ArgumentError, match="white"):
        AR1(0.5, innovation=AR1(0.3, 1.0))


# --- mixture -------------------------------------------------------------------
def _mixture_moments(w, s):
    """Central moments m2, m4, m6, m8 of a zero-mean Gaussian mixture (closed form)."""
    w, s = np.asarray(w), np.asarray(s)
    return (w @ s**2, 3 * w @ s**4, 15 * w @ s**6, 105 * w @ s**8)


def test_mixture_variance_and_kurtosis():
    w, s = [0.8, 0.2], [1.0, 3.0]
    proc = Mixture(w, s)
    m2, m4, m6, m8 = _mixture_moments(w, s)
    kurt_true = m4 / m2**2 - 3                                  # 7.544 - 3 = 4.544
    assert proc.variance == pytest.approx(m2)
    assert proc.excess_kurtosis == pytest.approx(kurt_true)
    n, c = 100_000, 2
    x = proc.sample(np.arange(n), c, np.random.default_rng(7)).ravel()
    N = n * c
    assert abs(x.var() - m2) < 4 * np.sqrt((m4 - m2**2) / N)
    # delta-method sd of the sample kurtosis g = m4_hat / m2_hat^2
    var_g = ((m8 - m4**2) / m2**4 - 4 * m4 * (m6 - m2 * m4) / m2**5
             + 4 * m4**2 * (m4 - m2**2) / m2**6) / N
    g = np.mean(x**4) / np.mean(x**2)**2 - 3
    assert abs(g - kurt_true) < 4 * np.sqrt(var_g)


def test_mixture_with_means_and_from_gaussian_mixture():
    proc = Mixture([0.5, 0.5], [1.0, 1.0], means=[-2.0, 2.0])
    assert proc.variance == pytest.approx(5.0)
    # bimodal: m4 = 3 + 6*4 + 16 = 43, kurtosis 43/25 - 3 < 0
    assert proc.excess_kurtosis == pytest.approx(43 / 25 - 3)
    gm = GaussianMixture([0.3, 0.7], [[0.0], [1.0]], [[[4.0]], [[0.25]]])
    p2 = Mixture(gm)
    assert np.allclose(p2.sigmas, [2.0, 0.5]) and np.allclose(p2.means, [0.0, 1.0])
    x = p2.sample(np.arange(50_000), 2, np.random.default_rng(8))
    assert abs(x.mean() - 0.7) < 0.03                 # sd of the mean sqrt(1.4/1e5) = 0.004
    with pytest.raises(ArgumentError, match="dimension 2"):
        Mixture(GaussianMixture([1.0], [[0.0, 0.0]], [np.eye(2)]))


# --- gross errors -----------------------------------------------------------------
def test_gross_errors_every_n_are_exactly_where_configured():
    g = GrossErrors(2.5, every=20, start=5)
    x, mask = g.sample_with_mask(np.arange(200) * 0.1, 3, np.random.default_rng(9))
    expected = np.zeros(200, dtype=bool)
    expected[5::20] = True
    assert np.array_equal(mask, np.repeat(expected[:, None], 3, axis=1))
    assert np.all(np.abs(x[mask]) == 2.5) and np.all(x[~mask] == 0)
    assert np.any(x[mask] > 0) and np.any(x[mask] < 0)     # random sign
    xp, _ = GrossErrors(2.5, every=20, sign="+").sample_with_mask(np.arange(200), 2, np.random.default_rng(0))
    assert np.all(xp[::20] == 2.5)
    # only the chosen channels
    _, m = GrossErrors(1.0, every=10, channels=[1]).sample_with_mask(np.arange(100), 3, np.random.default_rng(0))
    assert m[:, 1].sum() == 10 and not m[:, [0, 2]].any()


def test_gross_errors_with_probability_occur_at_the_rate():
    p, n, c = 0.03, 20_000, 5
    x, mask = GrossErrors(4.0, probability=p).sample_with_mask(np.arange(n), c, np.random.default_rng(10))
    N = n * c
    # binomial count: mean N p, sd sqrt(N p (1 - p)); allow 4 sd
    assert abs(mask.sum() - N * p) < 4 * np.sqrt(N * p * (1 - p))
    assert np.all(np.abs(x[mask]) == 4.0) and np.all(x[~mask] == 0)
    # sign balance: binomial(count, 1/2)
    k = mask.sum()
    assert abs((x[mask] > 0).sum() - k / 2) < 4 * np.sqrt(k / 4)


def test_gross_error_mask_survives_composition():
    proc = Sum(Gaussian(0.1), VarianceProfile(GrossErrors(3.0, every=7), steps=[(50.0, 2.0)]))
    x, mask = proc.sample_with_mask(np.arange(100.0), 2, np.random.default_rng(0))
    assert np.array_equal(np.flatnonzero(mask[:, 0]), np.arange(0, 100, 7))


def test_gross_errors_bad_arguments():
    with pytest.raises(ArgumentError, match="exactly one"):
        GrossErrors(1.0)
    with pytest.raises(ArgumentError, match="exactly one"):
        GrossErrors(1.0, every=3, probability=0.1)
    with pytest.raises(ArgumentError, match="probability"):
        GrossErrors(1.0, probability=1.5)
    with pytest.raises(ArgumentError, match="sign"):
        GrossErrors(1.0, every=2, sign="up")


# --- bias, variance profile, outages, sum ----------------------------------------------
def test_bias_segments():
    t = np.arange(0.0, 100.0, 0.5)
    x = BiasSegments([(10.0, 20.0, 3.0), (15.0, 30.0, [0.0, -1.0])]).sample(t, 2, np.random.default_rng(0))
    assert np.all(x[(t >= 10) & (t < 15), 0] == 3.0)
    assert np.all(x[(t >= 15) & (t < 20), 1] == 2.0)             # overlapping segments add
    assert np.all(x[(t >= 20) & (t < 30)] == [0.0, -1.0])
    assert np.all(x[(t < 10) | (t >= 30)] == 0.0)


def test_variance_profile_scales_the_sd():
    t = np.arange(0.0, 500.0, 1.0)
    prof = VarianceProfile(Gaussian(0.5), steps=[(100.0, 3.0), (150.0, 1.0)], drifts=[(300.0, 400.0, 2.0)])
    s = prof.scale(t)
    assert np.all(s[t < 100] == 1) and np.all(s[(t >= 100) & (t < 150)] == 3) and s[200] == 1
    assert s[350] == pytest.approx(2.0) and s[325] == pytest.approx(1.5) and s[400] == 1.0
    c = 4000
    x = prof.sample(t, c, np.random.default_rng(11))
    sd_hat = x.std(axis=1)
    # relative sd of a per-epoch sd estimate from c samples: 1/sqrt(2c) = 1.1 %; allow 5 %
    assert np.all(np.abs(sd_hat / (0.5 * s) - 1) < 0.05)


def test_variance_profile_keeps_ar1_colour():
    prof = VarianceProfile(AR1(0.9, 1.0), steps=[(0.0, 10.0)])
    x = prof.sample(np.arange(20_000), 1, np.random.default_rng(12))[:, 0]
    assert abs(_acf(x, [1])[0] - 0.9) < 0.02
    assert abs(x.std() / (10 * np.sqrt(1 / (1 - 0.81))) - 1) < 0.1


def test_outages():
    t = np.arange(0.0, 100.0, 1.0)
    av = Outages([(10.0, 20.0)]).available(t, 3, np.random.default_rng(0))
    assert av.shape == (100, 3) and not av[10:20].any() and av[:10].all() and av[20:].all()
    av = Outages(fraction=0.25, channels=[0, 2]).available(t, 3, np.random.default_rng(1))
    assert (~av[:, 0]).sum() == 25 and av[:, 1].all() and np.array_equal(av[:, 0], av[:, 2])


def test_sum_variance_and_same_seed_same_numbers():
    proc = Sum(Gaussian(0.3), Mixture([0.1, 0.9], [0.3, 0.173]), AR1(0.5, 0.2),
               GrossErrors(2.5, probability=0.01), BiasSegments([(1.0, 2.0, 1.0)]))
    t = np.arange(0.0, 10.0, 0.1)
    a = proc.sample(t, 3, np.random.default_rng(42))
    b = proc.sample(t, 3, np.random.default_rng(42))
    c = proc.sample(t, 3, np.random.default_rng(43))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert proc.variance is None                                   # bias segments are not stationary
    white = Sum(Gaussian(0.3), Mixture([0.1, 0.9], [0.3, 0.173]), AR1(0.5, 0.2))
    assert white.variance == pytest.approx(0.09 + (0.1 * 0.09 + 0.9 * 0.173**2) + 0.04 / 0.75)


def test_sample_argument_checks():
    with pytest.raises(TypeError, match="Generator"):
        Gaussian(1.0).sample(np.arange(3), 1, 42)
    with pytest.raises(ValueError, match="n_channels"):
        Gaussian(1.0).sample(np.arange(3), 0, np.random.default_rng(0))
    with pytest.raises(ValueError, match="1-D"):
        Gaussian(1.0).sample(np.zeros((3, 2)), 1, np.random.default_rng(0))
    with pytest.raises(ArgumentError, match="negative"):
        Gaussian(-1.0)


# --- config ----------------------------------------------------------------------------
def test_from_config_builds_the_documented_examples():
    p = from_config({"type": "mixture", "weights": [0.1, 0.9], "sigmas": ["0.3 m", "0.173 m"]}, LENGTH)
    assert isinstance(p, Mixture) and np.allclose(p.sigmas, [0.3, 0.173])
    g = from_config({"type": "gross", "size": "2.5 m", "every": 20}, LENGTH)
    assert isinstance(g, GrossErrors) and g.size == 2.5 and g.every == 20
    a = from_config({"type": "ar1", "coefficient": 0.9, "sigma": "0.3 m"}, LENGTH)
    assert isinstance(a, AR1) and a.variance == pytest.approx(0.09 / 0.19)
    d = from_config({"type": "gaussian", "sigma": "36 km/h"}, VELOCITY)
    assert d.variance == pytest.approx(100.0)
    s = from_config({"type": "sum", "parts": [
        {"type": "ar1", "coefficient": [[0.5, 0.1], [0.0, 0.7]],
         "innovation": {"type": "mixture", "weights": [0.5, 0.5], "sigmas": ["1 m", "2 m"]}},
        {"type": "bias_segments", "segments": [["10 s", "20 s", "4 m"],
                                               {"start": "1 min", "end": "2 min", "bias": ["1 m", "0 m"]}]},
        {"type": "variance_profile", "base": {"type": "gaussian", "sigma": "1 m"},
         "steps": [["100 s", 3]], "drifts": [{"start": "200 s", "end": "400 s", "factor": 2}]},
    ]}, LENGTH)
    assert isinstance(s, Sum) and len(s.processes) == 3
    assert s.processes[1].segments[1][:2] == (60.0, 120.0)
    assert s.sample(np.arange(0.0, 500.0), 2, np.random.default_rng(0)).shape == (500, 2)
    o = from_config({"type": "outages", "windows": [["100 s", "130 s"]], "fraction": 0.1}, LENGTH)
    assert isinstance(o, Outages) and o.windows == ((100.0, 130.0),)


@pytest.mark.parametrize("table, key, words", [
    ({"type": "gaussian", "sigma": "1 m", "sigam": 2}, "gnss.noise.sigam", "unknown key"),
    ({"type": "gaussian", "sigma": "0.3"}, "gnss.noise.sigma", "missing its unit"),
    ({"type": "gaussian", "sigma": "0.3 m/s"}, "gnss.noise.sigma", "length"),
    ({"type": "gaussian", "sigma": "-1 m"}, "gnss.noise.sigma", "negative"),
    ({"type": "mixture", "weights": [0.2, 0.9], "sigmas": ["1 m", "2 m"]}, "gnss.noise.weights", "sum to 1.1"),
    ({"type": "mixture", "weights": [0.5, 0.5], "sigmas": ["1 m", "-2 m"]}, "gnss.noise.sigmas[1]", "negative"),
    ({"type": "mixture", "weights": [0.5, 0.5], "sigmas": ["1 m"]}, "gnss.noise.sigmas", "one per component"),
    ({"type": "ar1", "coefficient": 1.2, "sigma": "1 m"}, "gnss.noise.coefficient", "grows without bound"),
    ({"type": "gross", "size": "2 m", "every": 0}, "gnss.noise.every", "at least 1"),
    ({"type": "gross", "size": "2 m"}, "gnss.noise.every", "exactly one"),
    ({"type": "gaussian"}, "gnss.noise.sigma", "missing key"),
    ({"sigma": "1 m"}, "gnss.noise", "missing key 'type'"),
    ({"type": "gausian", "sigma": "1 m"}, "gnss.noise.type", "did you mean 'gaussian'"),
    ({"type": "sum", "parts": [{"type": "gaussian", "sigma": "1 m"},
                               {"type": "mixture", "weights": [0.5, 0.5], "sigmas": ["1 m", "2"]}]},
     "gnss.noise.parts[1].sigmas[1]", "missing its unit"),
    ({"type": "sum", "parts": [{"type": "outages", "fraction": 0.1}]}, "gnss.noise.parts[0].type", "not additive"),
    ({"type": "bias", "segments": [["20 s", "10 s", "1 m"]]}, "gnss.noise.segments[0]", "after start"),
    ({"type": "ar1", "coefficient": 0.5, "innovation": {"type": "ar1", "coefficient": 0.5, "sigma": "1 m"}},
     "gnss.noise.innovation.type", "white"),
])
def test_config_errors_name_the_key(table, key, words):
    with pytest.raises(ConfigError) as info:
        from_config(table, LENGTH, key_prefix="gnss.noise", source="scenario.toml")
    err = info.value
    assert err.key == key and err.file == "scenario.toml"
    assert words in str(err) and "scenario.toml" in str(err)


def test_sample_detail_gives_the_same_draws_and_their_systematic_part():
    """sample_detail draws the same numbers as sample (same generator state) and returns the
    mean of the component each sample came from: with joint components 0 and 10 every row
    is all 0 or all 10, the share of 10s is the weight (binomial 4-sigma), and the noise
    about it has each component's sigma; a profile scales it, a sum adds it, a bias segment
    is its own systematic part and white Gaussian noise has none."""
    from mixnav.noise.processes import BiasSegments, Gaussian, Mixture, Sum, VarianceProfile
    t = np.arange(1.0, 20001.0)
    mix = Mixture([0.7, 0.3], [1.0, 2.0], [0.0, 10.0], joint=True)
    proc = Sum(Gaussian(0.02), VarianceProfile(mix, steps=[(0.0, 0.0), (5000.0, 1.0), (15000.0, 0.0)]),
               BiasSegments([(100.0, 200.0, [0.5, 0.0, -0.5])]))
    x_ref = proc.sample(t, 3, np.random.default_rng(5))
    x, mask, b = proc.sample_detail(t, 3, np.random.default_rng(5))
    np.testing.assert_array_equal(x, x_ref)
    assert not mask.any()
    inside = (t >= 5000) & (t < 15000)
    np.testing.assert_array_equal(b[~inside & ((t < 100) | (t >= 200))], 0.0)
    assert np.all(b[(t >= 100) & (t < 200)] == [0.5, 0.0, -0.5])
    bi = b[inside]
    assert set(np.unique(bi)) == {0.0, 10.0} and np.all(bi == bi[:, :1])   # joint: one label per epoch
    share = (bi[:, 0] == 10.0).mean()
    assert abs(share - 0.3) < 4 * np.sqrt(0.3 * 0.7 / inside.sum())
    e = (x - b)[inside]
    for level, sigma in ((0.0, 1.0), (10.0, 2.0)):
        sel = bi[:, 0] == level
        s = e[sel].std()
        assert abs(s - np.hypot(sigma, 0.02)) < 4 * sigma / np.sqrt(2 * e[sel].size), (level, s)
