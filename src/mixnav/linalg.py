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


# --- fixed-chunk reductions over particles (the particle filters' kernels, filters/ and ins/) ---

#: the fixed number of partial sums of a reduction over particles (thread-count independent)
CHUNKS = 16


@njit(cache=True)
def heaviest(w):
    """The index of the largest weight (the first, if tied)."""
    k0 = 0
    for j in range(w.shape[0]):
        if w[j] > w[k0]:
            k0 = j
    return k0


@njit(cache=True)
def innovation_nis(y, ym, Pyy, r):
    """``e^T (Pyy + diag r)^-1 e``, ``e = y - ym`` (Cholesky); inf when not finite or not
    positive definite."""
    m = y.shape[0]
    S = np.empty((m, m))
    L = np.empty((m, m))
    for i in range(m):
        for k in range(m):
            S[i, k] = Pyy[i, k]
        S[i, i] += r[i]
    if not cholesky_lower(S, L):
        return np.inf
    nis = 0.0
    u = np.empty(m)
    for i in range(m):
        s = y[i] - ym[i]
        for k in range(i):
            s -= L[i, k] * u[k]
        u[i] = s / L[i, i]
        nis += u[i] * u[i]
    return nis if np.isfinite(nis) else np.inf


@njit(cache=True)
def sum_chunked_cov(part, P):
    """``P`` (n, n): the symmetric sum of the :data:`CHUNKS` partial covariances in
    ``part[:, n:]`` (row-major upper triangles), added in chunk order."""
    n = P.shape[0]
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            for c in range(CHUNKS):
                s += part[c, n + a * n + b]
            P[a, b] = s
            P[b, a] = s


@njit(cache=True, error_model="numpy", fastmath={"reassoc"})
def chunk_dots_cols(W, E, j0, j1, off, p):
    """``p[off + a n + b] = sum_t W[a, t] E[b, t]`` over ``j0 <= t < j1`` for ``a <= b < n``
    (``n`` the rows of ``W``, state-major arrays).

    Reassociation allowed (``fastmath={"reassoc"}``): the compiler sums each product in
    vector lanes, ~2 x faster than a scalar chain (measured). The order is then the
    compiler's, but fixed by this one compiled function, which both kernel twins call
    (not inlined): the same sums on any thread count."""
    n = W.shape[0]
    for a in range(n):
        wa = W[a, j0:j1]
        for b in range(a, n):
            eb = E[b, j0:j1]
            s = 0.0
            for t in range(j1 - j0):
                s += wa[t] * eb[t]
            p[off + a * n + b] = s
