"""Small dense linear-algebra kernels shared by the filters and the learners (numba).

Hand-written because numba's ``np.linalg`` calls LAPACK per call with an
allocation each, which for the 3x3 to 20x20 matrices of a GNSS epoch or a
mixture component costs more than the arithmetic (measured in
filters/kalman.py: 11 us -> 4 us per update).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def cholesky_lower(a, out):
    """Lower Cholesky factor ``out out^T = a`` of a symmetric matrix, written into ``out``.

    Returns False (``out`` partly written) if ``a`` is not numerically positive definite.
    """
    m = a.shape[0]
    for j in range(m):
        s = a[j, j]
        for k in range(j):
            s -= out[j, k] * out[j, k]
        if not (s > 0.0):
            return False
        d = math.sqrt(s)
        out[j, j] = d
        for i in range(j + 1, m):
            s = a[i, j]
            for k in range(j):
                s -= out[i, k] * out[j, k]
            out[i, j] = s / d
        for i in range(j):
            out[i, j] = 0.0
    return True


@njit(cache=True)
def tril_inv(L, Li):
    """Inverse ``Li`` of a lower-triangular ``L`` (also lower triangular)."""
    d = L.shape[0]
    for j in range(d):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, d):
            s = 0.0
            for p in range(j, i):
                s -= L[i, p] * Li[p, j]
            Li[i, j] = s / L[i, i]
        for i in range(j):
            Li[i, j] = 0.0


@njit(cache=True)
def ar1_recursion(w, a, x0):
    """``y_k = a y_{k-1} + w_k`` per column, ``y_{-1} = x0``: (n, c) from ``w`` (n, c),
    ``a`` (c,), ``x0`` (c,).

    The same operations as ``scipy.signal.lfilter([1], [1, -a], w, axis=0, zi=a x0)``
    (equal bitwise, tested), without importing scipy.signal (half a second at start-up).
    """
    n, c = w.shape
    y = np.empty((n, c))
    for j in range(c):
        prev = x0[j]
        aj = a[j]
        for k in range(n):
            prev = w[k, j] + aj * prev
            y[k, j] = prev
    return y
