"""Compiled IMM cycle: mixing and the modes' predictive log-likelihoods in one call, and
for modes that are plain Kalman filters the whole epoch and prediction of all modes.

In numpy the two cost ~140 us per epoch for two 21-state modes (einsum, Cholesky and
solve calls with an allocation each), seven times an EKF epoch; here they cost a few
microseconds (benchmarks/results/imm.md). :mod:`mixnav.filters.imm` keeps the numpy
formulas (``mix``, ``log_likelihood``) as the readable reference the tests compare with.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..engine.status import NEEDS_REPAIR, OK
from ..ins._error_kernels import covariance_predict
from ..linalg import cholesky_lower
from ._ekf_kernels import kalman_correct

_LOG_2PI = math.log(2.0 * math.pi)


@njit(cache=True)
def imm_mix_score(mu, Pi, xs, Ps, z, H, R, x0, P0, logl):
    """Mix the modes and score the epoch's rows under each mixed mode.

    ``mu`` (r,), ``Pi`` (r, r), ``xs`` (r, n), ``Ps`` (r, n, n); ``z`` (m,), ``H`` (m, n),
    ``R`` (m, m). Writes the mixed moments into ``x0`` (r, n), ``P0`` (r, n, n) and
    ``log N(z; H x0_j, H P0_j H^T + R)`` into ``logl`` (r,) (-inf when S is not positive
    definite); returns ``c = mu Pi`` (r,). A mode that cannot be entered (``c_j = 0``)
    keeps its moments.
    """
    r, n = xs.shape
    m = z.shape[0]
    c = np.zeros(r)
    for j in range(r):
        for i in range(r):
            c[j] += Pi[i, j] * mu[i]
    w = np.zeros(r)
    d = np.empty(n)
    HP = np.empty((m, n))
    S = np.empty((m, m))
    L = np.empty((m, m))
    y = np.empty(m)
    for j in range(r):
        if c[j] <= 0.0:
            x0[j] = xs[j]
            P0[j] = Ps[j]
        else:
            for i in range(r):
                w[i] = Pi[i, j] * mu[i] / c[j]
            for k in range(n):
                s = 0.0
                for i in range(r):
                    s += w[i] * xs[i, k]
                x0[j, k] = s
            for a in range(n):
                for b in range(n):
                    P0[j, a, b] = 0.0
            for i in range(r):
                wi = w[i]
                if wi == 0.0:
                    continue
                for k in range(n):
                    d[k] = xs[i, k] - x0[j, k]
                for a in range(n):
                    da = wi * d[a]
                    for b in range(n):
                        P0[j, a, b] += wi * Ps[i, a, b] + da * d[b]
        # log-likelihood of the rows under the mixed mode j
        for i in range(m):
            for k in range(n):
                HP[i, k] = 0.0
            for k in range(n):
                h = H[i, k]
                if h != 0.0:
                    for b in range(n):
                        HP[i, b] += h * P0[j, k, b]
        for i in range(m):
            s = z[i]
            for k in range(n):
                s -= H[i, k] * x0[j, k]
            y[i] = s
            for q in range(m):
                t = R[i, q]
                for k in range(n):
                    t += HP[i, k] * H[q, k]
                S[i, q] = t
        if not cholesky_lower(S, L):
            logl[j] = -np.inf
            continue
        quad = 0.0
        logdet = 0.0
        for i in range(m):          # forward substitution L v = y
            s = y[i]
            for k in range(i):
                s -= L[i, k] * y[k]
            y[i] = s / L[i, i]
            quad += y[i] * y[i]
            logdet += 2.0 * math.log(L[i, i])
        logl[j] = -0.5 * (quad + logdet + m * _LOG_2PI)
    return c


@njit(cache=True)
def imm_combine(mu, xs, Ps, P):
    """The combined covariance ``sum_j mu_j (P_j + (x_j - x)(x_j - x)^T)`` into ``P`` (n, n),
    ``x = sum_j mu_j x_j``; returns ``x`` (n,)."""
    r, n = xs.shape
    x = np.zeros(n)
    for j in range(r):
        for k in range(n):
            x[k] += mu[j] * xs[j, k]
    for a in range(n):
        for b in range(n):
            P[a, b] = 0.0
    d = np.empty(n)
    for j in range(r):
        mj = mu[j]
        if mj == 0.0:
            continue
        for k in range(n):
            d[k] = xs[j, k] - x[k]
        for a in range(n):
            da = mj * d[a]
            for b in range(n):
                P[a, b] += mj * Ps[j, a, b] + da * d[b]
    return x


@njit(cache=True)
def imm_probabilities(logl, c, mu):
    """``mu_j ∝ exp(logl_j) c_j`` into ``mu`` (r,) (P4 eq. 14), in log space; returns False,
    with ``mu = c``, when no mode has a finite likelihood."""
    r = c.shape[0]
    best = -np.inf
    for j in range(r):
        a = logl[j] + math.log(max(c[j], 1e-300))
        mu[j] = a
        if a > best:
            best = a
    if not best > -np.inf:
        for j in range(r):
            mu[j] = c[j]
        return False
    s = 0.0
    for j in range(r):
        v = math.exp(mu[j] - best) if mu[j] > -np.inf else 0.0
        mu[j] = v
        s += v
    for j in range(r):
        mu[j] /= s
    return True


@njit(cache=True)
def imm_predict(xs, Ps, phi, qd, tmp):
    """Every mode's ``x <- Phi x``, ``P <- Phi P Phi^T + Qd`` in place (one call for all)."""
    r, n = xs.shape
    x = np.empty(n)
    for j in range(r):
        covariance_predict(Ps[j], phi, qd, tmp)
        for i in range(n):
            s = 0.0
            for k in range(n):
                f = phi[i, k]
                if f != 0.0:
                    s += f * xs[j, k]
            x[i] = s
        for i in range(n):
            xs[j, i] = x[i]


@njit(cache=True)
def imm_epoch(mu, Pi, xs, Ps, z, H, r, users, n_sigma, x0, P0, logl, status, nis):
    """One IMM cycle up to the probabilities for modes that are plain Kalman filters:
    :func:`imm_mix_score`, then the gated Kalman update (:func:`kalman_correct` about each
    mixed mean) of the modes with ``users[j]``; the modes' new moments are written into
    ``xs``, ``Ps`` (in place), each mode's update status into ``status`` (-1: not updated)
    and NIS into ``nis``. ``r`` (m,) variances or (m, m). Returns ``c = mu Pi``."""
    if r.ndim == 1:
        R = np.diag(r)
    else:
        R = r
    c = imm_mix_score(mu, Pi, xs, Ps, z, H, R, x0, P0, logl)
    nm, n = xs.shape
    m = z.shape[0]
    y = np.empty(m)
    for j in range(nm):
        status[j] = -1
        nis[j] = np.inf
        if users[j]:
            for i in range(m):
                s = z[i]
                for k in range(n):
                    s -= H[i, k] * x0[j, k]
                y[i] = s
            P_post, dx, nj, st = kalman_correct(P0[j], y, H, R, n_sigma)
            status[j] = st
            nis[j] = nj
            if st == OK or st == NEEDS_REPAIR:
                for k in range(n):
                    x0[j, k] += dx[k]
                P0[j] = P_post
    xs[:, :] = x0
    Ps[:, :, :] = P0
    return c
