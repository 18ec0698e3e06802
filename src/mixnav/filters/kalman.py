"""The Kalman correction as a pure, compiled function.

``kalman_update`` is shared by every Kalman-type filter in mixnav. It never
forms an explicit inverse: the innovation covariance is Cholesky-factored,
the gain comes from triangular solves, and the covariance update uses the
Joseph form, which keeps P symmetric positive semi-definite under round-off.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Status codes returned by :func:`kalman_update`.
OK = 0
S_NOT_POSITIVE_DEFINITE = 1


@njit(cache=True)
def cholesky_lower(a, out):
    """Cholesky factor of a symmetric matrix into ``out``; False if not PD."""
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
def _solve_lower(L, b):
    """Solve ``L y = b`` for each column of ``b`` (in place)."""
    m = L.shape[0]
    for c in range(b.shape[1]):
        for i in range(m):
            s = b[i, c]
            for k in range(i):
                s -= L[i, k] * b[k, c]
            b[i, c] = s / L[i, i]


@njit(cache=True)
def _solve_upper_t(L, b):
    """Solve ``L^T y = b`` for each column of ``b`` (in place)."""
    m = L.shape[0]
    for c in range(b.shape[1]):
        for i in range(m - 1, -1, -1):
            s = b[i, c]
            for k in range(i + 1, m):
                s -= L[k, i] * b[k, c]
            b[i, c] = s / L[i, i]


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
        Normalised innovation squared ``z^T S^-1 z``.
    status : int
        :data:`OK`, or :data:`S_NOT_POSITIVE_DEFINITE` in which case the
        prior is returned unchanged (the caller counts a rejected epoch).
    """
    n = P.shape[0]
    m = z.shape[0]
    PHt = P @ H.T
    S = H @ PHt + R
    L = np.empty((m, m))
    if not cholesky_lower(S, L):
        return x.copy(), P.copy(), np.inf, S_NOT_POSITIVE_DEFINITE
    # K^T = S^-1 (P H^T)^T, via L L^T.
    Kt = PHt.T.copy()
    _solve_lower(L, Kt)
    _solve_upper_t(L, Kt)
    y = z - H @ x
    w = y.reshape(m, 1).copy()
    _solve_lower(L, w)
    nis = 0.0
    for i in range(m):
        nis += w[i, 0] * w[i, 0]
    K = Kt.T
    x_post = x + K @ y
    IKH = -K @ H
    for i in range(n):
        IKH[i, i] += 1.0
    P_post = IKH @ P @ IKH.T + K @ R @ K.T
    P_post = 0.5 * (P_post + P_post.T)
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
