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

Two guards keep this update from losing the state (P1's epoch-0 trap: gross
errors meeting a state that is not yet known, or is off, make the first rows set
the state and the mixture explain the later, correct rows away), both in
:func:`bank_update_gated` / :func:`bank_epoch_guarded`:

- *convergence gate*: a row whose state share of the predicted variance
  ``h P h^T`` exceeds ``gate * r`` is updated with its noise mixture's
  moment-matched Gaussian (mean ``sum pi_l mu_l``, the mixture's variance), not
  the mixture: the assignment of a row to a component is trusted only once the
  state is known better than the noise;
- *outlier components*: a component whose standardised mean exceeds
  ``outlier_mean`` weighs the row with its density, but a child it explains
  keeps the prior (the row is not used) instead of being corrected by its mean,
  so a state error of the size of the gross errors cannot be absorbed as
  "gross errors on these rows" (the rows the mixture calls gross are left out,
  and the others still pull the state back).

With ``gate = outlier_mean = inf`` it is the plain update above.
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
    return bank_update_gated(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, np.inf, np.inf)


@njit(cache=True, fastmath={"reassoc", "contract"})
def bank_update_gated(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, gate, outlier_mean):
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
    outlier_mean : float
        A noise component whose standardised mean exceeds this in magnitude is an outlier
        component: it weighs the row (its density with its mean) but a child it explains
        keeps the prior (the row is not used), instead of being corrected by the mean
        (``inf``: every component corrects).

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
                if abs(mix_mu[kd, l]) > outlier_mean:
                    continue          # this child keeps the prior: g = 0, no 1/s
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


#: Status codes of :func:`bank_epoch` (the values of mixnav.filters._ekf_kernels).
_OK, _NOT_PD, _ABSURD, _NON_FINITE, _NEEDS_REPAIR = 0, 1, 2, 3, 4


# bank_epoch and bank_epoch_collect are Python wrappers of bank_epoch_guarded, not kernels: a
# kernel passing the constant False/True would compile _epoch once more per constant (numba
# specialises a literal argument; measured 4-5 s each on a cold cache), and the filter calls
# only bank_epoch_guarded. The wrappers' own cost is a Python call (< 1 us against 63 us).
_NO_ROWS = np.empty(0)


def bank_epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n):
    """One measurement of the bank in one call: gate the merged prediction,
    NIS, per-row mixture update, reduction, merged correction.

    Returns ``(status, nis, lw, X, P, dx)``: on ``_OK``/``_NEEDS_REPAIR`` the
    new bank re-centred on its merged mean and that mean ``dx`` (na,), which
    the caller feeds back; otherwise the bank unchanged and ``dx`` zero.
    """
    return bank_epoch_guarded(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                              np.inf, np.inf, False, _NO_ROWS, _NO_ROWS)


def bank_epoch_collect(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                       u, q):
    """:func:`bank_epoch` that also writes, per row ``k``, the standardised
    innovation of the merged prediction ``u[k] = (z_k - h_k x_m) / sigma_k``
    and the state's share of its variance ``q[k] = h_k P_m h_k^T / sigma_k^2``
    (``sigma_k^2 = r_k``; ``u``, ``q`` preallocated, length >= m) -- what the
    online mixture learner (:mod:`mixnav.noise.learn.online`) collects. Written
    before the gate, so also for a rejected epoch. The returned values are
    bitwise those of :func:`bank_epoch`."""
    return bank_epoch_guarded(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                              np.inf, np.inf, True, u, q)


@njit(cache=True)
def bank_epoch_guarded(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n, gate,
                       outlier_mean, collect, u, q):
    """:func:`bank_epoch` (with ``collect``: :func:`bank_epoch_collect`) with the two guards
    of the module docstring (``gate``, ``outlier_mean``; ``inf`` turns each off)."""
    return _epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n,
                  collect, u, q, gate, outlier_mean)


@njit(cache=True)
def _epoch(lw, X, P, z, H, r, kinds, mix_logw, mix_mu, mix_var, n_sigma, max_components, n, collect, u, q,
           gate, outlier_mean):
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
    if not bank_update_gated(lw2, X2, P2, z, H, r, kinds, mix_logw, mix_mu, mix_var, gate, outlier_mean):
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
