"""The particle filter's in-kernel normals (filters/_normals.py: SplitMix64 + a 256-layer
ziggurat) and the resampling jitter that draws them (pf_jitter_drawn)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

import mixnav.filters._pf_kernels as K
from mixnav.filters._normals import LAYERS, R, fill_standard_normal, ziggurat_tables


def test_ziggurat_layers_have_equal_areas_and_close_at_the_top():
    X, F, Kb, _ = ziggurat_tables()
    v = R * math.exp(-0.5 * R * R) + math.sqrt(0.5 * math.pi) * math.erfc(R / math.sqrt(2.0))
    assert X[0] * F[1] == pytest.approx(v, rel=1e-12)          # the base layer as a rectangle
    areas = X[1:LAYERS] * (F[2:] - F[1:LAYERS])
    np.testing.assert_allclose(areas, v, rtol=1e-9)           # the recursion's layers, the top one included:
    assert F[LAYERS] == 1.0 and X[LAYERS - 1] > 0.0            # only the right R closes the top at f = 1
    assert np.all(np.diff(X[1:]) < 0)
    assert np.all(Kb[1:] < 2 ** 52) and Kb[LAYERS - 1] == 0    # the top layer is all wedge


def test_normals_match_the_standard_normal():
    z = np.empty(2_000_000)
    fill_standard_normal(np.uint64(20240611), z)
    # a fixed seed, so no flakiness; a wrong table or wedge test moves the KS distance past
    # ~1.9 / sqrt(n) = 1.3e-3 (p = 0.0015)
    assert stats.kstest(z, "norm").pvalue > 2e-3
    n = z.size
    assert abs(z.mean()) < 5 / math.sqrt(n)
    assert abs(z.var() - 1.0) < 5 * math.sqrt(2.0 / n)
    for c in (1.0, R, 4.5):          # a body point, the tail branch's start, deep in the tail
        p = 2 * stats.norm.sf(c)
        assert abs(np.mean(np.abs(z) > c) - p) < 5 * math.sqrt(p * (1 - p) / n)
    assert abs(np.mean(z > 0) - 0.5) < 5 * math.sqrt(0.25 / n)   # the sign bit
    # neighbouring draws uncorrelated (the stream's successive outputs)
    assert abs(np.corrcoef(z[:-1], z[1:])[0, 1]) < 5 / math.sqrt(n)


def test_streams_are_reproducible_and_distinct():
    a, b, c = np.empty(1000), np.empty(1000), np.empty(1000)
    fill_standard_normal(np.uint64(7), a)
    fill_standard_normal(np.uint64(7), b)
    fill_standard_normal(np.uint64(8), c)
    assert np.array_equal(a, b)
    assert abs(np.corrcoef(a, c)[0, 1]) < 0.15


def _cloud(N=3000, n=6, seed=3):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    P = A @ A.T + n * np.eye(n)
    D = rng.standard_normal((N, n)) @ np.linalg.cholesky(P).T
    w = rng.random(N)
    w /= w.sum()
    idx = np.empty(N, dtype=np.int64)
    K.pf_systematic(w, 0.37, idx)
    x = w @ D
    Pw = (D - x).T @ ((D - x) * w[:, None])
    return D, idx, x, Pw, rng


@pytest.mark.parametrize("threads", [1, 2])
def test_jitter_drawn_is_the_jitter_of_its_normals_on_any_thread_count(threads):
    import numba
    D, idx, x, Pw, rng = _cloud()
    N, n = D.shape
    h = 0.9
    hL = h * np.linalg.cholesky(Pw)
    seeds = rng.integers(0, 2 ** 64, size=K.CHUNKS, dtype=np.uint64)
    ZT, Dn = np.empty((n, N)), np.empty((N, n))
    K.pf_jitter_drawn_serial(D, idx, math.sqrt(1 - h * h), h, x, hL, seeds, ZT, Dn)
    ref = np.empty((N, n))
    K.pf_jitter_serial(D, idx, math.sqrt(1 - h * h), h, x, hL, ZT, ref)
    assert np.array_equal(Dn, ref)
    for c in range(K.CHUNKS):           # chunk c's normals are its own stream's
        j0, j1 = c * N // K.CHUNKS, (c + 1) * N // K.CHUNKS
        z = np.empty((n, j1 - j0))
        fill_standard_normal(seeds[c], z)
        assert np.array_equal(ZT[:, j0:j1], z)
    old = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        ZT2, Dn2 = np.empty((n, N)), np.empty((N, n))
        K.pf_jitter_drawn(D, idx, math.sqrt(1 - h * h), h, x, hL, seeds, ZT2, Dn2)
    finally:
        numba.set_num_threads(old)
    assert np.array_equal(Dn2, Dn)


def test_jitter_drawn_without_roughening_is_the_plain_copy_and_draws_nothing():
    D, idx, x, _, _ = _cloud()
    N, n = D.shape
    ZT = np.full((n, N), 7.0)
    Dn = np.empty((N, n))
    K.pf_jitter_drawn_serial(D, idx, 1.0, 0.0, x, np.eye(n), np.zeros(K.CHUNKS, np.uint64), ZT, Dn)
    assert np.array_equal(Dn, D[idx])
    assert np.all(ZT == 7.0)


def test_liu_west_jitter_keeps_mean_and_covariance():
    """Liu & West (2001): with the cloud's own weighted mean x and covariance L L^T, the
    jittered resampled cloud ``a D[idx] + (1 - a) x + h L z`` has, in expectation, the same
    mean and covariance; a stream with correlated or non-unit normals would not."""
    D, idx, x, Pw, rng = _cloud(N=40000, n=4)
    N, n = D.shape
    h = 0.9
    seeds = rng.integers(0, 2 ** 64, size=K.CHUNKS, dtype=np.uint64)
    Dn = np.empty((N, n))
    K.pf_jitter_drawn_serial(D, idx, math.sqrt(1 - h * h), h, x, h * np.linalg.cholesky(Pw), seeds,
                             np.empty((n, N)), Dn)
    sd = np.sqrt(np.diag(Pw))
    # the resampling's own noise dominates: tolerances of ~6 standard errors of N draws
    assert np.all(np.abs(Dn.mean(axis=0) - x) < 6 * sd / math.sqrt(N))
    C = np.cov(Dn.T)
    corr_err = (C - Pw) / np.outer(sd, sd)
    assert np.max(np.abs(corr_err)) < 6 * math.sqrt(2.0 / N)


def test_linear_step_drawn_is_the_linear_step_of_its_normals_on_any_thread_count():
    import numba
    rng = np.random.default_rng(5)
    N, n = 1001, 4
    D = rng.standard_normal((N, n))
    FT = rng.standard_normal((n, n))
    SQT = np.ascontiguousarray(np.linalg.cholesky(np.eye(n) + 0.3).T)   # C order, as the filter passes it (no extra compile)
    seeds = rng.integers(0, 2 ** 64, size=K.CHUNKS, dtype=np.uint64)
    Z, Dn = np.empty((N, n)), np.empty((N, n))
    K.pf_linear_step_drawn_serial(D, FT, SQT, seeds, Z, Dn)
    ref = np.empty((N, n))
    K.pf_linear_step_serial(D, FT, SQT, Z, ref)
    assert np.array_equal(Dn, ref)
    for c in range(K.CHUNKS):           # chunk c's rows are its own stream's, row by row
        j0, j1 = c * N // K.CHUNKS, (c + 1) * N // K.CHUNKS
        z = np.empty((j1 - j0, n))
        fill_standard_normal(seeds[c], z)
        assert np.array_equal(Z[j0:j1], z)
    old = numba.get_num_threads()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    try:
        Dn2 = np.empty((N, n))
        K.pf_linear_step_drawn(D, FT, SQT, seeds, np.empty((N, n)), Dn2)
    finally:
        numba.set_num_threads(old)
    assert np.array_equal(Dn2, Dn)
