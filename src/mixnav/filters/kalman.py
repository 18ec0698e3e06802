"""The Kalman correction as a pure, compiled function.

``kalman_update`` is shared by every Kalman-type filter in mixnav. It never
forms an explicit inverse: the innovation covariance is Cholesky-factored,
the gain comes from triangular solves, and the covariance update uses the
Joseph form, which keeps P symmetric positive semi-definite under round-off.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Status codes returned by :func:`kalman_update`.
from ..engine.status import OK, S_NOT_POSITIVE_DEFINITE  # noqa: E402,F401
from ..linalg import cholesky_lower  # noqa: E402,F401  (re-exported: the bank kernels use it)


@njit(cache=True)
def _solve_lower(L, b):
    """Solve ``L y = b`` for each column of ``b`` (in place).

    Row-oriented: the innermost loop runs along a row of ``b`` (contiguous),
    which numba vectorises; column by column it strides and costs 2-3x more
    for the (m, 17) right-hand sides of a GNSS epoch.
    """
    m = L.shape[0]
    nc = b.shape[1]
    for i in range(m):
        for k in range(i):
            lik = L[i, k]
            for c in range(nc):
                b[i, c] -= lik * b[k, c]
        d = 1.0 / L[i, i]
        for c in range(nc):
            b[i, c] *= d


@njit(cache=True)
def _solve_upper_t(L, b):
    """Solve ``L^T y = b`` for each column of ``b`` (in place), row-oriented."""
    m = L.shape[0]
    nc = b.shape[1]
    for i in range(m - 1, -1, -1):
        for k in range(i + 1, m):
            lki = L[k, i]
            for c in range(nc):
                b[i, c] -= lki * b[k, c]
        d = 1.0 / L[i, i]
        for c in range(nc):
            b[i, c] *= d


@njit(cache=True)
def sparse_left_product(H, P):
    """``H P`` (m, n) skipping the zeros of ``H`` (a measurement Jacobian is mostly zeros)."""
    m, n = H.shape
    HP = np.zeros((m, P.shape[1]))
    for i in range(m):
        for k in range(n):
            h = H[i, k]
            if h != 0.0:
                for j in range(P.shape[1]):
                    HP[i, j] += h * P[k, j]
    return HP


@njit(cache=True)
def kalman_update(x, P, z, H, R):
    """Kalman measurement update, Joseph form.

    Parameters
    ----------
    x : ndarray (n,)
        Prior state (the error state is zero in closed loop).
    P : ndarray (n, n)
        Prior covariance.
    z : ndarray (m,)
        Measurement of the linear model ``z = H x + v``; for an error-state
        filter in closed loop (``x = 0``) this is the innovation.
    H : ndarray (m, n)
    R : ndarray (m, m)

    Returns
    -------
    x_post : ndarray (n,)
    P_post : ndarray (n, n)
    nis : float
        Normalised innovation squared ``y^T S^-1 y``, ``y = z - H x``.
    status : int
        :data:`OK`, or :data:`S_NOT_POSITIVE_DEFINITE` in which case the
        prior is returned unchanged (the caller counts a rejected epoch).

    Notes
    -----
    Written as loops rather than ``@`` because numba's matmul of 15x6
    matrices pays a BLAS call and an allocation each (11 us -> 4 us here).
    The Joseph form is factored as ``A = P - K (H P)``,
    ``P+ = A - (A H^T) K^T + K R K^T``, which equals
    ``(I - K H) P (I - K H)^T + K R K^T`` and costs O(n^2 m).
    """
    n = P.shape[0]
    m = z.shape[0]
    HP = sparse_left_product(H, P)  # H P; (P H^T) = HP^T since P is symmetric
    S = R.copy()
    diag_r = True  # a diagonal R (independent measurements, the common case) saves O(n m^2)
    for i in range(m):
        for j in range(i + 1, m):
            if R[i, j] != 0.0 or R[j, i] != 0.0:
                diag_r = False
        for j in range(m):
            s = 0.0
            for k in range(n):
                s += HP[i, k] * H[j, k]
            S[i, j] += s
    L = np.empty((m, m))
    if not cholesky_lower(S, L):
        return x.copy(), P.copy(), np.inf, S_NOT_POSITIVE_DEFINITE
    # K^T = S^-1 (H P), via L L^T.
    Kt = HP.copy()
    _solve_lower(L, Kt)
    _solve_upper_t(L, Kt)
    y = z.copy()
    for i in range(m):
        for k in range(n):
            y[i] -= H[i, k] * x[k]
    w = y.reshape(m, 1).copy()
    _solve_lower(L, w)
    nis = 0.0
    for i in range(m):
        nis += w[i, 0] * w[i, 0]
    x_post = x.copy()
    for k in range(n):
        for i in range(m):
            x_post[k] += Kt[i, k] * y[i]
    # A = P - K (H P)
    A = P.copy()
    for i in range(n):
        for c in range(m):
            kc = Kt[c, i]
            for j in range(n):
                A[i, j] -= kc * HP[c, j]
    # B = A H^T  (n x m)
    B = np.zeros((n, m))
    for i in range(n):
        for c in range(m):
            s = 0.0
            for k in range(n):  # no zero test: a branch stops vectorisation
                s += A[i, k] * H[c, k]
            B[i, c] = s
    # KR = K R  (n x m)
    KR = np.zeros((n, m))
    for i in range(n):
        for c in range(m):
            if diag_r:
                KR[i, c] = Kt[c, i] * R[c, c]
            else:
                s = 0.0
                for d in range(m):
                    s += Kt[d, i] * R[d, c]
                KR[i, c] = s
    P_post = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            s = A[i, j]
            for c in range(m):
                s += (KR[i, c] - B[i, c]) * Kt[c, j]
            P_post[i, j] = s
    # symmetrise from the upper triangle (the lower one carries the same
    # value up to round-off)
    for i in range(n):
        for j in range(i):
            P_post[i, j] = P_post[j, i]
    return x_post, P_post, nis, OK


@njit(cache=True)
def innovation_is_absurd(z, H, P, r_diag, n_sigma):
    """True when any innovation exceeds ``n_sigma`` of its own predicted sigma.

    ``sqrt((H P H^T)_ii + R_ii)`` is the predicted sigma of component i; a
    non-finite innovation is absurd too.
    """
    m, n = H.shape
    for i in range(m):
        if not np.isfinite(z[i]):
            return True
        s = r_diag[i]
        for a in range(n):
            if H[i, a] != 0.0:
                acc = 0.0
                for b in range(n):
                    acc += P[a, b] * H[i, b]
                s += H[i, a] * acc
        if z[i] * z[i] > n_sigma * n_sigma * s:
            return True
    return False


@njit(cache=True)
def innovation_logdet(P, H, r):
    """``log det S``, ``S = H P H^T + R`` (``r``: the variances (m,) or R (m, m)), by a
    Cholesky factor of ``S``; NaN when ``S`` is not positive definite.

    Compiled because the tuning criterion asks for it at every correction: numpy's
    ``slogdet`` of the same product was a fifth of a tuning run, its Python calls, not the
    arithmetic (m <= 6 rows here). ``H`` is mostly zeros: its zero entries are skipped."""
    m, n = H.shape
    HP = sparse_left_product(H, P)
    S = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            acc = 0.0
            for k in range(n):
                if H[j, k] != 0.0:
                    acc += HP[i, k] * H[j, k]
            if r.ndim == 1:
                if i == j:
                    acc += r[i]
            else:
                acc += 0.5 * (r[i, j] + r[j, i])
            S[i, j] = acc
    L = np.empty((m, m))
    if not cholesky_lower(S, L):      # reads the lower triangle filled above
        return np.nan
    out = 0.0
    for j in range(m):
        out += 2.0 * np.log(L[j, j])
    return out
