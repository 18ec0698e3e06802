"""AR(1) fit, whitening and gap-aware autocorrelation (mixnav.noise.ar).

Oracles: an independent least-squares regression (numpy.linalg.lstsq) and
the lag-1 coefficient of mixnav.noise.diagnostics; invariants: gaps equal
the pooled pieces, NaN equals a mask, masked values never matter; seeded
statistics on mixnav.noise.processes.AR1 series with known psi per channel.
"""

import numpy as np
import pytest
from scipy import stats

from mixnav.noise.ar import Ar1Fit, autocorrelation, fit_ar1, whiten_ar1
from mixnav.noise.diagnostics import diagnose
from mixnav.noise.processes import AR1

PSIS = np.array([-0.5, 0.0, 0.3, 0.6, 0.8, 0.9])


def simulate(psi, n, seed, sigma=1.0, reps=1):
    """AR(1) series (n, len(psi) * reps) from mixnav's own noise process, stationary start."""
    coef = np.tile(np.asarray(psi, dtype=float), reps)
    rng = np.random.default_rng(seed)
    return AR1(coefficient=coef, sigma=sigma).sample(np.arange(n) * 0.2, coef.size, rng), coef


# ---------------------------------------------------------------------------
# oracles
# ---------------------------------------------------------------------------
def test_equals_least_squares_regression_oracle(rng):
    x, _ = simulate([0.7], 500, 3)
    x = x[:, 0] + 4.0
    fit = fit_ar1(x)
    d = x - x.mean()
    A, b = d[:-1, None], d[1:]
    coef, rss, *_ = np.linalg.lstsq(A, b, rcond=None)
    s2 = rss[0] / (b.size - 2)
    assert fit.psi[0] == pytest.approx(coef[0], rel=1e-12)
    assert fit.innovation_variance[0] == pytest.approx(s2, rel=1e-12)
    assert fit.std_error[0] == pytest.approx(np.sqrt(s2 / (A[:, 0] @ A[:, 0])), rel=1e-12)
    assert fit.mean[0] == pytest.approx(x.mean())
    assert fit.n_pairs[0] == 499 and fit.n_valid[0] == 500
    z = stats.norm.ppf(0.975)
    assert fit.ci_low[0] == pytest.approx(coef[0] - z * fit.std_error[0])
    assert fit.ci_high[0] == pytest.approx(coef[0] + z * fit.std_error[0])
    assert fit.stationary_variance[0] == pytest.approx(s2 / (1 - coef[0] ** 2))


def test_same_coefficient_as_diagnostics_lag1():
    x, _ = simulate([0.4], 300, 8)
    assert fit_ar1(x).psi[0] == pytest.approx(diagnose(x[:, 0])["ar1"]["coefficient"], rel=1e-12)


def test_not_demeaned_fits_raw_series():
    x, _ = simulate([0.5], 400, 2)
    x = x + 3.0
    fit = fit_ar1(x, demean=False)
    assert fit.mean[0] == 0.0
    assert fit.psi[0] == pytest.approx((x[1:, 0] @ x[:-1, 0]) / (x[:-1, 0] @ x[:-1, 0]))
    assert fit.psi[0] > fit_ar1(x).psi[0]          # an unremoved mean looks like colour


# ---------------------------------------------------------------------------
# seeded statistical checks on simulated AR(1) with known psi
# ---------------------------------------------------------------------------
def test_psi_within_asymptotic_tolerance_and_ci_coverage():
    n, reps, seeds = 2000, 40, range(5)
    hits, total, worst = 0, 0, 0.0
    per_psi_hits = np.zeros(PSIS.size)
    for seed in seeds:
        x, psi = simulate(PSIS, n, seed, sigma=0.7, reps=reps)
        fit = fit_ar1(x)
        # asymptotic sd of the estimate: sqrt((1 - psi^2) / n)
        sd = np.sqrt((1 - psi ** 2) / fit.n_pairs)
        worst = max(worst, float(np.max(np.abs(fit.psi - psi) / sd)))
        inside = (fit.ci_low <= psi) & (psi <= fit.ci_high)
        hits += int(inside.sum())
        total += psi.size
        per_psi_hits += inside.reshape(reps, PSIS.size).sum(axis=0)
        # the regression standard error matches the asymptotic one (relative error O(1/sqrt(n)))
        np.testing.assert_allclose(fit.std_error, fit.asymptotic_std_error, rtol=0.1)
        # innovation variance: relative sd sqrt(2/n) ~ 0.032, 5 sd
        np.testing.assert_allclose(fit.innovation_variance, 0.49, rtol=5 * np.sqrt(2 / n))
        # stationary variance s2 / (1 - psi^2): delta method, relative sd
        # sqrt(2/n + 4 psi^2 / ((1 - psi^2) n)) (0.09 at psi = 0.9); 5 sd
        rel = fit.stationary_variance / (0.49 / (1 - psi ** 2)) - 1
        assert np.all(np.abs(rel) < 5 * np.sqrt(2 / n + 4 * psi ** 2 / ((1 - psi ** 2) * n))), rel
    # family-wise: all 1200 estimates within z sd with P(any outside) ~ 1e-3 under the asymptotics
    z = stats.norm.isf(1e-3 / (2 * total))
    assert worst < z, (worst, z)
    # coverage of the 95 % CI: binomial sd sqrt(.95 .05 / 1200) = 0.0063; 4 sd plus 0.01 for the
    # O(1/n) least-squares bias (-(1 + 3 psi) / n, about 0.25 sd at psi = 0.9, n = 2000)
    cov = hits / total
    assert abs(cov - 0.95) < 4 * np.sqrt(0.95 * 0.05 / total) + 0.01, cov
    # per psi (200 each): binomial sd 0.015; none below 0.95 - 4 sd - 0.01
    assert np.all(per_psi_hits / (reps * len(seeds)) > 0.95 - 4 * 0.0154 - 0.01), per_psi_hits


def test_ci_level_changes_width():
    x, _ = simulate([0.5, 0.2], 500, 1)
    f95, f99 = fit_ar1(x), fit_ar1(x, level=0.99)
    np.testing.assert_allclose(f95.psi, f99.psi)
    ratio = (f99.ci_high - f99.ci_low) / (f95.ci_high - f95.ci_low)
    np.testing.assert_allclose(ratio, stats.norm.ppf(0.995) / stats.norm.ppf(0.975))


# ---------------------------------------------------------------------------
# gaps
# ---------------------------------------------------------------------------
def _pieces(seed):
    x, _ = simulate([0.7], 900, seed)
    return [x[:300, 0] + 2.0, x[300:350, 0] + 2.0, x[350:, 0] + 2.0]


def test_gaps_equal_pooled_pieces():
    a, b, c = _pieces(4)
    # oracle: one mean over all valid samples, pairs only inside each piece
    mu = np.concatenate([a, b, c]).mean()
    num = sum(((p[1:] - mu) * (p[:-1] - mu)).sum() for p in (a, b, c))
    den = sum(((p[:-1] - mu) ** 2).sum() for p in (a, b, c))
    psi = num / den
    rss = sum((((p[1:] - mu) - psi * (p[:-1] - mu)) ** 2).sum() for p in (a, b, c))
    m = a.size + b.size + c.size - 3
    nan = np.full(7, np.nan)
    x = np.concatenate([a, nan, b, nan[:1], c])
    fit = fit_ar1(x)
    assert fit.psi[0] == pytest.approx(psi, rel=1e-12)
    assert fit.mean[0] == pytest.approx(mu, rel=1e-12)
    assert fit.n_pairs[0] == m
    assert fit.innovation_variance[0] == pytest.approx(rss / (m - 2), rel=1e-12)
    # the gap length does not matter, nor leading/trailing gaps
    y = np.concatenate([nan, a, np.full(100, np.nan), b, nan, c, nan])
    g = fit_ar1(y)
    for k in ("psi", "mean", "innovation_variance", "std_error", "n_pairs"):
        np.testing.assert_allclose(getattr(g, k), getattr(fit, k), rtol=1e-12)


def test_mask_equals_nan_and_masked_values_are_ignored():
    a, b, c = _pieces(5)
    x = np.concatenate([a, [np.nan] * 3, b, [np.nan], c])
    miss = np.isnan(x)
    junk = np.where(miss, np.inf, x)                     # masked values may be anything
    f_nan, f_mask = fit_ar1(x), fit_ar1(junk, mask=miss)
    np.testing.assert_array_equal(f_nan.psi, f_mask.psi)
    np.testing.assert_array_equal(f_nan.innovation_variance, f_mask.innovation_variance)
    junk2 = np.where(miss, 1e6, x)
    np.testing.assert_array_equal(fit_ar1(junk2, mask=miss).psi, f_nan.psi)


def test_gap_does_not_pair_across_it():
    # two pieces with opposite trends: pairing across the gap would add one large jump
    a = np.linspace(0, 1, 50) + np.sin(np.arange(50))
    b = np.linspace(1, 0, 50) + np.cos(np.arange(50))
    x = np.concatenate([a, [np.nan], b])
    stacked = np.concatenate([a, b])
    assert fit_ar1(x).n_pairs[0] == 98
    assert fit_ar1(stacked).n_pairs[0] == 99
    assert fit_ar1(x).psi[0] != pytest.approx(fit_ar1(stacked).psi[0], rel=1e-9)


def test_channels_are_independent():
    x, _ = simulate([0.2, 0.9], 400, 6)
    x[50:60, 1] = np.nan
    both = fit_ar1(x)
    for j in range(2):
        one = fit_ar1(x[:, j])
        assert both.psi[j] == pytest.approx(one.psi[0], rel=1e-12)
        assert both.std_error[j] == pytest.approx(one.std_error[0], rel=1e-12)


# ---------------------------------------------------------------------------
# whitening
# ---------------------------------------------------------------------------
def test_whiten_formula_and_gaps():
    x = np.array([[1.0, 2.0], [3.0, np.nan], [4.0, 5.0], [np.nan, 7.0], [6.0, 11.0]])
    w = whiten_ar1(x, [0.5, -1.0])
    expected = np.array([[np.nan, np.nan], [2.5, np.nan], [2.5, np.nan], [np.nan, 12.0], [np.nan, 18.0]])
    np.testing.assert_array_equal(w, expected)
    w1 = whiten_ar1(x[:, 0], 0.5)
    assert w1.shape == (5,)
    np.testing.assert_array_equal(w1, expected[:, 0])
    # psi = 0 returns the series itself where the predecessor is valid
    w0 = whiten_ar1(x, 0.0)
    assert w0[2, 0] == x[2, 0] and w0[4, 1] == x[4, 1] and np.isnan(w0[2, 1])


def test_whitening_a_simulated_ar1_gives_white_innovations():
    n = 3000
    band = 1.96 / np.sqrt(n)
    inside_fit, inside_true, raw_outside = 0, 0, 0
    total = 0
    for seed in range(4):
        x, psi = simulate(PSIS, n, 100 + seed)
        fit = fit_ar1(x)
        r_raw, _ = autocorrelation(x, 1)
        r_fit, _ = autocorrelation(whiten_ar1(x - fit.mean, fit.psi), 1)
        r_true, _ = autocorrelation(whiten_ar1(x, psi), 1)
        inside_fit += int(np.sum(np.abs(r_fit[1]) < band))
        inside_true += int(np.sum(np.abs(r_true[1]) < band))
        coloured = np.abs(psi) > 0.2
        raw_outside += int(np.sum(np.abs(r_raw[1][coloured]) > band))
        total += psi.size
    # with the fitted psi the lag-1 residual autocorrelation has sd about |psi| / sqrt(n) < 1/sqrt(n):
    # all 24 inside the 95 % band is expected; allow one miss
    assert inside_fit >= total - 1, inside_fit
    # with the true psi each is inside with probability 0.95: expect 22.8 of 24; P(< 20) ~ 0.3 %
    assert inside_true >= total - 4, inside_true
    # and the un-whitened coloured series are all far outside it (|r1| ~ psi >> band)
    assert raw_outside == 4 * np.sum(np.abs(PSIS) > 0.2)


# ---------------------------------------------------------------------------
# autocorrelation
# ---------------------------------------------------------------------------
def test_autocorrelation_oracle_and_ar1_shape():
    x, psi = simulate([0.8], 4000, 9)
    r, counts = autocorrelation(x, 10)
    d = x[:, 0] - x[:, 0].mean()
    n = d.size
    for lag in range(1, 11):
        biased = (d[lag:] @ d[:-lag]) / (d @ d)
        assert r[lag, 0] == pytest.approx(biased * n / (n - lag), rel=1e-10)
        assert counts[lag, 0] == n - lag
        # AR(1): r_L ~ psi^L; sd of r_L is at most sqrt((1 + psi^2) / (1 - psi^2) / n) = 0.036
        assert abs(r[lag, 0] - 0.8 ** lag) < 4 * 0.036
    assert r[0, 0] == 1.0 and counts[0, 0] == n


def test_autocorrelation_with_gaps_counts_pairs():
    x = np.arange(10.0)
    x[[3, 7]] = np.nan
    r, counts = autocorrelation(x, 3)
    # valid 0,1,2,4,5,6,8,9; lag 1: (0,1)(1,2)(4,5)(5,6)(8,9); lag 2: (0,2)(2,4)(4,6)(6,8); lag 3: (1,4)(2,5)(5,8)(6,9)
    assert counts[:, 0].tolist() == [8, 5, 4, 4]
    valid = ~np.isnan(x)
    for lag in range(1, 4):
        assert counts[lag, 0] == np.sum(valid[lag:] & valid[:-lag])


# ---------------------------------------------------------------------------
# bad inputs
# ---------------------------------------------------------------------------
def test_too_few_pairs_names_the_channel():
    x, _ = simulate([0.5, 0.5], 100, 0)
    x[::2, 1] = np.nan                                   # no consecutive pair left in channel 1
    with pytest.raises(ValueError, match=r"channel 1 \('G12'\): 0 consecutive valid pair"):
        fit_ar1(x, names=["G02", "G12"])
    with pytest.raises(ValueError, match="at least 10 are needed"):
        fit_ar1(x[:8])
    with pytest.raises(ValueError, match="min_pairs"):
        fit_ar1(x, min_pairs=2)


def test_constant_series_raises():
    x = np.ones((50, 2))
    x[:, 0] = np.random.default_rng(0).normal(size=50)
    with pytest.raises(ValueError, match=r"channel 1 is constant"):
        fit_ar1(x)
    # constant pieces at different levels are not a constant channel: d_k = d_{k-1} inside
    # each piece, so psi = 1 exactly
    y = np.concatenate([np.zeros(20), [np.nan], np.ones(20)])
    assert fit_ar1(y).psi[0] == pytest.approx(1.0)


def test_non_finite_values_outside_the_mask_raise():
    x, _ = simulate([0.5, 0.5], 100, 0)
    x[10, 1] = np.inf
    with pytest.raises(ValueError, match=r"channel 1 \('R301'\), sample 10: value inf is infinite"):
        fit_ar1(x, names=["G02", "R301"])
    x[10, 1] = np.nan
    mask = np.zeros(x.shape, dtype=bool)
    with pytest.raises(ValueError, match=r"channel 1, sample 10: value nan is not finite and not masked"):
        fit_ar1(x, mask=mask)
    mask[10, 1] = True
    assert fit_ar1(x, mask=mask).n_pairs[1] == 97
    with pytest.raises(ValueError, match="infinite"):
        whiten_ar1(np.array([1.0, np.inf, 2.0]), 0.5)


@pytest.mark.parametrize("kwargs, match", [
    (dict(level=1.0), "level"),
    (dict(level=0), "level"),
    (dict(min_pairs=3.5), "min_pairs"),
    (dict(mask=np.zeros((100, 2), dtype=int)), "boolean"),
    (dict(mask=np.zeros((99, 2), dtype=bool)), "shape"),
    (dict(names=["a"]), "names"),
])
def test_bad_arguments(kwargs, match):
    x, _ = simulate([0.5, 0.5], 100, 0)
    with pytest.raises(ValueError, match=match):
        fit_ar1(x, **kwargs)


def test_bad_shapes():
    with pytest.raises(ValueError, match="shape"):
        fit_ar1(np.zeros((10, 2, 2)))
    with pytest.raises(ValueError, match="one value per channel"):
        whiten_ar1(np.zeros((10, 3)), [0.1, 0.2])
    with pytest.raises(ValueError, match="finite"):
        whiten_ar1(np.zeros((10, 2)), [0.1, np.nan])
    with pytest.raises(ValueError, match="max_lag"):
        autocorrelation(np.zeros(10), 0)


def test_non_stationary_fit_reports_infinite_stationary_variance():
    x = 1.02 ** np.arange(200.0)                         # exponential growth: psi > 1
    fit = fit_ar1(x)
    assert fit.psi[0] > 1.0
    assert np.isinf(fit.stationary_variance[0])
    assert isinstance(fit, Ar1Fit) and fit.as_dict()["n_pairs"] == [199]
