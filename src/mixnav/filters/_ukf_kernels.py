"""Compiled kernels of the unscented filters (numba, ``cache=True``).

- :func:`ukf_sigma`: the sigma points of ``N(x, P)`` as error states (Cholesky
  and the scaled deviations); the motion model turns them into full states,
  propagates them and differences them back (``motion.propagate_members``,
  ``motion.member_states``: the ensemble seam, :mod:`mixnav.engine.protocols`);
- :func:`ukf_moments`: the weighted mean and covariance of the propagated
  points plus ``Qd``;
- :func:`measurement_moments`: predicted measurement mean, ``Pyy`` and ``Pxy``
  of the sigma points;
- :func:`vb_correct`: the (variational-Bayes adaptive) Kalman correction from
  those moments, shared by the UKF, the VB-AUKF and the VB-AKF.

Nothing here knows the motion model: the error state is whatever the run's
layout says, and the maps between error states and full states are the motion
model's (for the strapdown INS :mod:`mixnav.ins._batch_kernels`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..engine.status import ABSURD, NEEDS_REPAIR, NON_FINITE, OK, S_NOT_POSITIVE_DEFINITE
from ..linalg import cholesky_lower


@njit(cache=True)
def sigma_deviations(x, L, c, D):
    """``D[0] = x``, ``D[1 + k] = x + c L[:, k]``, ``D[1 + n + k] = x - c L[:, k]``
    (the 2n + 1 scaled sigma points of N(x, L L^T) as error states)."""
    n = x.shape[0]
    for i in range(n):
        D[0, i] = x[i]
    for k in range(n):
        for i in range(n):
            d = c * L[i, k]
            D[1 + k, i] = x[i] + d
            D[1 + n + k, i] = x[i] - d


@njit(cache=True)
def weighted_moments(D, wm, wc, x, P):
    """``x = sum_j wm_j D_j``, ``P = sum_j wc_j (D_j - x)(D_j - x)^T`` (written into x, P)."""
    N, n = D.shape
    for i in range(n):
        s = 0.0
        for j in range(N):
            s += wm[j] * D[j, i]
        x[i] = s
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            xa, xb = x[a], x[b]
            for j in range(N):
                s += wc[j] * (D[j, a] - xa) * (D[j, b] - xb)
            P[a, b] = s
            P[b, a] = s


@njit(cache=True)
def ukf_sigma(x, P, c, L, D):
    """The ``2n + 1`` sigma points of ``N(x, P)`` as error states into ``D`` (2n+1, n)
    (``L`` (n, n) scratch: the Cholesky factor). False (nothing written to ``D``) when
    ``P`` is not positive definite."""
    if not cholesky_lower(P, L):
        return False
    sigma_deviations(x, L, c, D)
    return True


@njit(cache=True)
def ukf_moments(Dn, wm, wc, Qd, x_out, P_out):
    """The prediction from the propagated sigma points ``Dn`` (2n+1, n): ``x_out`` their
    weighted mean, ``P_out = sum wc (Dn - x)(Dn - x)^T + Qd`` (additive process noise)."""
    n = x_out.shape[0]
    weighted_moments(Dn, wm, wc, x_out, P_out)
    for a in range(n):
        for b in range(n):
            P_out[a, b] += Qd[a, b]


@njit(cache=True)
def measurement_moments(D, Y, y, wm, wc):
    """``(innovation y - E[Y], Pyy, Pxy)`` of the sigma points ``D`` (N, n) and their
    predictions ``Y`` (N, m)."""
    N, n = D.shape
    m = Y.shape[1]
    ym = np.zeros(m)
    xm = np.zeros(n)
    for j in range(N):
        for i in range(m):
            ym[i] += wm[j] * Y[j, i]
        for i in range(n):
            xm[i] += wm[j] * D[j, i]
    Pyy = np.zeros((m, m))
    Pxy = np.zeros((n, m))
    dy = np.empty(m)
    for j in range(N):
        w = wc[j]
        for i in range(m):
            dy[i] = Y[j, i] - ym[i]
        for a in range(m):
            for b in range(m):
                Pyy[a, b] += w * dy[a] * dy[b]
        for a in range(n):
            da = w * (D[j, a] - xm[a])
            for b in range(m):
                Pxy[a, b] += da * dy[b]
    innov = np.empty(m)
    for i in range(m):
        innov[i] = y[i] - ym[i]
    return innov, Pyy, Pxy


@njit(cache=True)
def _forward(L, B, out):
    """``out = L^-1 B`` (L lower triangular (m, m), B (m, k))."""
    m, k = B.shape
    for col in range(k):
        for i in range(m):
            s = B[i, col]
            for p in range(i):
                s -= L[i, p] * out[p, col]
            out[i, col] = s / L[i, i]


@njit(cache=True)
def linearized_pyy(L, Pxy):
    """``G = Pxy^T P^-1 Pxy`` (m, m) from ``L`` (the lower Cholesky factor of ``P``): the
    statistically linearised ``H P H^T``; the VB step's posterior residual moments
    use it (exactly ``H P H^T`` for a linear ``h``)."""
    n, m = Pxy.shape
    V = np.empty((n, m))
    _forward(L, Pxy, V)
    G = np.zeros((m, m))
    for a in range(m):
        for b in range(m):
            s = 0.0
            for i in range(n):
                s += V[i, a] * V[i, b]
            G[a, b] = s
    return G


@njit(cache=True)
def vb_correct(x, P, Pxy, Pyy, G, innov, r, alpha0, beta0, vb, iterations, tol, n_sigma):
    """One Kalman correction from the moments; with ``vb`` the variational-Bayes
    noise adaptation of Sarkka & Nummenmaa (2009) per row.

    Parameters
    ----------
    x, P : ndarray (n,), (n, n)
        Prior mean and covariance (not modified).
    Pxy, Pyy : ndarray (n, m), (m, m)
        Cross and measurement covariances of the prior (``P H^T``, ``H P H^T``
        for a linear model).
    G : ndarray (m, m)
        ``Pxy^T P^-1 Pxy`` (see :func:`linearized_pyy`); used only with ``vb``.
    innov : ndarray (m,)
        ``y - E[h(x)]`` under the prior.
    r : ndarray (m,)
        Noise variances (without ``vb``).
    alpha0, beta0 : ndarray (m,)
        Predicted inverse-Gamma parameters per row (with ``vb``).
    vb : bool
    iterations : int
        At most this many fixed-point iterations (``vb``).
    tol : float
        Stop when no row's variance ``beta / alpha`` changes by more than ``tol``
        relative.
    n_sigma : float
        Absurd-innovation gate in predicted sigmas (with the prior variance).

    Returns
    -------
    x_post, P_post, nis, status, alpha, beta, used_iterations
        With ``vb``: ``alpha = alpha0 + 1/2``, ``beta = beta0 + (e^2 + (H P+ H^T)_ii) / 2``
        at the fixed point (``e`` the posterior residual). Rejected: the prior.
    """
    n = x.shape[0]
    m = innov.shape[0]
    alpha = alpha0.copy()
    beta = beta0.copy()
    R = np.empty(m)
    if vb:
        for i in range(m):
            alpha[i] = alpha0[i] + 0.5
            R[i] = beta0[i] / alpha[i]
    else:
        for i in range(m):
            R[i] = r[i]
    for i in range(m):  # the gate, with the prior noise level
        if not np.isfinite(innov[i]):
            return x, P, np.inf, ABSURD, alpha0, beta0, 0
        if innov[i] * innov[i] > n_sigma * n_sigma * (Pyy[i, i] + R[i]):
            return x, P, np.inf, ABSURD, alpha0, beta0, 0
    S = np.empty((m, m))
    Ls = np.empty((m, m))
    W = np.empty((m, n))
    PxyT = np.ascontiguousarray(Pxy.T)
    u = np.empty((m, 1))
    iv = np.empty((m, 1))
    for i in range(m):
        iv[i, 0] = innov[i]
    U = np.empty((m, m))
    it = 0
    n_iter = max(iterations, 1) if vb else 1
    # Sarkka & Nummenmaa (2009), algorithm 1: per pass (1) the state with R = beta / alpha,
    # (2) beta from that posterior; the state returned is the last pass's (1).
    while it < n_iter:
        for a in range(m):
            for b in range(m):
                S[a, b] = Pyy[a, b]
            S[a, a] += R[a]
        if not cholesky_lower(S, Ls):
            return x, P, np.inf, S_NOT_POSITIVE_DEFINITE, alpha0, beta0, it
        _forward(Ls, iv, u)        # u = Ls^-1 innov
        it += 1
        if not vb:
            break
        # posterior residual moments (statistical linearisation): e = innov - G S^-1 innov,
        # its variance diag(G - G S^-1 G)
        _forward(Ls, G, U)         # U = Ls^-1 G
        change = 0.0
        for i in range(m):
            gsi = 0.0
            gsg = 0.0
            for k in range(m):
                gsi += U[k, i] * u[k, 0]
                gsg += U[k, i] * U[k, i]
            e = innov[i] - gsi
            beta[i] = beta0[i] + 0.5 * (e * e + max(G[i, i] - gsg, 0.0))
            r_new = beta[i] / alpha[i]
            d = abs(r_new - R[i]) / R[i]
            if d > change:
                change = d
            R[i] = r_new
        if change <= tol:
            break
    _forward(Ls, PxyT, W)          # W = Ls^-1 Pxy^T  (m, n)
    x_post = np.empty(n)
    P_post = np.empty((n, n))
    nis = 0.0
    for k in range(m):
        nis += u[k, 0] * u[k, 0]
    for i in range(n):
        s = x[i]
        for k in range(m):
            s += W[k, i] * u[k, 0]
        x_post[i] = s
    for a in range(n):
        for b in range(a, n):
            s = P[a, b]
            for k in range(m):
                s -= W[k, a] * W[k, b]
            P_post[a, b] = s
            P_post[b, a] = s
    for i in range(n):
        if not np.isfinite(x_post[i]):
            return x, P, nis, NON_FINITE, alpha0, beta0, it
        for j in range(n):
            if not np.isfinite(P_post[i, j]):
                return x, P, nis, NON_FINITE, alpha0, beta0, it
    for i in range(n):
        if P_post[i, i] <= 0.0:
            return x_post, P_post, nis, NEEDS_REPAIR, alpha, beta, it
    return x_post, P_post, nis, OK, alpha, beta, it
