"""Compiled kernels of the Gaussian-sum (bank) error-state filter.

A bank is ``N`` components sharing one nominal INS solution: log-weights
``lw`` (N,), error-state means ``X`` (N, na) relative to the nominal, and
covariances ``P`` (N, na, na), where ``na = n + nc`` counts the error states
and a stochastic clone (``nc = 0`` without one). Every kernel loops over the
leading component axis inside one compiled call: no Python loop over
components anywhere.

The measurement update processes the rows of an epoch one at a time (their
noises are independent). Row ``k`` has a 1-D noise mixture
``sum_l pi_l N(mu_l sigma_k, v_l sigma_k^2)`` in units of the row's model
sigma ``sigma_k = sqrt(r_k)``. Each component splits into its ``L``
children, one per noise component, and the children are merged straight back
into their parent (moment-preserving). Children of one parent share the
prior, so this merge has a closed form that costs one scalar Kalman update::

    s_l = h P h^T + v_l r,   e_l = y - mu_l sigma,   y = z - h x
    rho_l ∝ pi_l N(e_l; 0, s_l)                       (posterior of child l)
    a = sum rho_l e_l / s_l,  b = sum rho_l / s_l - (sum rho_l (e_l / s_l)^2 - a^2)
    x <- x + (P h^T) a,       P <- P - b (P h^T)(P h^T)^T
    log w <- log w + log sum_l pi_l N(e_l; 0, s_l)

(the mean and covariance of the children's mixture, exactly). With one noise
component it is the plain scalar Kalman update. This is how per-satellite
mixtures avoid the ``L^m`` explosion of a joint bank: ``m`` rows cost ``m N``
scalar updates, not ``N L^m`` components.

The row-by-row update decides each row's component from the state as the rows
before it left it, so when gross errors meet an unconverged state the first
rows set the state and the later, correct rows are explained as outliers (P1's
epoch-0 trap). The *whole-epoch* update (:func:`bank_epoch_whole`) decides the
assignments from all rows at once: a variational-Bayes fixed point on the bank's
merged Gaussian, ``q(x) q(labels)``, alternating

    rows -> effective rows: lambda_k = sum_l rho_kl / (v_l r_k),
                            o_k = sum_l rho_kl mu_l sigma_k / (v_l r_k) / lambda_k
    q(x) = Kalman update by (y_k - o_k, 1 / lambda_k) of every row
    rho_kl ∝ pi_l (v_l r_k)^-1/2 exp(-((e_k - mu_l sigma_k)^2 + h_k P h_k^T) / (2 v_l r_k)),
             e_k = y_k - h_k x   (the expectations under q(x))

from the prior-predictive responsibilities until they change by less than
``tol``; then every component takes the same effective rows, and its weight the
rise of its evidence ``sum_k log N(effective innovation; 0, s_k)`` (the
variational bound of the epoch's evidence less terms common to all
components). With one noise component ``rho = 1`` and it is the Kalman
update, as the row-by-row update is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kalman import cholesky_lower, innovation_is_absurd

_LOG2PI = math.log(2.0 * math.pi)


@njit(cache=True)
def bank_propagate(X, P, phi, qd, n):
    """``x <- Phi x``, ``P <- Phi P Phi^T + Qd`` on the error-state block of
    every component; the clone (states ``n:``) is constant, so its cross block
    becomes ``Phi P_xc`` and its own block is unchanged."""
    N, na = X.shape
    tmp = np.empty((n, na))
    xs = np.empty(n)
    for c in range(N):
        for i in range(n):
            s = 0.0
            for k in range(n):
                s += phi[i, k] * X[c, k]
            xs[i] = s
        for i in range(n):
            X[c, i] = xs[i]
        # tmp = Phi P[:n, :]   (phi is sparse: skip its zeros)
        tmp[:, :] = 0.0
        for i in range(n):
            for k in range(n):
                f = phi[i, k]
                if f != 0.0:
                    for j in range(na):
                        tmp[i, j] += f * P[c, k, j]
        for i in range(n):
            for j in range(i, n):
                s = 0.0
                for k in range(n):
                    s += tmp[i, k] * phi[j, k]
                v = s + qd[i, j]
                P[c, i, j] = v
                P[c, j, i] = v
            for j in range(n, na):
                P[c, i, j] = tmp[i, j]
                P[c, j, i] = tmp[i, j]


@njit(cache=True)
def bank_split(lw, X, P, Q, log_wj, cj):
    """Children ``(c, j)`` of every component for each process-noise component
    ``j``: ``P_cj = P_c + c_j Q`` on the error-state block, ``log w + log w_j``."""
    N, na = X.shape
    J = cj.shape[0]
    n = Q.shape[0]
    lw2 = np.empty(N * J)
    X2 = np.empty((N * J, na))
    P2 = np.empty((N * J, na, na))
    for c in range(N):
        for j in range(J):
            o = c * J + j
            lw2[o] = lw[c] + log_wj[j]
            X2[o] = X[c]
            P2[o] = P[c]
            for a in range(n):
                for b in range(n):
                    P2[o, a, b] += cj[j] * Q[a, b]
    return lw2, X2, P2


@njit(cache=True)
def bank_moments(lw, X, P):
    """Normalised weights, merged mean and merged covariance of the bank."""
    N, na = X.shape
    m = lw.max()
    w = np.exp(lw - m)
    w /= w.sum()
    xm = np.zeros(na)
    for c in range(N):
        for i in range(na):
            xm[i] += w[c] * X[c, i]
    Pm = np.zeros((na, na))
    for c in range(N):
        for i in range(na):
            di = X[c, i] - xm[i]
            for j in range(na):
                Pm[i, j] += w[c] * (P[c, i, j] + di * (X[c, j] - xm[j]))
    return w, xm, Pm


@njit(cache=True)
def predicted_nis(xm, Pm, z, H, r):
    """NIS of the merged prediction: ``y^T (H P H^T + R)^-1 y``, ``y = z - H x``.

    Returns ``inf`` when the innovation covariance is not positive definite."""
    m, na = H.shape
    y = np.empty(m)
    HP = np.zeros((m, na))
    for i in range(m):
        s = z[i]
        for k in range(na):
            h = H[i, k]
            if h != 0.0:
                s -= h * xm[k]
                for j in range(na):
                    HP[i, j] += h * Pm[k, j]
        y[i] = s
    S = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            s = 0.0
            for k in range(na):
                s += HP[i, k] * H[j, k]
            S[i, j] = s
        S[i, i] += r[i]
    L = np.empty((m, m))
    if not cholesky_lower(S, L):
        return np.inf, y
    nis = 0.0
    w = y.copy()
    for i in range(m):
        s = w[i]
        for k in range(i):
            s -= L[i, k] * w[k]
        w[i] = s / L[i, i]
        nis += w[i] * w[i]
    return nis, y


# reassociation lets the row loops vectorise; no 'nnan'/'ninf', so the infinity checks stay
@njit(cache=True)
def bank_update(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var):
    """:func:`bank_update_gated` with no gate (every row updated with its noise mixture)."""
    return bank_update_gated(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, np.inf)


@njit(cache=True, fastmath={"reassoc", "contract"})
def bank_update_gated(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, gate):
    """Sequential scalar update of every component by every row (module docstring).

    Parameters
    ----------
    lw, X, P : bank (updated in place)
    z, H, r : ndarray (m,), (m, na), (m,)
        Innovations of the nominal state, Jacobian, noise variances.
    kinds : ndarray of int (m,)
        Row -> index into the mixture tables.
    mix_logw, mix_mu, mix_var : ndarray (n_kinds, L)
        Per kind, log-weights (``-inf`` pads unused slots), means and variance
        scales of the standardised noise mixture.
    gate : float
        A row whose state share of the predicted variance ``h P h^T`` exceeds
        ``gate * r`` (the component's state is not yet known better than the
        noise) is updated with its mixture's moment-matched Gaussian, not the
        mixture (``inf``: never): the epoch-0 trap guard (module docstring).

    Returns
    -------
    ok : bool
        False when a component's predicted variance is not positive or a
        value is not finite (the caller rejects the epoch).
    """
    N, na = X.shape
    m = z.shape[0]
    L = mix_logw.shape[1]
    Ph = np.empty(na)
    ll = np.empty(L)
    ex = np.empty(L)
    # each row's non-zero columns, found once for all components
    nz = np.empty((m, na), dtype=np.int64)
    n_nz = np.zeros(m, dtype=np.int64)
    for k in range(m):
        for j in range(na):
            if H[k, j] != 0.0:
                nz[k, n_nz[k]] = j
                n_nz[k] += 1
    # components are independent here: one at a time, all rows (it stays in cache)
    for c in range(N):
        Pc = P[c]
        Xc = X[c]
        for k in range(m):
            kd = kinds[k]
            rk = r[k]
            sig = math.sqrt(rk)
            for i in range(na):
                Ph[i] = 0.0
            hx = 0.0
            for q in range(n_nz[k]):
                j = nz[k, q]
                h = H[k, j]
                hx += h * Xc[j]
                for i in range(na):
                    Ph[i] += Pc[j, i] * h  # P symmetric: row j is column j
            hPh = 0.0
            for q in range(n_nz[k]):
                hPh += H[k, nz[k, q]] * Ph[nz[k, q]]
            y = z[k] - hx
            if hPh > gate * rk:     # unconverged: the mixture's moment-matched Gaussian
                mbar = 0.0
                m2 = 0.0
                for l in range(L):
                    if mix_logw[kd, l] > -np.inf:
                        wl = math.exp(mix_logw[kd, l])
                        mbar += wl * mix_mu[kd, l]
                        m2 += wl * (mix_var[kd, l] + mix_mu[kd, l] * mix_mu[kd, l])
                s = hPh + (m2 - mbar * mbar) * rk
                if not (s > 0.0):
                    return False
                e = y - mbar * sig
                lam = -0.5 * (_LOG2PI + math.log(s) + e * e / s)
                a = e / s
                b = 1.0 / s
                if not (np.isfinite(a) and np.isfinite(lam)):
                    return False
                for i in range(na):
                    Xc[i] += Ph[i] * a
                for i in range(na):
                    bi = b * Ph[i]
                    for j in range(na):
                        Pc[i, j] -= bi * Ph[j]
                lw[c] += lam
                continue
            lmax = -np.inf
            for l in range(L):
                if mix_logw[kd, l] == -np.inf:
                    ll[l] = -np.inf
                    continue
                s = hPh + mix_var[kd, l] * rk
                if not (s > 0.0):
                    return False
                e = y - mix_mu[kd, l] * sig
                ll[l] = mix_logw[kd, l] - 0.5 * (_LOG2PI + math.log(s) + e * e / s)
                if ll[l] > lmax:
                    lmax = ll[l]
            tot = 0.0
            for l in range(L):
                ex[l] = math.exp(ll[l] - lmax)
                tot += ex[l]
            lam = lmax + math.log(tot)
            a = 0.0
            e2 = 0.0
            inv = 0.0
            for l in range(L):
                if ex[l] == 0.0:
                    continue
                rho = ex[l] / tot
                s = hPh + mix_var[kd, l] * rk
                g = (y - mix_mu[kd, l] * sig) / s
                a += rho * g
                e2 += rho * g * g
                inv += rho / s
            b = inv - (e2 - a * a)
            if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(lam)):
                return False
            for i in range(na):
                Xc[i] += Ph[i] * a
            # full rows (contiguous, vectorised); symmetric by construction
            for i in range(na):
                bi = b * Ph[i]
                for j in range(na):
                    Pc[i, j] -= bi * Ph[j]
            lw[c] += lam
    return True


@njit(cache=True)
def bank_log_likelihood(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var):
    """``log p(z)`` of an epoch under the bank (an IMM mode's score): the rise of the log
    total weight over a sequential update of a copy (:func:`bank_update`); -inf when that
    update fails. The bank itself is unchanged."""
    lw2, X2, P2 = lw.copy(), X.copy(), P.copy()
    if not bank_update(lw2, X2, P2, z, H, r, kinds, mix_logw, mix_mu, mix_var):
        return -np.inf
    return _logsumexp(lw2) - _logsumexp(lw)


@njit(cache=True)
def _logsumexp(a):
    m = a.max()
    if not np.isfinite(m):
        return m
    s = 0.0
    for v in a:
        s += math.exp(v - m)
    return m + math.log(s)


@njit(cache=True)
def bank_reduce(lw, X, P, max_components, n):
    """Merge pairs until at most ``max_components`` remain (Salmond's criterion).

    The pair with the smallest ``w_i w_j / (w_i + w_j) |L^-1 (x_i - x_j)|^2``
    is merged first, ``L`` the Cholesky factor of the whole bank's error-state
    covariance (moment-preserving merges leave it unchanged, so the whitened
    means are computed once and merged linearly). Salmond's distance needs no
    determinant per pair, unlike Runnalls' bound (``GaussianMixture.reduce``):
    one merge pass costs ``O(N^2 n)`` instead of ``N^2`` Cholesky factorisations.

    Returns the reduced ``(lw, X, P)`` (new arrays), weights normalised.
    """
    N, na = X.shape
    w, xm, Pm = bank_moments(lw, X, P)
    if N <= max_components:
        out = np.log(w)
        return out, X, P
    Lc = np.empty((n, n))
    Pn = Pm[:n, :n].copy()
    if not cholesky_lower(Pn, Lc):  # fall back to the diagonal (never singular in practice)
        Lc[:, :] = 0.0
        for i in range(n):
            Lc[i, i] = math.sqrt(max(Pn[i, i], 1e-30))
    Y = np.empty((N, n))
    for c in range(N):
        for i in range(n):
            s = X[c, i] - xm[i]
            for k in range(i):
                s -= Lc[i, k] * Y[c, k]
            Y[c, i] = s / Lc[i, i]
    D = np.full((N, N), np.inf)
    for i in range(N):
        for j in range(i + 1, N):
            d2 = 0.0
            for k in range(n):
                t = Y[i, k] - Y[j, k]
                d2 += t * t
            D[i, j] = w[i] * w[j] / (w[i] + w[j]) * d2
    alive = np.ones(N, dtype=np.bool_)
    Xw = X.copy()
    Pw = P.copy()
    for _ in range(N - max_components):
        best = np.inf
        bi, bj = 0, 1
        for i in range(N):
            if not alive[i]:
                continue
            for j in range(i + 1, N):
                if alive[j] and D[i, j] < best:
                    best = D[i, j]
                    bi, bj = i, j
        if best == np.inf:  # all remaining distances overflowed: merge the two lightest
            bi, bj = -1, -1
            for i in range(N):
                if alive[i] and (bi < 0 or w[i] < w[bi]):
                    bj = bi
                    bi = i
                elif alive[i] and (bj < 0 or w[i] < w[bj]):
                    bj = i
            if bi > bj:
                bi, bj = bj, bi
        wi, wj = w[bi], w[bj]
        ws = wi + wj
        a = wi / ws
        b = wj / ws
        for p in range(na):
            dp = Xw[bi, p] - Xw[bj, p]
            for q in range(na):
                dq = Xw[bi, q] - Xw[bj, q]
                Pw[bi, p, q] = a * Pw[bi, p, q] + b * Pw[bj, p, q] + a * b * dp * dq
        for p in range(na):
            Xw[bi, p] = a * Xw[bi, p] + b * Xw[bj, p]
        for k in range(n):
            Y[bi, k] = a * Y[bi, k] + b * Y[bj, k]
        w[bi] = ws
        alive[bj] = False
        for j in range(N):
            if alive[j] and j != bi:
                d2 = 0.0
                for k in range(n):
                    t = Y[bi, k] - Y[j, k]
                    d2 += t * t
                v = w[bi] * w[j] / (w[bi] + w[j]) * d2
                if j < bi:
                    D[j, bi] = v
                else:
                    D[bi, j] = v
    keep = np.nonzero(alive)[0]
    K = keep.shape[0]
    lw2 = np.empty(K)
    X2 = np.empty((K, na))
    P2 = np.empty((K, na, na))
    for o in range(K):
        c = keep[o]
        lw2[o] = math.log(w[c])
        X2[o] = Xw[c]
        P2[o] = Pw[c]
    return lw2, X2, P2


@njit(cache=True)
def _row_nonzeros(H):
    m, na = H.shape
    nz = np.empty((m, na), dtype=np.int64)
    n_nz = np.zeros(m, dtype=np.int64)
    for k in range(m):
        for j in range(na):
            if H[k, j] != 0.0:
                nz[k, n_nz[k]] = j
                n_nz[k] += 1
    return nz, n_nz


@njit(cache=True)
def _effective_pass(x, P, z, H, r, lam, off, nz, n_nz, Ph):
    """Sequential scalar Kalman updates of ``(x, P)`` (in place) by the effective rows
    ``(z_k - off_k, 1 / lam_k)``; returns the sum of their predictive log-densities, or
    NaN when a predicted variance is not positive."""
    m, na = H.shape
    ll = 0.0
    for k in range(m):
        for i in range(na):
            Ph[i] = 0.0
        hx = 0.0
        for q in range(n_nz[k]):
            j = nz[k, q]
            h = H[k, j]
            hx += h * x[j]
            for i in range(na):
                Ph[i] += P[j, i] * h
        hPh = 0.0
        for q in range(n_nz[k]):
            hPh += H[k, nz[k, q]] * Ph[nz[k, q]]
        s = hPh + 1.0 / lam[k]
        if not (s > 0.0):
            return np.nan
        y = z[k] - off[k] - hx
        ll += -0.5 * (_LOG2PI + math.log(s) + y * y / s)
        g = y / s
        for i in range(na):
            x[i] += Ph[i] * g
        for i in range(na):
            bi = Ph[i] / s
            for j in range(na):
                P[i, j] -= bi * Ph[j]
    return ll


@njit(cache=True)
def _effective_rows(rho, r, kinds, mix_mu, mix_var, lam, off):
    m, L = rho.shape
    for k in range(m):
        kd = kinds[k]
        a = 0.0
        b = 0.0
        sig = math.sqrt(r[k])
        for l in range(L):
            if rho[k, l] > 0.0:
                inv = rho[k, l] / (mix_var[kd, l] * r[k])
                a += inv
                b += inv * mix_mu[kd, l] * sig
        lam[k] = a
        off[k] = b / a


@njit(cache=True)
def _responsibilities(x, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, nz, n_nz, rho, expected):
    """``rho`` (m, L) of every row's noise components given ``q(x) = N(x, P)``: with
    ``expected`` the variational ones (the state's variance ``h P h^T`` in the exponent),
    else the predictive ones (in the variance). Returns the largest change."""
    m, L = rho.shape
    ll = np.empty(L)
    change = 0.0
    for k in range(m):
        kd = kinds[k]
        hx = 0.0
        hPh = 0.0
        for q in range(n_nz[k]):
            j = nz[k, q]
            hx += H[k, j] * x[j]
            for q2 in range(n_nz[k]):
                hPh += H[k, j] * P[j, nz[k, q2]] * H[k, nz[k, q2]]
        y = z[k] - hx
        sig = math.sqrt(r[k])
        lmax = -np.inf
        for l in range(L):
            if mix_logw[kd, l] == -np.inf:
                ll[l] = -np.inf
                continue
            v = mix_var[kd, l] * r[k]
            e = y - mix_mu[kd, l] * sig
            if expected:
                ll[l] = mix_logw[kd, l] - 0.5 * (math.log(v) + (e * e + hPh) / v)
            else:
                s = v + hPh
                ll[l] = mix_logw[kd, l] - 0.5 * (math.log(s) + e * e / s)
            if ll[l] > lmax:
                lmax = ll[l]
        tot = 0.0
        for l in range(L):
            ll[l] = math.exp(ll[l] - lmax) if ll[l] > -np.inf else 0.0
            tot += ll[l]
        for l in range(L):
            v = ll[l] / tot
            d = abs(v - rho[k, l])
            if d > change:
                change = d
            rho[k, l] = v
    return change


@njit(cache=True)
def bank_update_whole(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, xm, Pm, iterations, tol, rho):
    """The whole-epoch mixture update (module docstring) of every component, in place.

    ``xm``, ``Pm``: the bank's merged moments (the variational fixed point runs on them);
    ``iterations`` (>= 1) the most passes, ``tol`` the largest change of a responsibility
    that ends them; ``rho`` (m, L) receives the responsibilities used. Returns the number
    of passes, or -1 when a variance is not positive or a value not finite (the caller
    rejects the epoch).
    """
    N, na = X.shape
    m = z.shape[0]
    nz, n_nz = _row_nonzeros(H)
    lam = np.empty(m)
    off = np.empty(m)
    Ph = np.empty(na)
    for k in range(m):
        for l in range(rho.shape[1]):
            rho[k, l] = 0.0
    _responsibilities(xm, Pm, z, H, r, kinds, mix_logw, mix_mu, mix_var, nz, n_nz, rho, False)
    x = np.empty(na)
    Pc = np.empty((na, na))
    new = np.empty_like(rho)
    L = rho.shape[1]
    passes = 0
    # 1. one row at a time: while some row's assignment would change by more than a half,
    #    move only the row that would change most, then re-fit the state (coordinate ascent
    #    of the same bound; like data snooping, it does not let a majority of rows that
    #    disagree with a few gross ones swing together into a wrong fixed point)
    for it in range(m + 1):
        passes += 1
        _effective_rows(rho, r, kinds, mix_mu, mix_var, lam, off)
        x[:] = xm
        Pc[:, :] = Pm
        if not np.isfinite(_effective_pass(x, Pc, z, H, r, lam, off, nz, n_nz, Ph)):
            return -1
        new[:, :] = rho
        _responsibilities(x, Pc, z, H, r, kinds, mix_logw, mix_mu, mix_var, nz, n_nz, new, True)
        worst, kw = 0.0, -1
        for k in range(m):
            for l in range(L):
                d = abs(new[k, l] - rho[k, l])
                if d > worst:
                    worst, kw = d, k
        if worst <= 0.5:
            break
        for l in range(L):
            rho[kw, l] = new[kw, l]
    # 2. then all rows together until no responsibility moves by more than tol
    rho[:, :] = new
    for it in range(iterations):
        if it > 0:
            passes += 1
        _effective_rows(rho, r, kinds, mix_mu, mix_var, lam, off)
        x[:] = xm
        Pc[:, :] = Pm
        if not np.isfinite(_effective_pass(x, Pc, z, H, r, lam, off, nz, n_nz, Ph)):
            return -1
        change = _responsibilities(x, Pc, z, H, r, kinds, mix_logw, mix_mu, mix_var, nz, n_nz, rho, True)
        if change < tol:
            break
    _effective_rows(rho, r, kinds, mix_mu, mix_var, lam, off)
    for c in range(N):
        ll = _effective_pass(X[c], P[c], z, H, r, lam, off, nz, n_nz, Ph)
        if not np.isfinite(ll):
            return -1
        lw[c] += ll
    return passes


#: Status codes of :func:`bank_epoch` (the values of mixnav.filters._ekf_kernels).
_OK, _NOT_PD, _ABSURD, _NON_FINITE, _NEEDS_REPAIR = 0, 1, 2, 3, 4


@njit(cache=True)
def bank_epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n):
    """One measurement of the bank in one call: gate the merged prediction,
    NIS, per-row mixture update, reduction, merged correction.

    Returns ``(status, nis, lw, X, P, dx)``: on ``_OK``/``_NEEDS_REPAIR`` the
    new bank re-centred on its merged mean and that mean ``dx`` (na,), which
    the caller feeds back; otherwise the bank unchanged and ``dx`` zero.
    """
    empty = np.empty(0)
    return _epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                  False, empty, empty, 0, 0.0, np.empty((0, 0)))


@njit(cache=True)
def bank_epoch_collect(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                       u, q):
    """:func:`bank_epoch` that also writes, per row ``k``, the standardised
    innovation of the merged prediction ``u[k] = (z_k - h_k x_m) / sigma_k``
    and the state's share of its variance ``q[k] = h_k P_m h_k^T / sigma_k^2``
    (``sigma_k^2 = r_k``; ``u``, ``q`` preallocated, length >= m) -- what the
    online mixture learner (:mod:`mixnav.noise.learn.online`) collects. Written
    before the gate, so also for a rejected epoch. The returned values are
    bitwise those of :func:`bank_epoch`."""
    return _epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                  True, u, q, 0, 0.0, np.empty((0, 0)))


@njit(cache=True)
def bank_epoch_gated(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n, gate,
                     collect, u, q):
    """:func:`bank_epoch` (with ``collect``: :func:`bank_epoch_collect`) with the row-by-row
    update's convergence gate (:func:`bank_update_gated`)."""
    return _epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                  collect, u, q, 0, 0.0, np.empty((0, 0)), gate)


@njit(cache=True)
def bank_epoch_whole(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                     iterations, tol, rho, collect, u, q):
    """:func:`bank_epoch` (with ``collect``: :func:`bank_epoch_collect`) with the whole-epoch
    mixture update (:func:`bank_update_whole`: ``iterations`` >= 1, ``tol``; the
    responsibilities used written into ``rho`` (>= m, L)) instead of the row-by-row one."""
    return _epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                  collect, u, q, iterations, tol, rho)


@njit(cache=True)
def _epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n, collect, u, q,
           iterations, tol, rho, gate=np.inf):
    na = X.shape[1]
    zero = np.zeros(na)
    w, xm, Pm = bank_moments(lw, X, P)
    for i in range(na):  # a NaN bank is a fault to raise, not an epoch to reject as "not PD"
        if not (np.isfinite(xm[i]) and np.isfinite(Pm[i, i])):
            return _NON_FINITE, np.inf, lw, X, P, zero
    m = z.shape[0]
    y = z.copy()
    for i in range(m):
        for k in range(na):
            y[i] -= H[i, k] * xm[k]
    if collect:
        for i in range(m):
            s = 0.0
            for a in range(na):
                ha = H[i, a]
                if ha != 0.0:
                    acc = 0.0
                    for b in range(na):
                        acc += Pm[a, b] * H[i, b]
                    s += ha * acc
            u[i] = y[i] / math.sqrt(r[i])
            q[i] = s / r[i]
    if innovation_is_absurd(y, H, Pm, r, n_sigma):
        return _ABSURD, np.inf, lw, X, P, zero
    nis, _ = predicted_nis(xm, Pm, z, H, r)
    if not np.isfinite(nis):
        return _NOT_PD, nis, lw, X, P, zero
    lw2, X2, P2 = lw.copy(), X.copy(), P.copy()
    if iterations > 0:
        if bank_update_whole(lw2, X2, P2, z, H, r, kinds, mix_logw, mix_mu, mix_var, xm, Pm, iterations, tol,
                             rho[:m]) < 0:
            return _NOT_PD, nis, lw, X, P, zero
    elif not bank_update_gated(lw2, X2, P2, z, H, r, kinds, mix_logw, mix_mu, mix_var, gate):
        return _NOT_PD, nis, lw, X, P, zero
    lw2, X2, P2 = bank_reduce(lw2, X2, P2, max_components, n)
    K = lw2.shape[0]
    dx = np.zeros(na)
    for c in range(K):
        wc = math.exp(lw2[c])
        for i in range(na):
            dx[i] += wc * X2[c, i]
    for i in range(na):
        if not np.isfinite(dx[i]):
            return _NON_FINITE, nis, lw, X, P, zero
    status = _OK
    for c in range(K):
        if not np.isfinite(lw2[c]):
            return _NON_FINITE, nis, lw, X, P, zero
        for i in range(na):
            X2[c, i] -= dx[i]
            if i < n and not (P2[c, i, i] > 0.0):
                status = _NEEDS_REPAIR
    return status, nis, lw2, X2, P2, dx
