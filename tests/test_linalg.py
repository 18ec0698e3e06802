"""Shared kernels of mixnav.linalg against numpy/scipy."""

import numpy as np
import pytest
from scipy.signal import lfilter

from mixnav.linalg import ar1_recursion, cholesky_lower, tril_inv


def test_ar1_recursion_is_lfilter_bitwise():
    """The recursion replaces scipy.signal.lfilter in the simulators (same operations):
    the simulated noise, hence every stored reference result, is unchanged."""
    rng = np.random.default_rng(0)
    w = rng.standard_normal((5000, 3))
    a = np.array([0.999, -0.5, 0.0])
    x0 = rng.standard_normal(3)
    ours = ar1_recursion(w, a, x0)
    for j in range(3):
        ref, _ = lfilter([1.0], [1.0, -a[j]], w[:, j], zi=[a[j] * x0[j]])
        np.testing.assert_array_equal(ours[:, j], ref)
    same, _ = lfilter([1.0], [1.0, -0.9], w, axis=0, zi=(0.9 * x0)[None, :])
    np.testing.assert_array_equal(ar1_recursion(w, np.full(3, 0.9), x0), same)


@pytest.mark.parametrize("d", [1, 3, 7])
def test_cholesky_and_triangular_inverse(d):
    rng = np.random.default_rng(d)
    A = rng.standard_normal((d, d))
    A = A @ A.T + d * np.eye(d)
    L = np.empty((d, d))
    assert cholesky_lower(A, L)
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-12, atol=1e-14)
    Li = np.empty((d, d))
    tril_inv(L, Li)
    np.testing.assert_allclose(Li @ L, np.eye(d), atol=1e-12)
    assert not cholesky_lower(-A, L)
