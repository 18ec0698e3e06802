"""Variational Bayes Gaussian mixture (paper P1 eqs. 10-29; Bishop PRML section 10.2).

Model (P1 eqs. 13-17)::

    pi            ~ Dir(alpha0, ..., alpha0)
    Lambda_k      ~ Wishart(W0, nu0)
    mu_k | Lambda ~ N(m0, (beta0 Lambda_k)^-1)
    z_n | pi      ~ Cat(pi),   x_n | z_n = k ~ N(mu_k, Lambda_k^-1)

Mean-field posterior q(Z) q(pi) prod_k q(mu_k | Lambda_k) q(Lambda_k) (P1 eq. 18)
with q(pi) = Dir(alpha), q(mu_k | Lambda_k) = N(m_k, (beta_k Lambda_k)^-1),
q(Lambda_k) = Wishart(W_k, nu_k).  The iteration alternates the
responsibilities (E-step, P1 eq. 19 with the expectations of eqs. 26-28) and
the posterior parameters (M-step, eqs. 22-25), and stops when the lower bound
(eq. 29) changes by less than ``tol`` per unit sample weight.

Lower bound.  It is evaluated right after each E-step: with q(Z) optimal for
the current q(theta), the three terms of eq. (29) that involve Z collapse to
``sum_n w_n log sum_k rho_nk`` (rho the unnormalised responsibilities of eq. 19),
so the bound is that sum plus the (closed form) difference
``E[ln p(pi, mu, Lambda)] - E[ln q(pi, mu, Lambda)]``.  This is the exact
eq. (29) (with all constants), costs nothing beyond the E-step, and cannot
decrease from one iteration to the next (coordinate ascent).

Sample weights ``w_n`` act as replication counts in every sum over samples.

Pruning.  As soon as (after an M-step) a component's expected weight
``alpha_k / sum(alpha)`` is below ``prune_threshold`` it is removed from
q(theta) and the iteration continues from the remaining posterior (the
largest component is never removed); so the number of components is learned.
Pruning as soon as a weight drops (rather than only after convergence) avoids
hundreds of iterations spent on a dying component.
``lower_bounds_`` restarts its monotone run after each pruning (the model
changes; ``pruned_at_`` lists the indices into ``lower_bounds_`` where a new
run starts) and after each accepted merge (``merged_at_``).

Initialisation.  Hard responsibilities of weighted k-means (greedy k-means++
seeding, then Lloyd iterations; scikit-learn's default for its
BayesianGaussianMixture), or the k-means++ seeding alone (``init="kmeans++"``),
or given ``init_resp``.

Merging.  With K larger than the number of clusters, VB often stops in a local
optimum where one cluster is shared by two components (a "split duplicate"),
neither of which falls below the pruning threshold.  After convergence the
merge moves therefore try, in order of decreasing responsibility overlap
(:func:`_merge_candidates`), to merge a pair: the pair's responsibilities are
added, the posterior is recomputed from them (M-step) and iterated to
convergence (with pruning).  The merge is kept if that converged bound is
higher than the current one; then the candidates are recomputed, until no
candidate raises the bound.

Which bounds are compared.  At q(pi) optimal for q(Z) the Dirichlet terms of
eq. (29) and E[ln p(Z | pi)] sum to ``ln C(alpha0 1_K) - ln C(alpha)``, i.e.
``ln G(K alpha0) - ln G(K alpha0 + N) + sum_k [ln G(alpha_k) - ln G(alpha0)]``
(G the gamma function, N the total sample weight), and a component with no
responsibility has q(mu_k, Lambda_k) = prior, whose Gaussian-Wishart terms are
0.  So a K'-component fit, seen as a K-component fit with K - K' empty
components, has the bound ``L_K' + c(K) - c(K')`` with
``c(K) = ln G(K alpha0) - ln G(K alpha0 + N)``: a fixed amount, but not zero
(about ``-ln(N / (K' - 1))`` per empty component for alpha0 = 1; tested).  The
rule used here compares the bounds of the K'- and (K' - 1)-component models
themselves (``lower_bound_`` after the emptied component is pruned, each model
with its own symmetric Dirichlet prior), as the pruning already does: the
model after pruning is the smaller one.  Comparing within the fixed
K-component model instead (adding ``c(K) - c(K')``) penalises every removed
component by about ln(N / K') nats for alpha0 = 1; measured on two
well-separated 1-D / 2-D mixtures and two 3-sigma-apart pairs (100 seeds each,
n = 2000) it recovered the number of components in 100 / 100 / 97 / 99 % of
seeds against 100 % in all four with the rule used.

Defaults (paper P1 settings): alpha0 = 1, beta0 = 1, nu0 = 1 raised to d when
1 <= d - 1 (the Wishart needs nu0 > d - 1), m0 = the (weighted) data mean,
W0 = 2 I in the units of the data's precision, i.e. ``W0 = 2 inv(Cov(X))``
(the paper's W0 = 2I for data whitened by its covariance; a scalar ``W0=c``
means ``c inv(Cov(X))``; an array (d, d) is used as is).

Data with d <= ``_NUMBA_MAX_DIM`` use a fused numba kernel
(:func:`_vb_loop_nd`): one pass over the samples per iteration does the
E-step, the lower bound and the sufficient statistics of the M-step.  Per
component it computes the Cholesky factor of W_k^-1 and its triangular
inverse; the samples are taken in blocks of ``_BLOCK`` with the loops over the
samples innermost, so that the compiler vectorises them (SIMD): the whitened
distances (written out for d = 1, 2, 3), ``exp`` by a vectorisable polynomial
(:func:`_exp_nonpos`; numba's ``math.exp`` is a scalar call), a stable
log-sum-exp and the weighted first and second moments.  Blocks form chunks of
``_CHUNK`` samples whose partial sums are added in a fixed order, so the
result is the same serial or on numba's threads (``parallel=True``).  The
kernel implements the same arithmetic as the numpy path
:func:`_vb_loop_numpy` (the reference, used for larger d; tested to agree to 1e-10).
"""

from __future__ import annotations

import math
import threading
import warnings

import numba
import numpy as np
from scipy.special import digamma, gammaln, logsumexp

from mixnav._jit import serial_and_parallel
from mixnav.noise.learn import ConvergenceWarning
from mixnav.noise.learn.base import MixtureLearner
from mixnav.noise.learn.em import (check_random_state, check_resp, kmeanspp_resp, validate_data,
                                   validate_weights, weighted_moments)
from mixnav.noise.mixture import GaussianMixture

_LOG2PI = math.log(2.0 * math.pi)
_EPS10 = 10 * np.finfo(float).eps


# --------------------------------------------------------------------------
# numpy core (any dimension)
# --------------------------------------------------------------------------
def _m_step(X, wr, prior):
    """Posterior parameters from weighted responsibilities (P1 eqs. 22-25).

    Returns (alpha (K,), beta (K,), m (K, d), nu (K,), Winv (K, d, d)).
    """
    alpha0, beta0, m0, nu0, W0inv = prior
    nk, xbar, S = weighted_moments(X, wr)
    alpha = alpha0 + nk                                                   # P1 eq. (23)
    beta = beta0 + nk                                                     # P1 eq. (24)
    m = (beta0 * m0[None, :] + nk[:, None] * xbar) / beta[:, None]        # P1 eq. (24)
    nu = nu0 + nk                                                         # P1 eq. (25)
    dm = xbar - m0[None, :]
    Winv = (W0inv[None] + nk[:, None, None] * S                           # P1 eq. (25)
            + (beta0 * nk / (beta0 + nk))[:, None, None] * dm[:, :, None] * dm[:, None, :])
    Winv = 0.5 * (Winv + np.swapaxes(Winv, 1, 2))
    return alpha, beta, m, nu, Winv


def _expectations(params, d):
    """E[ln pi_k] (P1 eq. 28), E[ln|Lambda_k|] (eq. 27), Cholesky of W_k^-1, log|W_k^-1|."""
    alpha, beta, m, nu, Winv = params
    chol = np.linalg.cholesky(Winv)
    logdet_winv = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
    e_ln_pi = digamma(alpha) - digamma(alpha.sum())                                    # P1 eq. (28)
    e_ln_lam = (np.sum(digamma(0.5 * (nu[:, None] - np.arange(d)[None, :])), axis=1)  # P1 eq. (27)
                + d * math.log(2.0) - logdet_winv)
    return e_ln_pi, e_ln_lam, chol, logdet_winv


def _log_wishart_norm(nu, logdet_winv, d):
    """ln B(W, nu) of the Wishart normaliser (PRML B.79), with ln|W| = -ln|W^-1|."""
    j = np.arange(d)
    return (0.5 * nu * logdet_winv - 0.5 * nu * d * math.log(2.0) - 0.25 * d * (d - 1) * math.log(math.pi)
            - np.sum(gammaln(0.5 * (np.asarray(nu)[..., None] - j)), axis=-1))


def _theta_terms(params, prior, e_ln_pi, e_ln_lam, chol, logdet_winv):
    """E[ln p(pi, mu, Lambda)] - E[ln q(pi, mu, Lambda)]: the non-Z part of P1 eq. (29)."""
    alpha, beta, m, nu, Winv = params
    alpha0, beta0, m0, nu0, W0inv = prior
    K, d = m.shape
    # Dirichlet part: ln C(alpha0) - ln C(alpha) + sum_k (alpha0 - alpha_k) E[ln pi_k]
    t_pi = (gammaln(K * alpha0) - K * gammaln(alpha0) - gammaln(alpha.sum()) + np.sum(gammaln(alpha))
            + np.sum((alpha0 - alpha) * e_ln_pi))
    # Gaussian-Wishart part, per component
    z0 = np.linalg.solve(chol, (m - m0[None, :])[:, :, None])[..., 0]
    q0 = np.sum(z0 * z0, axis=1)                                          # (m_k-m0)^T W_k (m_k-m0)
    tr = np.trace(np.linalg.solve(Winv, np.broadcast_to(W0inv, Winv.shape)), axis1=1, axis2=2)
    logdet_w0inv = np.linalg.slogdet(W0inv)[1]
    lnB0 = _log_wishart_norm(nu0, logdet_w0inv, d)
    lnB = _log_wishart_norm(nu, logdet_winv, d)
    t_k = (0.5 * d * np.log(beta0 / beta) + 0.5 * d - 0.5 * d * beta0 / beta - 0.5 * beta0 * nu * q0
           + lnB0 - lnB + 0.5 * (nu0 - nu) * e_ln_lam - 0.5 * nu * tr + 0.5 * nu * d)
    return float(t_pi + np.sum(t_k))


def _log_rho(X, params, e_ln_pi, e_ln_lam, chol):
    """Unnormalised log responsibilities ``ln rho_nk`` (n, K), P1 eqs. (19), (26)."""
    alpha, beta, m, nu, Winv = params
    d = X.shape[1]
    Linv = np.linalg.inv(chol)
    LinvT = np.swapaxes(Linv, 1, 2)
    y = np.matmul(X[None], LinvT) - np.matmul(m[:, None, :], LinvT)                 # (K, n, d)
    maha = np.einsum("kni,kni->nk", y, y)                                           # (x-m_k)^T W_k (x-m_k)
    return (e_ln_pi + 0.5 * e_ln_lam - 0.5 * d * _LOG2PI)[None, :] \
        - 0.5 * (d / beta[None, :] + nu[None, :] * maha)                            # P1 eqs. (19), (26)


def _responsibilities(X, params):
    """Responsibilities ``gamma_nk`` (n, K) of the posterior ``params`` (P1 eqs. 19-21)."""
    e_ln_pi, e_ln_lam, chol, _ = _expectations(params, X.shape[1])
    log_rho = _log_rho(X, params, e_ln_pi, e_ln_lam, chol)
    return np.exp(log_rho - logsumexp(log_rho, axis=1)[:, None])


def _vb_loop_numpy(X, w, params, prior, tol_abs, max_iter, bounds, prune_thr=0.0):
    """Iterate E-step / bound / M-step from posterior ``params``.

    Returns (params, n_iter, status): status 0 = max_iter reached, 1 = converged,
    2 = a component's expected weight fell below ``prune_thr``.  Appends the bound
    of every iteration to ``bounds``.
    """
    n, d = X.shape
    prev = -np.inf
    for it in range(1, max_iter + 1):
        e_ln_pi, e_ln_lam, chol, logdet_winv = _expectations(params, d)
        log_rho = _log_rho(X, params, e_ln_pi, e_ln_lam, chol)
        log_norm = logsumexp(log_rho, axis=1)
        bound = float(w @ log_norm) + _theta_terms(params, prior, e_ln_pi, e_ln_lam, chol, logdet_winv)
        bounds.append(bound)                                                        # P1 eq. (29)
        resp = np.exp(log_rho - log_norm[:, None])                                  # gamma_nk, P1 eq. (21)
        params = _m_step(X, w[:, None] * resp, prior)
        a = params[0]
        if prune_thr > 0 and len(a) > 1 and np.any(a < prune_thr * a.sum()):
            return params, it, 2
        if abs(bound - prev) < tol_abs:
            return params, it, 1
        prev = bound
    return params, max_iter, 0


# --------------------------------------------------------------------------
# numba fast path, 1 <= d <= _NUMBA_MAX_DIM
# --------------------------------------------------------------------------
@numba.njit(cache=True)
def _digamma(x):
    r = 0.0
    while x < 6.0:
        r -= 1.0 / x
        x += 1.0
    f = 1.0 / (x * x)
    return r + math.log(x) - 0.5 / x - f * (1.0 / 12 - f * (1.0 / 120 - f * (1.0 / 252 - f * (1.0 / 240 - f / 132))))


_NUMBA_MAX_DIM = 16     # fused kernel for d <= this (measured faster than numpy up to d = 16)


from mixnav.linalg import cholesky_lower as _chol_lower  # noqa: E402  (shared with the Kalman kernels)
from mixnav.linalg import tril_inv as _tril_inv  # noqa: E402


# --- blocked E-step: samples in blocks of _BLOCK, inner loops over samples (SIMD) ---
_BLOCK = 256            # samples per block (the block's work arrays stay in L1)
_CHUNK = 4 * _BLOCK     # samples per chunk: the unit of (parallel) work and of the partial sums
_PARALLEL_MIN_N = 8 * _CHUNK    # the parallel E-step is used from this many samples on
_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01    # ln 2 = _LN2_HI + _LN2_LO, _LN2_HI with 32 trailing zero bits
_LN2_LO = 1.90821492927058770002e-10


@numba.njit(cache=True)
def _exp_nonpos(v, out, ibuf, nb):
    """``out[:nb] = exp(v[:nb])`` for ``v <= 0``, in loops the compiler vectorises.

    ``math.exp`` is a scalar call in numba (no SVML here), the largest cost of the E-step.
    ``exp(x) = 2^t exp(r)`` with ``t = round(x / ln 2)``, ``r = x - t ln 2`` (Cody-Waite: two
    parts of ln 2, so ``r`` is exact to ~1 ulp), ``|r| <= ln2 / 2``; ``exp(r)`` by its
    Taylor polynomial of degree 13 (truncation < 1e-17 relative) and ``2^t`` built in the
    exponent bits.  Relative error <= 2.5e-16 (tested against numpy).  Values below -708
    (where 2^t would be subnormal) give exactly 0: they are < 1e-307 of the largest term
    of a log-sum-exp, which is 1.
    """
    fbuf = ibuf.view(np.float64)
    for s in range(nb):
        x = max(v[s], -708.0)
        t = math.floor(x * _LOG2E + 0.5)
        r = (x - t * _LN2_HI) - t * _LN2_LO
        p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6 + r * (1.0 / 24 + r * (1.0 / 120 + r * (1.0 / 720 + r * (
            1.0 / 5040 + r * (1.0 / 40320 + r * (1.0 / 362880 + r * (1.0 / 3628800 + r * (
                1.0 / 39916800 + r * (1.0 / 479001600 + r * (1.0 / 6227020800)))))))))))))
        ibuf[s] = (np.int64(t) + 1023) << 52                                         # bits of 2^t
        out[s] = p
    for s in range(nb):
        y = out[s] * fbuf[s]
        out[s] = y if v[s] >= -708.0 else 0.0


@numba.njit(cache=True)
def _lr_block(XT, lo, nb, Li, b, const, hnu, lr):
    """``lr[k, s] = const_k - nu_k / 2 |L_k^-1 x_s - b_k|^2`` for the block (P1 eqs. 19, 26); any d."""
    K, d = b.shape
    z = np.empty(nb)
    for k in range(K):
        out = lr[k]
        for s in range(nb):
            out[s] = 0.0
        for i in range(d):
            bi = b[k, i]
            for s in range(nb):
                z[s] = -bi
            for j in range(i + 1):
                c = Li[k, i, j]
                xj = XT[j]
                for s in range(nb):
                    z[s] += c * xj[lo + s]
            for s in range(nb):
                out[s] += z[s] * z[s]
        ck = const[k]
        hk = hnu[k]
        for s in range(nb):
            out[s] = ck - hk * out[s]


@numba.njit(cache=True)
def _lr_block1(XT, lo, nb, Li, b, const, hnu, lr):
    """:func:`_lr_block` written out for d = 1."""
    X0 = XT[0]
    for k in range(Li.shape[0]):
        l00 = Li[k, 0, 0]
        b0 = b[k, 0]
        ck = const[k]
        hk = hnu[k]
        out = lr[k]
        for s in range(nb):
            z0 = l00 * X0[lo + s] - b0
            out[s] = ck - hk * (z0 * z0)


@numba.njit(cache=True)
def _lr_block2(XT, lo, nb, Li, b, const, hnu, lr):
    """:func:`_lr_block` written out for d = 2 (one pass per component, all in registers)."""
    X0 = XT[0]
    X1 = XT[1]
    for k in range(Li.shape[0]):
        l00 = Li[k, 0, 0]
        l10 = Li[k, 1, 0]
        l11 = Li[k, 1, 1]
        b0 = b[k, 0]
        b1 = b[k, 1]
        ck = const[k]
        hk = hnu[k]
        out = lr[k]
        for s in range(nb):
            x0 = X0[lo + s]
            x1 = X1[lo + s]
            z0 = l00 * x0 - b0
            z1 = l10 * x0 + l11 * x1 - b1
            out[s] = ck - hk * (z0 * z0 + z1 * z1)


@numba.njit(cache=True)
def _lr_block3(XT, lo, nb, Li, b, const, hnu, lr):
    """:func:`_lr_block` written out for d = 3."""
    X0 = XT[0]
    X1 = XT[1]
    X2 = XT[2]
    for k in range(Li.shape[0]):
        l00 = Li[k, 0, 0]
        l10 = Li[k, 1, 0]
        l11 = Li[k, 1, 1]
        l20 = Li[k, 2, 0]
        l21 = Li[k, 2, 1]
        l22 = Li[k, 2, 2]
        b0 = b[k, 0]
        b1 = b[k, 1]
        b2 = b[k, 2]
        ck = const[k]
        hk = hnu[k]
        out = lr[k]
        for s in range(nb):
            x0 = X0[lo + s]
            x1 = X1[lo + s]
            x2 = X2[lo + s]
            z0 = l00 * x0 - b0
            z1 = l10 * x0 + l11 * x1 - b1
            z2 = l20 * x0 + l21 * x1 + l22 * x2 - b2
            out[s] = ck - hk * (z0 * z0 + z1 * z1 + z2 * z2)


# The statistics are sums over the block's samples; "reassoc" lets the compiler keep them in
# SIMD lanes (a fixed summation order per compiled kernel, so results stay deterministic).
@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _stats_block(XT, lo, nb, m, r, s0, s1, s2):
    """Add the block's ``sum r``, ``sum r dx``, ``sum r dx dx^T`` (lower), ``dx = x - m_k``; any d."""
    K, d = m.shape
    dx = np.empty((d, nb))
    t = np.empty(nb)
    for k in range(K):
        rk = r[k]
        a = 0.0
        for s in range(nb):
            a += rk[s]
        s0[k] += a
        for i in range(d):
            mk = m[k, i]
            xi = XT[i]
            for s in range(nb):
                dx[i, s] = xi[lo + s] - mk
        for i in range(d):
            a = 0.0
            for s in range(nb):
                ti = rk[s] * dx[i, s]
                t[s] = ti
                a += ti
            s1[k, i] += a
            for j in range(i + 1):
                a = 0.0
                for s in range(nb):
                    a += t[s] * dx[j, s]
                s2[k, i, j] += a


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _stats_block1(XT, lo, nb, m, r, s0, s1, s2):
    """:func:`_stats_block` written out for d = 1."""
    X0 = XT[0]
    for k in range(m.shape[0]):
        m0 = m[k, 0]
        rk = r[k]
        a = a0 = a00 = 0.0
        for s in range(nb):
            rs = rk[s]
            d0 = X0[lo + s] - m0
            t0 = rs * d0
            a += rs
            a0 += t0
            a00 += t0 * d0
        s0[k] += a
        s1[k, 0] += a0
        s2[k, 0, 0] += a00


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _stats_block2(XT, lo, nb, m, r, s0, s1, s2):
    """:func:`_stats_block` written out for d = 2."""
    X0 = XT[0]
    X1 = XT[1]
    for k in range(m.shape[0]):
        m0 = m[k, 0]
        m1 = m[k, 1]
        rk = r[k]
        a = a0 = a1 = a00 = a10 = a11 = 0.0
        for s in range(nb):
            rs = rk[s]
            d0 = X0[lo + s] - m0
            d1 = X1[lo + s] - m1
            t0 = rs * d0
            t1 = rs * d1
            a += rs
            a0 += t0
            a1 += t1
            a00 += t0 * d0
            a10 += t1 * d0
            a11 += t1 * d1
        s0[k] += a
        s1[k, 0] += a0
        s1[k, 1] += a1
        s2[k, 0, 0] += a00
        s2[k, 1, 0] += a10
        s2[k, 1, 1] += a11


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _stats_block3(XT, lo, nb, m, r, s0, s1, s2):
    """:func:`_stats_block` written out for d = 3."""
    X0 = XT[0]
    X1 = XT[1]
    X2 = XT[2]
    for k in range(m.shape[0]):
        m0 = m[k, 0]
        m1 = m[k, 1]
        m2 = m[k, 2]
        rk = r[k]
        a = a0 = a1 = a2 = a00 = a10 = a11 = a20 = a21 = a22 = 0.0
        for s in range(nb):
            rs = rk[s]
            d0 = X0[lo + s] - m0
            d1 = X1[lo + s] - m1
            d2 = X2[lo + s] - m2
            t0 = rs * d0
            t1 = rs * d1
            t2 = rs * d2
            a += rs
            a0 += t0
            a1 += t1
            a2 += t2
            a00 += t0 * d0
            a10 += t1 * d0
            a11 += t1 * d1
            a20 += t2 * d0
            a21 += t2 * d1
            a22 += t2 * d2
        s0[k] += a
        s1[k, 0] += a0
        s1[k, 1] += a1
        s1[k, 2] += a2
        s2[k, 0, 0] += a00
        s2[k, 1, 0] += a10
        s2[k, 1, 1] += a11
        s2[k, 2, 0] += a20
        s2[k, 2, 1] += a21
        s2[k, 2, 2] += a22


@numba.njit(cache=True)
def _e_chunk(c, XT, w, Li, b, const, hnu, m, acc_t, acc0, acc1, acc2):
    """E-step, bound and statistics of chunk ``c`` (samples ``c _CHUNK`` on), into ``acc_*[c]``.

    Per block: ``ln rho`` of every component, a stable log-sum-exp per sample, the
    weighted responsibilities ``w_n gamma_nk`` and their statistics shifted by ``m_k``.
    """
    n = XT.shape[1]
    K, d = m.shape
    lo_c = c * _CHUNK
    hi_c = min(n, lo_c + _CHUNK)
    lr = np.empty((K, _BLOCK))
    mx = np.empty(_BLOCK)
    se = np.empty(_BLOCK)
    v = np.empty(_BLOCK)
    ibuf = np.empty(_BLOCK, dtype=np.int64)
    s0 = acc0[c]
    s1 = acc1[c]
    s2 = acc2[c]
    for k in range(K):
        s0[k] = 0.0
        for i in range(d):
            s1[k, i] = 0.0
            for j in range(d):
                s2[k, i, j] = 0.0
    total = 0.0
    for lo in range(lo_c, hi_c, _BLOCK):
        nb = min(_BLOCK, hi_c - lo)
        if d == 3:
            _lr_block3(XT, lo, nb, Li, b, const, hnu, lr)                             # P1 eqs. (19), (26)
        elif d == 2:
            _lr_block2(XT, lo, nb, Li, b, const, hnu, lr)
        elif d == 1:
            _lr_block1(XT, lo, nb, Li, b, const, hnu, lr)
        else:
            _lr_block(XT, lo, nb, Li, b, const, hnu, lr)
        for s in range(nb):
            mx[s] = lr[0, s]
        for k in range(1, K):
            for s in range(nb):
                mx[s] = max(mx[s], lr[k, s])
        for s in range(nb):
            se[s] = 0.0
        for k in range(K):
            for s in range(nb):
                v[s] = lr[k, s] - mx[s]
            _exp_nonpos(v, lr[k], ibuf, nb)                                           # rho_nk / max_k rho_nk
            for s in range(nb):
                se[s] += lr[k, s]
        for s in range(nb):
            ws = w[lo + s]
            total += ws * (mx[s] + math.log(se[s]))                                   # w_n ln sum_k rho_nk
            se[s] = ws / se[s]
        for k in range(K):
            for s in range(nb):
                lr[k, s] *= se[s]                                                     # w_n gamma_nk
        if d == 3:
            _stats_block3(XT, lo, nb, m, lr, s0, s1, s2)
        elif d == 2:
            _stats_block2(XT, lo, nb, m, lr, s0, s1, s2)
        elif d == 1:
            _stats_block1(XT, lo, nb, m, lr, s0, s1, s2)
        else:
            _stats_block(XT, lo, nb, m, lr, s0, s1, s2)
    acc_t[c] = total


def _e_pass(XT, w, Li, b, const, hnu, m, acc_t, acc0, acc1, acc2):
    # chunks are independent and write their own slots; the caller sums the slots in chunk
    # order, so the result does not depend on the number of threads or their schedule
    for c in numba.prange(acc_t.shape[0]):
        _e_chunk(np.int64(c), XT, w, Li, b, const, hnu, m, acc_t, acc0, acc1, acc2)


_e_passes = serial_and_parallel(_e_pass, "_e_pass_parallel", serial_name="_e_pass_serial")


@numba.njit(cache=True)
def _prior_consts(w0inv, nu0, L0):
    """Cholesky factor ``L0`` of W0^-1 (written) and ln B(W0, nu0); (False, 0) if not SPD."""
    d = w0inv.shape[0]
    if not _chol_lower(w0inv, L0):
        return False, 0.0
    logdet_w0inv = 0.0
    for j in range(d):
        logdet_w0inv += 2.0 * math.log(L0[j, j])
    lnB0 = 0.5 * nu0 * logdet_w0inv - 0.5 * nu0 * d * math.log(2.0) - 0.25 * d * (d - 1) * math.log(math.pi)
    for j in range(d):
        lnB0 -= math.lgamma(0.5 * (nu0 - j))
    return True, lnB0


@numba.njit(cache=True)
def _iter_prepare(alpha, beta, m, nu, winv, alpha0, beta0, m0, nu0, L0, lnB0, L, Li, b, const, hnu):
    """Per component: ``Li`` = inverse Cholesky factor of W_k^-1, ``b = Li m_k``, the constant
    and ``nu_k / 2`` of ln rho (P1 eqs. 19, 26-28); returns (ok, the non-Z part of the bound).
    """
    K, d = m.shape
    ln2 = math.log(2.0)
    lnpi = math.log(math.pi)
    asum = 0.0
    for k in range(K):
        asum += alpha[k]
    dg_sum = _digamma(asum)
    theta = math.lgamma(K * alpha0) - K * math.lgamma(alpha0) - math.lgamma(asum)
    for k in range(K):
        if not _chol_lower(winv[k], L):
            return False, 0.0
        _tril_inv(L, Li[k])
        logdet_winv = 0.0
        for j in range(d):
            logdet_winv += 2.0 * math.log(L[j, j])
        e_ln_pi = _digamma(alpha[k]) - dg_sum                                        # P1 eq. (28)
        e_ln_lam = d * ln2 - logdet_winv                                              # P1 eq. (27)
        lnB = 0.5 * nu[k] * logdet_winv - 0.5 * nu[k] * d * ln2 - 0.25 * d * (d - 1) * lnpi
        for j in range(d):
            e_ln_lam += _digamma(0.5 * (nu[k] - j))
            lnB -= math.lgamma(0.5 * (nu[k] - j))
        const[k] = e_ln_pi + 0.5 * e_ln_lam - 0.5 * d * _LOG2PI - 0.5 * d / beta[k]
        hnu[k] = 0.5 * nu[k]
        # b_k = L_k^-1 m_k;  q0 = |L_k^-1 (m_k - m0)|^2;  tr(W_k W0^-1) = |L_k^-1 L0|_F^2
        q0 = 0.0
        tr = 0.0
        for i in range(d):
            sb = 0.0
            sq = 0.0
            for j in range(i + 1):
                sb += Li[k, i, j] * m[k, j]
                sq += Li[k, i, j] * (m[k, j] - m0[j])
            b[k, i] = sb
            q0 += sq * sq
            for c in range(i + 1):
                st = 0.0
                for j in range(c, i + 1):
                    st += Li[k, i, j] * L0[j, c]
                tr += st * st
        # non-Z part of the bound (see _theta_terms)
        theta += math.lgamma(alpha[k]) + (alpha0 - alpha[k]) * e_ln_pi
        theta += (0.5 * d * math.log(beta0 / beta[k]) + 0.5 * d - 0.5 * d * beta0 / beta[k]
                  - 0.5 * beta0 * nu[k] * q0 + lnB0 - lnB + 0.5 * (nu0 - nu[k]) * e_ln_lam
                  - 0.5 * nu[k] * tr + 0.5 * nu[k] * d)
    return True, theta


@numba.njit(cache=True)
def _iter_finish(acc_t, acc0, acc1, acc2, alpha, beta, m, nu, winv, alpha0, beta0, m0, nu0, w0inv):
    """Add the chunks' partial sums in chunk order, then the M-step (P1 eqs. 22-25) in place.

    Returns ``sum_n w_n ln sum_k rho_nk``.
    """
    K, d = m.shape
    s0 = np.zeros(K)
    s1 = np.zeros((K, d))
    s2 = np.zeros((K, d, d))                # lower triangle used
    dz = np.empty(d)
    dx = np.empty(d)
    total = 0.0
    for ch in range(acc_t.shape[0]):
        total += acc_t[ch]
        for k in range(K):
            s0[k] += acc0[ch, k]
            for i in range(d):
                s1[k, i] += acc1[ch, k, i]
                for j in range(i + 1):
                    s2[k, i, j] += acc2[ch, k, i, j]
    for k in range(K):                                                                # P1 eqs. (22)-(25)
        nk = s0[k] + 1e1 * 2.220446049250313e-16
        for i in range(d):
            dz[i] = s1[k, i] / nk                                                     # xbar - m_k
            dx[i] = m[k, i] + dz[i] - m0[i]                                           # xbar - m0
        c = beta0 * nk / (beta0 + nk)
        for i in range(d):
            for j in range(i + 1):
                v = w0inv[i, j] + s2[k, i, j] - s1[k, i] * dz[j] + c * dx[i] * dx[j]
                winv[k, i, j] = v
                winv[k, j, i] = v
        alpha[k] = alpha0 + nk
        beta[k] = beta0 + nk
        nu[k] = nu0 + nk
        for i in range(d):
            m[k, i] = (beta0 * m0[i] + nk * (m[k, i] + dz[i])) / beta[k]
    return total


@numba.njit(cache=True)
def _iter_status(alpha, prune_thr, bound, prev, tol_abs):
    """2 if a component's expected weight is below ``prune_thr``, 1 if converged, else 0."""
    K = alpha.shape[0]
    if prune_thr > 0.0 and K > 1:
        asum = 0.0
        for k in range(K):
            asum += alpha[k]
        for k in range(K):
            if alpha[k] < prune_thr * asum:
                return 2
    if abs(bound - prev) < tol_abs:
        return 1
    return 0


def _vb_loop(XT, w, alpha, beta, m, nu, winv, alpha0, beta0, m0, nu0, w0inv, tol_abs, max_iter, bounds,
                prune_thr):
    """Fused VB iteration; updates alpha, beta, nu (K,), m (K, d), winv (K, d, d) in place.

    Same arithmetic as :func:`_vb_loop_numpy`, one pass over the samples per iteration:
    per component (:func:`_iter_prepare`) the Cholesky factor ``L_k`` of ``W_k^-1`` (so
    ``W_k = L_k^-T L_k^-1``), its triangular inverse, E[ln pi_k], E[ln|Lambda_k|] and the
    non-Z part of the bound; then (:func:`_e_chunk`, per chunk of ``_CHUNK`` samples) the
    whitened distances ``|L_k^-1 (x - m_k)|^2``, a stable log-sum-exp and the weighted
    statistics (N_k, sum r (x - m_k), sum r (x - m_k)(x - m_k)^T, shifted by the current
    m_k for accuracy); then (:func:`_iter_finish`) the chunks' partial sums added in chunk
    order and the M-step (P1 eqs. 22-25).  ``XT`` is the data transposed, (d, n),
    C-contiguous.  Compiled twice (:func:`~mixnav._jit.serial_and_parallel`):
    ``_vb_loop_nd`` calls the serial E-pass, ``_vb_loop_nd_parallel`` the one with the
    chunks on numba's threads (compiled only when used): the same result bitwise.

    Returns (n_iter, status): status 0 (max_iter reached), 1 (converged), 2 (a component
    fell below ``prune_thr``) or 3 (a ``W_k^-1`` is not numerically positive definite;
    ``bounds[:n_iter - 1]`` are valid).  ``bounds[:n_iter]`` holds the lower bound of
    each iteration.
    """
    d, n = XT.shape
    K = alpha.shape[0]
    const, hnu, L, Li, b = np.empty(K), np.empty(K), np.empty((d, d)), np.empty((K, d, d)), np.empty((K, d))
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    acc_t, acc0 = np.empty(n_chunks), np.empty((n_chunks, K))      # per-chunk partial sums
    acc1, acc2 = np.empty((n_chunks, K, d)), np.empty((n_chunks, K, d, d))
    L0 = np.empty((d, d))
    ok, lnB0 = _prior_consts(w0inv, nu0, L0)
    if not ok:
        return 1, 3
    prev = -np.inf
    for it in range(1, max_iter + 1):
        ok, theta = _iter_prepare(alpha, beta, m, nu, winv, alpha0, beta0, m0, nu0, L0, lnB0, L, Li, b, const, hnu)
        if not ok:
            return it, 3
        _e_pass(XT, w, Li, b, const, hnu, m, acc_t, acc0, acc1, acc2)
        bound = _iter_finish(acc_t, acc0, acc1, acc2, alpha, beta, m, nu, winv, alpha0, beta0, m0, nu0,
                             w0inv) + theta                                          # P1 eq. (29)
        bounds[it - 1] = bound
        status = _iter_status(alpha, prune_thr, bound, prev, tol_abs)
        if status != 0:
            return it, status
        prev = bound
    return max_iter, 0


_vb_loop_nd, _vb_loop_nd_parallel = serial_and_parallel(_vb_loop, "_vb_loop_nd_parallel", serial_name="_vb_loop_nd",
                                                        calls={"_e_pass": _e_passes}, parallel=False)


def _use_parallel(requested, n):
    """Whether the E-step runs on numba's threads: if ``requested``, for ``n >= _PARALLEL_MIN_N``
    samples, with more than one thread (``NUMBA_NUM_THREADS``), and only from the main thread.

    The results do not depend on this choice (tested).  Numba's default threading layer
    (workqueue) aborts the process on concurrent use from two Python threads, so fits
    running in worker threads (a thread pool, a Dask worker) always use the serial E-step.
    """
    return bool(requested and n >= _PARALLEL_MIN_N and numba.get_num_threads() > 1
                and threading.current_thread() is threading.main_thread())


# --------------------------------------------------------------------------
# initialisation and merge moves
# --------------------------------------------------------------------------
_LLOYD_MAX_ITER = 100           # Lloyd iterations after k-means++ seeding (stops earlier when labels settle)
_LLOYD_TOL = 1e-4               # ... or when the centres move less than this x the mean data variance (sklearn's)
_MERGE_MIN_OVERLAP = 1e-3       # merge candidates: responsibility overlap J_ij at least this


def _greedy_kmeanspp(X, k, rng, w):
    """Greedy k-means++ seeding (Arthur & Vassilvitskii 2007; scikit-learn's default), centres (K, d).

    Each new centre is the best (lowest weighted potential ``sum_n w_n D_n^2``) of
    ``2 + floor(ln K)`` candidates drawn with probability proportional to ``w_n D_n^2``.
    """
    n = X.shape[0]
    n_trials = 2 + int(math.log(k))
    centres = np.empty((k, X.shape[1]))
    centres[0] = X[rng.choice(n, p=w / w.sum())]
    d2 = np.sum((X - centres[0]) ** 2, axis=1)
    for j in range(1, k):
        q = w * d2
        s = q.sum()
        if not s > 0:
            centres[j:] = centres[0]
            break
        cand = rng.choice(n, size=n_trials, p=q / s)
        cd2 = np.zeros((n_trials, n))
        for c in range(X.shape[1]):
            cd2 += (X[None, :, c] - X[cand, c][:, None]) ** 2
        np.minimum(cd2, d2[None, :], out=cd2)
        best = int(np.argmin(cd2 @ w))
        centres[j] = X[cand[best]]
        d2 = cd2[best]
    return centres


@numba.njit(cache=True)
def _lloyd(X, w, centres, labels, max_iter, shift_tol):
    """Weighted Lloyd iterations from ``centres`` (K, d), in place; ``labels`` (n,) out.

    Assign each sample to its nearest centre (the first on a tie), move each centre to
    the weighted mean of its samples (an empty cluster keeps its centre); stop when no
    label changes, when the centres moved by less than ``shift_tol`` in total squared
    distance, or after ``max_iter`` updates; the labels are those of the final centres.
    Returns the number of updates.
    """
    n, d = X.shape
    K = centres.shape[0]
    nk = np.empty(K)
    sx = np.empty((K, d))
    XT = np.ascontiguousarray(X.T)
    bd = np.empty(_BLOCK)
    dist = np.empty(_BLOCK)
    best = np.empty(_BLOCK, dtype=np.int64)
    it = 0
    shift = np.inf
    while True:
        changed = 0
        for lo in range(0, n, _BLOCK):                 # blocks of samples, sample loops innermost (SIMD)
            nb = min(_BLOCK, n - lo)
            for k in range(K):
                for s in range(nb):
                    dist[s] = 0.0
                for j in range(d):
                    c = centres[k, j]
                    xj = XT[j]
                    for s in range(nb):
                        t = xj[lo + s] - c
                        dist[s] += t * t
                if k == 0:
                    for s in range(nb):
                        bd[s] = dist[s]
                        best[s] = 0
                else:
                    for s in range(nb):
                        closer = dist[s] < bd[s]
                        bd[s] = dist[s] if closer else bd[s]
                        best[s] = k if closer else best[s]
            for s in range(nb):
                if best[s] != labels[lo + s]:
                    changed += 1
                    labels[lo + s] = best[s]
        if (changed == 0 and it > 0) or it >= max_iter or shift <= shift_tol:
            return it
        it += 1
        nk[:] = 0.0
        sx[:] = 0.0
        for i in range(n):
            k = labels[i]
            nk[k] += w[i]
            for j in range(d):
                sx[k, j] += w[i] * X[i, j]
        shift = 0.0
        for k in range(K):
            if nk[k] > 0:
                for j in range(d):
                    c = sx[k, j] / nk[k]
                    shift += (c - centres[k, j]) ** 2
                    centres[k, j] = c


def kmeans_resp(X, k, rng, w, max_iter=_LLOYD_MAX_ITER):
    """Hard responsibilities (n, K) of weighted k-means: k-means++ seeding, then Lloyd iterations.

    Lloyd's iterations (:func:`_lloyd`) stop when no label changes, when the centres move
    by less than ``_LLOYD_TOL`` times the mean variance of the data columns (squared
    distance summed over the centres; scikit-learn's KMeans rule) or after ``max_iter``;
    a cluster that becomes empty keeps its previous centre.  Deterministic given ``rng``.
    """
    n = X.shape[0]
    centres = _greedy_kmeanspp(X, k, rng, w)
    labels = np.full(n, -1, dtype=np.int64)
    mean = (w @ X) / w.sum()
    var = (w @ (X - mean) ** 2) / w.sum()
    _lloyd(np.ascontiguousarray(X, dtype=float), np.ascontiguousarray(w, dtype=float), centres, labels,
           int(max_iter), _LLOYD_TOL * float(np.mean(var)))
    resp = np.zeros((n, k))
    resp[np.arange(n), labels] = 1.0
    return resp


def _merge_candidates(X, w, params, min_overlap=_MERGE_MIN_OVERLAP):
    """Pairs (i, j), i < j, ordered by decreasing responsibility overlap, and the responsibilities.

    Overlap ``J_ij = sum_n w_n g_ni g_nj / sqrt(sum_n w_n g_ni^2 sum_n w_n g_nj^2)`` (the SMEM
    merge criterion of Ueda et al. 2000; 1 for identical responsibility columns, 0 for
    disjoint ones).  Pairs with ``J_ij < min_overlap`` are not returned: merging two
    components that share (almost) no samples replaces them by one Gaussian spanning both
    groups, which costs far more likelihood than one component's parameters.
    """
    resp = _responsibilities(X, params)
    G = (w[:, None] * resp).T @ resp
    diag = np.sqrt(np.maximum(np.diag(G), 1e-300))
    J = G / diag[:, None] / diag[None, :]
    K = len(diag)
    pairs = [(float(J[i, j]), i, j) for i in range(K) for j in range(i + 1, K) if J[i, j] >= min_overlap]
    pairs.sort(key=lambda t: -t[0])                   # stable: ties keep (i, j) order
    return pairs, resp


# --------------------------------------------------------------------------
# estimator
# --------------------------------------------------------------------------
class VariationalGaussianMixture(MixtureLearner):
    """Variational Bayes Gaussian mixture with pruning, merging and warm start (paper P1).

    Parameters
    ----------
    n_components : int, default 4
        Upper bound on the number of components (K).
    alpha0 : float, default 1.0
        Dirichlet concentration of the weights (P1 eq. 15).
    beta0 : float, default 1.0
        Scale of the prior precision of the means (P1 eq. 17).
    nu0 : float or None
        Wishart degrees of freedom, > d - 1.  ``None``: the paper's 1, raised to d
        when d >= 2.
    W0 : None, float or array_like (d, d)
        Wishart scale.  ``None``: ``2 inv(Cov(X))`` (the paper's 2I in units of the
        data precision); float c: ``c inv(Cov(X))``; array: used as is.
    m0 : None or array_like (d,)
        Prior mean of the means; ``None``: the weighted data mean.
    tol : float, default 1e-6
        Convergence when the lower bound divided by the total sample weight
        changes by less than ``tol``.
    max_iter : int, default 500
        Total iterations over all pruning rounds of one run (the first run, and each
        merge trial separately).
    prune_threshold : float, default 0.01
        Components with expected weight below this are removed (0 disables).
    merge : {"auto", True, False}, default "auto"
        After convergence, try merge moves (see the module docstring) and keep those
        that raise the lower bound.  ``"auto"``: on when ``prune_threshold > 0`` and the
        fit is not warm-started (a warm start keeps the structure it starts from and
        stays cheap); ``True`` also merges after a warm start.
    init : {"kmeans", "kmeans++"}, default "kmeans"
        Initial hard responsibilities when ``init_resp`` is None: weighted k-means
        (k-means++ seeding then Lloyd iterations, as scikit-learn's default) or the
        k-means++ seeding alone.
    init_resp : None or array_like (n, K)
        Initial responsibilities; overrides ``init``.
    random_state : None, int or numpy Generator
    parallel : bool, default False
        Run the E-step of d <= 16 data on numba's threads (``NUMBA_NUM_THREADS``)
        when there are at least ``_PARALLEL_MIN_N`` samples and the fit runs in the main
        thread.  The results are identical (fixed chunks, partial sums added in a fixed
        order).  Off by default: on 2 idle cores it saves up to half of the time, but
        when the cores are busy with other processes a parallel region waits for a
        descheduled thread (measured ~10 ms per iteration on a loaded 2-core machine).

    Attributes
    ----------
    weights_ : ndarray (K',)
        Expected weights ``alpha_k / sum(alpha)`` (K' <= K after pruning and merging).
    means_ : ndarray (K', d)
        Posterior means ``m_k``.
    covariances_ : ndarray (K', d, d)
        ``W_k^-1 / nu_k`` = inverse of the expected precision (as scikit-learn).
    weight_concentration_, mean_precision_, degrees_of_freedom_ : ndarray (K',)
        Posterior ``alpha_k``, ``beta_k``, ``nu_k``.
    precisions_ : ndarray (K', d, d)
        Expected precisions ``nu_k W_k``.
    converged_ : bool
    n_iter_ : int
        Iterations on the path to the result (first run and accepted merge runs).
    lower_bound_ : float
        Final lower bound (eq. 29) of the K'-component model, total over samples.
    lower_bounds_ : list of float
        Lower bound at every iteration on the path to the result.
    pruned_at_ : list of int
        Indices into ``lower_bounds_`` where an iteration run after pruning starts.
    merged_at_ : list of int
        Indices into ``lower_bounds_`` where the run after an accepted merge starts.
        ``lower_bounds_`` never decreases between consecutive entries of
        ``sorted(pruned_at_ + merged_at_)``.
    merges_ : list of dict
        Every merge trial: ``pair`` (indices before the merge), ``overlap``,
        ``n_before``, ``n_after`` (components after the trial's own pruning),
        ``gain`` (change of ``lower_bound_``), ``n_iter``, ``converged``,
        ``accepted``.
    prior_ : dict
        The resolved prior (alpha0, beta0, m0, nu0, W0).
    """

    def __init__(self, n_components=4, alpha0=1.0, beta0=1.0, nu0=None, W0=None, m0=None, tol=1e-6,
                 max_iter=500, prune_threshold=0.01, merge="auto", init="kmeans", init_resp=None,
                 random_state=None, parallel=False):
        self.n_components = n_components
        self.alpha0 = alpha0
        self.beta0 = beta0
        self.nu0 = nu0
        self.W0 = W0
        self.m0 = m0
        self.tol = tol
        self.max_iter = max_iter
        self.prune_threshold = prune_threshold
        self.merge = merge
        self.init = init
        self.init_resp = init_resp
        self.random_state = random_state
        self.parallel = parallel

    # ---- priors -------------------------------------------------------------
    def _resolve_prior(self, X, w):
        d = X.shape[1]
        if not (self.alpha0 > 0 and self.beta0 > 0):
            raise ValueError("alpha0 and beta0 must be positive")
        if self.nu0 is None:
            nu0 = 1.0 if d == 1 else float(d)          # paper's 1, raised so that nu0 > d - 1
        else:
            nu0 = float(self.nu0)
            if not nu0 > d - 1:
                raise ValueError(f"nu0={nu0} must exceed d - 1 = {d - 1}")
        wsum = w.sum()
        mean = (w @ X) / wsum
        if self.m0 is None:
            m0 = mean
        else:
            m0 = np.asarray(self.m0, dtype=float).reshape(-1)
            if m0.shape != (d,):
                raise ValueError(f"m0 must have shape ({d},)")
        if self.W0 is None or np.ndim(self.W0) == 0:
            c = 2.0 if self.W0 is None else float(self.W0)
            diff = X - mean
            cov = (diff * w[:, None]).T @ diff / wsum
            W0inv = cov / c                              # W0 = c inv(Cov(X))
        else:
            W0 = np.asarray(self.W0, dtype=float)
            if W0.shape != (d, d):
                raise ValueError(f"W0 must have shape ({d}, {d})")
            W0inv = np.linalg.inv(W0)
        W0inv = 0.5 * (W0inv + W0inv.T)
        try:
            np.linalg.cholesky(W0inv)
        except np.linalg.LinAlgError:
            raise ValueError("W0 must be symmetric positive definite (is a data column constant?)") from None
        return float(self.alpha0), float(self.beta0), m0, nu0, W0inv

    def _initial_resp(self, X, w):
        """Initial responsibilities (n, K) from ``init_resp`` or ``init``."""
        n = X.shape[0]
        K = int(self.n_components)
        if self.init_resp is not None:
            return check_resp(self.init_resp, n, K)
        rng = check_random_state(self.random_state)
        if self.init == "kmeans":
            return kmeans_resp(X, K, rng, w)
        if self.init == "kmeans++":
            return kmeanspp_resp(X, K, rng, w)
        raise ValueError(f"init={self.init!r}: use 'kmeans' or 'kmeans++' (or pass init_resp)")

    # ---- fitting ----------------------------------------------------------
    def fit(self, X, sample_weight=None, warm_start_from=None):
        """Fit to samples ``X`` (n, d) or (n,).

        Parameters
        ----------
        X : array_like (n, d) or (n,)
        sample_weight : None or array_like (n,)
            Non-negative weights, acting as replication counts.
        warm_start_from : None or fitted VariationalGaussianMixture
            Start from its posterior parameters (alpha, beta, m, nu, W) instead of
            initial responsibilities -- for re-learning on a sliding window.  Its
            number of components (after its pruning) is used.

        Returns
        -------
        self
        """
        K = int(self.n_components)
        if self.merge not in ("auto", True, False):
            raise ValueError(f"merge={self.merge!r}: use 'auto', True or False")
        X = validate_data(X, K if warm_start_from is None else 1)
        n, d = X.shape
        w = validate_weights(sample_weight, n)
        prior = self._resolve_prior(X, w)
        if warm_start_from is not None:
            src = warm_start_from
            if not hasattr(src, "_Winv"):
                raise ValueError("warm_start_from must be a fitted VariationalGaussianMixture")
            if src.means_.shape[1] != d:
                raise ValueError(f"warm_start_from has dimension {src.means_.shape[1]}, the data {d}")
            params = (src.weight_concentration_.copy(), src.mean_precision_.copy(), src.means_.copy(),
                      src.degrees_of_freedom_.copy(), src._Winv.copy())
        else:
            params = _m_step(X, w[:, None] * self._initial_resp(X, w), prior)
        tol_abs = float(self.tol) * w.sum()
        thr = float(self.prune_threshold)
        params, bounds, pruned_at, n_iter, converged = self._run(X, w, params, prior, tol_abs, thr)
        merge = self.merge is True or (self.merge == "auto" and thr > 0 and warm_start_from is None)
        merged_at: list[int] = []
        merges: list[dict] = []
        if merge and converged:
            params, n_iter = self._merge_moves(X, w, params, prior, tol_abs, thr, bounds, pruned_at, merged_at,
                                               merges, n_iter)
        alpha, beta, m, nu, Winv = params
        self.weight_concentration_, self.mean_precision_, self.degrees_of_freedom_ = alpha, beta, nu
        self.means_ = m
        self._Winv = Winv
        self.covariances_ = Winv / nu[:, None, None]
        self.precisions_ = np.linalg.inv(self.covariances_)
        self.weights_ = alpha / alpha.sum()
        self.converged_ = bool(converged)
        self.n_iter_ = int(n_iter)
        self.lower_bounds_ = bounds
        self.lower_bound_ = bounds[-1] if bounds else -np.inf
        self.pruned_at_ = pruned_at
        self.merged_at_ = merged_at
        self.merges_ = merges
        self.prior_ = dict(alpha0=prior[0], beta0=prior[1], m0=prior[2], nu0=prior[3],
                           W0=np.linalg.inv(prior[4]))
        if not converged:
            warnings.warn(f"variational inference did not converge in {self.max_iter} iterations "
                          f"(tol={self.tol})", ConvergenceWarning, stacklevel=2)
        return self

    def _run(self, X, w, params, prior, tol_abs, thr):
        """Iterate to convergence from ``params``, pruning on the way (at most ``max_iter`` in all).

        Returns (params, bounds, pruned_at, n_iter, converged).
        """
        d = X.shape[1]
        bounds: list[float] = []
        pruned_at: list[int] = []
        iters_left = int(self.max_iter)
        while True:
            if d <= _NUMBA_MAX_DIM:
                params, it, status = self._loop_nd(X, w, params, prior, tol_abs, iters_left, bounds, thr,
                                                   _use_parallel(self.parallel, X.shape[0]))
            else:
                params, it, status = _vb_loop_numpy(X, w, params, prior, tol_abs, iters_left, bounds, thr)
            iters_left -= it
            converged = status == 1
            if status != 2:
                break
            # P1: drop components whose expected weight is below the threshold, keep iterating
            alpha = params[0]
            keep = alpha >= thr * alpha.sum()
            keep[np.argmax(alpha)] = True
            params = tuple(p[keep] for p in params)
            pruned_at.append(len(bounds))
            if iters_left <= 0:
                break
        return params, bounds, pruned_at, int(self.max_iter) - iters_left, converged

    def _merge_moves(self, X, w, params, prior, tol_abs, thr, bounds, pruned_at, merged_at, merges, n_iter):
        """Greedy merge moves after convergence (see the module docstring); extends the run records."""
        while len(params[0]) >= 2:
            current = bounds[-1]
            pairs, resp = _merge_candidates(X, w, params)
            for overlap, i, j in pairs:
                r = np.delete(resp, j, axis=1)
                r[:, i] += resp[:, j]                                  # merged responsibilities
                trial = _m_step(X, w[:, None] * r, prior)
                try:
                    p2, b2, pr2, it2, conv2 = self._run(X, w, trial, prior, tol_abs, thr)
                except np.linalg.LinAlgError:                          # a W_k^-1 lost definiteness
                    p2, b2, pr2, it2, conv2 = trial, [], [], 0, False
                gain = b2[-1] - current if b2 else -np.inf                 # rule: see the module docstring
                ok = bool(conv2 and gain > 0.0)
                merges.append(dict(pair=(i, j), overlap=overlap, n_before=len(params[0]), n_after=len(p2[0]),
                                   gain=float(gain), n_iter=it2, converged=conv2, accepted=ok))
                if ok:
                    merged_at.append(len(bounds))
                    pruned_at.extend(len(bounds) + p for p in pr2)
                    bounds.extend(b2)
                    params = p2
                    n_iter += it2
                    break
            else:
                break                                                  # no merge raises the bound
        return params, n_iter

    @staticmethod
    def _loop_nd(X, w, params, prior, tol_abs, max_iter, bounds, prune_thr, parallel):
        alpha, beta, m, nu, Winv = (np.array(p, dtype=float) for p in params)   # fresh C-contiguous copies
        buf = np.empty(max(max_iter, 1))
        kernel = _vb_loop_nd_parallel if parallel else _vb_loop_nd
        it, status = kernel(np.ascontiguousarray(X.T, dtype=float), np.ascontiguousarray(w, dtype=float),
                            alpha, beta, m, nu, Winv, prior[0], prior[1], np.ascontiguousarray(prior[2], dtype=float),
                            prior[3], np.ascontiguousarray(prior[4], dtype=float), tol_abs, max_iter, buf, prune_thr)
        if status == 3:
            raise np.linalg.LinAlgError("Matrix is not positive definite")
        bounds.extend(buf[:it].tolist())
        return (alpha, beta, m, nu, Winv), it, status

    # ---- results ---------------------------------------------------------
    @property
    def mixture_(self) -> GaussianMixture:
        """The fitted mixture (expected weights, posterior means, ``W_k^-1 / nu_k``)."""
        return GaussianMixture(self.weights_, self.means_, 0.5 * (self.covariances_ + np.swapaxes(self.covariances_, 1, 2)))

