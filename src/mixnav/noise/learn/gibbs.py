"""Gibbs sampling of the conjugate Bayesian Gaussian mixture (same model as the VB learner).

Model: ``pi ~ Dir(alpha0)``, ``Lambda_k ~ Wishart(W0, nu0)``,
``mu_k | Lambda_k ~ N(m0, (beta0 Lambda_k)^-1)``, ``z_n ~ Cat(pi)``,
``x_n | z_n = k ~ N(mu_k, Lambda_k^-1)`` (paper P1 eqs. 13-17).

One sweep samples, in turn:

1. ``pi | z ~ Dir(alpha0 + N_k)``
2. ``Lambda_k | z ~ Wishart(W_k, nu_k)`` and ``mu_k | Lambda_k, z ~ N(m_k, (beta_k Lambda_k)^-1)``,
   with (alpha_k, beta_k, m_k, W_k, nu_k) the conjugate update of P1 eqs. 23-25
   computed from the hard labels (the VB M-step with one-hot responsibilities);
3. ``z_n | pi, mu, Lambda`` ~ Categorical.

Label switching. The kept draws are first ordered by the mean of the first
dimension (the usual identifiability constraint). That is adequate when the
components are separated along the first dimension, but not for a scale
mixture: P1's noises are zero-mean components that differ only in variance,
so ordering by the mean swaps their labels at random and the posterior means
blend them. By default (``relabel="pivot"``) the draws are then relabelled
to match a pivot (Celeux's / Stephens' relabelling): each draw takes the
permutation of its components closest to the pivot in the means (scaled by
the pivot's variances) and the log variances, the pivot starts as the last
draw and becomes the mean of the relabelled draws, until no draw changes
(at most 20 passes). ``relabel="mean"`` keeps the ordering by the mean alone.

The priors default exactly as in :class:`~mixnav.noise.learn.vb.VariationalGaussianMixture`.

Two implementations of the sweeps sample the same chain distribution:

* ``backend="numba"`` (the default) -- :func:`_gibbs_loop`, a compiled kernel.
  One pass over the samples per sweep draws the labels and accumulates the
  hard-label sufficient statistics (counts, sums and scatter about the data
  mean) for the next sweep; there are no per-sweep allocations.  The Wishart
  draw uses the Cholesky factor ``U`` of ``W_k^-1`` directly
  (``Lambda = U^-T A A^T U^-1`` with ``A`` the Bartlett factor), so ``mu_k``,
  the label step's whitening ``A^T U^-1`` and ``Sigma_k = (U A^-T)(U A^-T)^T``
  need triangular solves only.  A label is drawn by inverting the categorical
  CDF with one uniform per sample (the numpy path uses the Gumbel-max trick,
  K Gumbel draws per sample: same distribution).  Random numbers come from
  numba's own generator, seeded by a 32-bit integer drawn from the caller's
  numpy Generator, so a fit is reproducible from ``random_state`` but the
  chain is not the numpy path's chain draw for draw.  It is the default
  because it samples the same posterior (tested against the closed form and
  against the numpy path) about 9x faster on the P1 training problem (1-D,
  n = 2000, K = 4: 57 us per sweep against 525 us; benchmarks/results/gibbs.md).
  For d > 1 the label step is a plain per-sample loop (:func:`_label_pass`, not
  blocked): about 4x faster than numpy in 3-D (measured once, n = 2000, K = 4).
* ``backend="numpy"`` -- :func:`_gibbs_loop_numpy`, the original vectorised
  numpy sweep, kept as the reference the tests compare the kernel with.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from mixnav.noise.learn.base import MixtureLearner
from mixnav.noise.learn.em import check_random_state, kmeanspp_resp, validate_data
from mixnav.noise.learn.vb import (_BLOCK, VariationalGaussianMixture, _chol_lower, _exp_nonpos, _m_step,
                                   _tril_inv)
from mixnav.noise.mixture import GaussianMixture

_LOG2PI = np.log(2.0 * np.pi)
_BACKENDS = ("numba", "numpy")


# --------------------------------------------------------------------------
# numpy reference sweep
# --------------------------------------------------------------------------
def _sample_wishart(rng, Winv, nu):
    """One draw per component of Wishart(W_k, nu_k) given W_k^-1 (K, d, d) (Bartlett decomposition)."""
    K, d = Winv.shape[:2]
    L = np.linalg.cholesky(np.linalg.inv(Winv))                       # W = L L^T
    A = np.zeros((K, d, d))
    il = np.tril_indices(d, -1)
    A[:, il[0], il[1]] = rng.standard_normal((K, len(il[0])))
    A[:, np.arange(d), np.arange(d)] = np.sqrt(rng.chisquare(nu[:, None] - np.arange(d)[None, :]))
    LA = np.matmul(L, A)
    return np.matmul(LA, np.swapaxes(LA, 1, 2))


def _gibbs_loop_numpy(X, z, prior, burn, rng, cw, cm, cc):
    """``burn + S`` sweeps from labels ``z`` (n,); the kept draws go into ``cw, cm, cc`` (S, ...)."""
    n, d = X.shape
    K = cw.shape[1]
    for t in range(burn + cw.shape[0]):
        onehot = np.zeros((n, K))
        onehot[np.arange(n), z] = 1.0
        alpha, beta, m, nu, Winv = _m_step(X, onehot, prior)        # conjugate update, P1 eqs. 23-25
        pi = rng.dirichlet(alpha)
        lam = _sample_wishart(rng, Winv, nu)
        C = np.linalg.cholesky(beta[:, None, None] * lam)            # C C^T = beta_k Lambda_k
        eps = rng.standard_normal((K, d, 1))
        mu = m + np.linalg.solve(np.swapaxes(C, 1, 2), eps)[..., 0]  # cov C^-T C^-1
        # labels: log pi_k + log N(x_n | mu_k, Lambda_k^-1), Gumbel-max
        Lc = np.linalg.cholesky(lam)                                 # Lambda = Lc Lc^T
        y = np.matmul(X[None] - mu[:, None, :], Lc)                  # (K, n, d)
        logdet = 2.0 * np.sum(np.log(np.diagonal(Lc, axis1=1, axis2=2)), axis=1)
        logp = (np.log(pi) + 0.5 * logdet)[None, :] - 0.5 * np.einsum("kni,kni->nk", y, y)
        z = np.argmax(logp + rng.gumbel(size=(n, K)), axis=1)
        if t >= burn:
            s = t - burn
            order = np.argsort(mu[:, 0], kind="stable")
            cw[s] = pi[order]
            cm[s] = mu[order]
            cc[s] = np.linalg.inv(lam[order])


# --------------------------------------------------------------------------
# compiled sweep
# --------------------------------------------------------------------------
@numba.njit(cache=True)
def _hard_stats(X, c, z, cnt, s1, s2):
    """Counts, sums and scatter of ``X - c`` per label (the initial labels' statistics)."""
    n, d = X.shape
    cnt[:] = 0.0
    s1[:] = 0.0
    s2[:] = 0.0
    for i in range(n):
        k = z[i]
        cnt[k] += 1.0
        for a in range(d):
            xa = X[i, a] - c[a]
            s1[k, a] += xa
            for b in range(a + 1):
                s2[k, a, b] += xa * (X[i, b] - c[b])


@numba.njit(cache=True)
def _draw_params(cnt, s1, s2, alpha0, beta0, m0c, nu0, w0inv, pi, mu, ld, M, cov, U, A, Ui, G, v, e):
    """Steps 1-2 of a sweep: ``pi``, ``Lambda_k``, ``mu_k`` given the hard-label statistics.

    ``s1, s2`` are about the data mean ``c``; ``m0c = m0 - c`` and ``mu`` are too.
    Writes ``pi`` (K,), ``mu`` (K, d), ``ld[k] = ln pi_k + ln|Lambda_k| / 2``,
    ``M[k] = A^T U^-1`` (so that ``(x - mu)^T Lambda (x - mu) = |M (x - mu)|^2``)
    and ``cov[k] = Lambda_k^-1``.
    """
    K, d = s1.shape
    gsum = 0.0
    for k in range(K):
        nk = cnt[k]
        pi[k] = np.random.gamma(alpha0 + nk, 1.0)               # Dir(alpha0 + N_k), P1 eq. (23)
        gsum += pi[k]
        beta = beta0 + nk                                         # P1 eq. (24)
        nu = nu0 + nk                                             # P1 eq. (25)
        # m_k (about c) and W_k^-1 = W0^-1 + N_k S_k + beta0 N_k / beta_k (xbar - m0)(xbar - m0)^T
        for a in range(d):
            xb = s1[k, a] / nk if nk > 0.0 else 0.0
            v[a] = xb - m0c[a]                                    # xbar - m0
            e[a] = (beta0 * m0c[a] + s1[k, a]) / beta             # m_k, P1 eq. (24)
        f = beta0 * nk / beta
        for a in range(d):
            for b in range(a + 1):
                sc = s2[k, a, b] - (s1[k, a] * s1[k, b] / nk if nk > 0.0 else 0.0)   # N_k S_k
                A[a, b] = w0inv[a, b] + sc + f * v[a] * v[b]      # P1 eq. (25) (lower triangle)
        # U U^T = W_k^-1 (the matrix is SPD: W0^-1 SPD plus PSD terms; only its lower triangle is read)
        _chol_lower(A, U)
        _tril_inv(U, Ui)                                  # Ui = U^-1 (lower triangular)
        # Bartlett factor A (lower): A_jj^2 ~ chi2(nu - j), A_ij ~ N(0, 1) below the diagonal;
        # Lambda = L A A^T L^T with L = U^-T (L L^T = W_k) is Wishart(W_k, nu_k)
        logdet = 0.0
        for j in range(d):
            A[j, j] = math.sqrt(np.random.chisquare(nu - j))
            logdet += 2.0 * (math.log(A[j, j]) - math.log(U[j, j]))
            for i in range(j + 1, d):
                A[i, j] = np.random.standard_normal()
            for i in range(j):
                A[i, j] = 0.0
        ld[k] = 0.5 * logdet
        # M = A^T U^-1 (upper times lower)
        for a in range(d):
            for b in range(d):
                s = 0.0
                for p in range(max(a, b), d):
                    s += A[p, a] * Ui[p, b]
                M[k, a, b] = s
        # G = U A^-T: first A^-T (upper) by back substitution into G's columns, then U times it;
        # Sigma_k = G G^T, and mu_k = m_k + G eps / sqrt(beta_k) has covariance (beta_k Lambda_k)^-1
        for j in range(d):                    # column j of A^-T: solve A^T g = e_j
            for i in range(d - 1, -1, -1):
                s = 1.0 if i == j else 0.0
                for p in range(i + 1, d):
                    s -= A[p, i] * v[p]
                v[i] = s / A[i, i]
            for i in range(d):
                s = 0.0
                for p in range(i + 1):
                    s += U[i, p] * v[p]
                G[i, j] = s
        for i in range(d):
            v[i] = np.random.standard_normal()
        sb = 1.0 / math.sqrt(beta)
        for i in range(d):
            s = 0.0
            for p in range(d):
                s += G[i, p] * v[p]
            mu[k, i] = e[i] + sb * s
            for j in range(i + 1):
                s = 0.0
                for p in range(d):
                    s += G[i, p] * G[j, p]
                cov[k, i, j] = s
                cov[k, j, i] = s
    for k in range(K):
        pi[k] /= gsum
        ld[k] += math.log(pi[k])


@numba.njit(cache=True)
def _label_pass1(x, z, pi, mu, ld, M, cnt, s1, s2, lr, tmp, mx, ibuf, kb):
    """Step 3 for d = 1, fused with the statistics of the new labels (``x`` about the data mean).

    Samples in blocks of ``_BLOCK`` with the loops over the samples innermost (SIMD), ``exp``
    by the vectorisable :func:`~mixnav.noise.learn.vb._exp_nonpos`; ``lr`` (K, _BLOCK),
    ``tmp, mx`` (_BLOCK,) and ``ibuf, kb`` (_BLOCK,) int64 are work arrays.
    """
    n = x.shape[0]
    K = pi.shape[0]
    cnt[:] = 0.0
    s1[:] = 0.0
    s2[:] = 0.0
    for lo in range(0, n, _BLOCK):
        nb = min(_BLOCK, n - lo)
        for k in range(K):
            a = M[k, 0, 0]
            m = mu[k, 0]
            c = ld[k]
            out = lr[k]
            for s in range(nb):
                y = a * (x[lo + s] - m)
                out[s] = c - 0.5 * y * y                  # ln pi_k + ln N(x | mu_k, 1/Lambda_k) + const
        for s in range(nb):
            mx[s] = lr[0, s]
        for k in range(1, K):
            for s in range(nb):
                mx[s] = max(mx[s], lr[k, s])
        for k in range(K):
            out = lr[k]
            for s in range(nb):
                tmp[s] = out[s] - mx[s]
            _exp_nonpos(tmp, out, ibuf, nb)
        for k in range(1, K):                             # cumulative: the categorical's CDF
            for s in range(nb):
                lr[k, s] += lr[k - 1, s]
        for s in range(nb):                               # the uniforms (numba's generator is scalar)
            tmp[s] = np.random.random() * lr[K - 1, s]
        # label = number of CDF values <= u: branch-free and vectorised (a search loop mispredicts)
        for s in range(nb):
            kb[s] = 0
        for k in range(K - 1):
            cdf = lr[k]
            for s in range(nb):
                kb[s] += cdf[s] <= tmp[s]
        for s in range(nb):
            k = kb[s]
            xi = x[lo + s]
            z[lo + s] = k
            cnt[k] += 1.0
            s1[k, 0] += xi
            s2[k, 0, 0] += xi * xi


@numba.njit(cache=True)
def _label_pass(X, z, pi, mu, ld, M, cnt, s1, s2, lp, y):
    """Step 3 for any d, fused with the statistics of the new labels (``X`` about the data mean)."""
    n, d = X.shape
    K = pi.shape[0]
    cnt[:] = 0.0
    s1[:] = 0.0
    s2[:] = 0.0
    for i in range(n):
        mx = -np.inf
        for k in range(K):
            for a in range(d):
                y[a] = X[i, a] - mu[k, a]
            q = 0.0
            for a in range(d):
                s = 0.0
                for b in range(d):
                    s += M[k, a, b] * y[b]
                q += s * s
            q = ld[k] - 0.5 * q
            lp[k] = q
            if q > mx:
                mx = q
        tot = 0.0
        for k in range(K):
            tot += math.exp(lp[k] - mx)
            lp[k] = tot
        u = np.random.random() * tot
        k = 0
        for j in range(K - 1):                                # number of CDF values <= u (branch-free)
            k += lp[j] <= u
        z[i] = k
        cnt[k] += 1.0
        for a in range(d):
            xa = X[i, a]
            s1[k, a] += xa
            for b in range(a + 1):
                s2[k, a, b] += xa * X[i, b]


@numba.njit(cache=True)
def _gibbs_loop(Xc, z, alpha0, beta0, m0c, nu0, w0inv, burn, seed, cw, cm, cc):
    """``burn + S`` sweeps from labels ``z`` (n,) on data ``Xc`` (n, d) centred on its mean.

    ``m0c`` is the prior mean minus the same centre; the kept draws (``cm`` about
    the centre too) go into ``cw`` (S, K), ``cm`` (S, K, d), ``cc`` (S, K, d, d),
    each ordered by the first coordinate of the means.
    """
    np.random.seed(seed)
    n, d = Xc.shape
    S, K = cw.shape
    cnt = np.empty(K)
    s1 = np.empty((K, d))
    s2 = np.empty((K, d, d))
    pi = np.empty(K)
    mu = np.empty((K, d))
    ld = np.empty(K)
    M = np.empty((K, d, d))
    cov = np.empty((K, d, d))
    U = np.empty((d, d))
    A = np.empty((d, d))
    Ui = np.empty((d, d))
    G = np.empty((d, d))
    v = np.empty(d)
    e = np.empty(d)
    lp = np.empty(K)
    y = np.empty(d)
    order = np.empty(K, dtype=np.int64)
    lr = np.empty((K, _BLOCK))
    tmp = np.empty(_BLOCK)
    mx = np.empty(_BLOCK)
    ibuf = np.empty(_BLOCK, dtype=np.int64)
    kb = np.empty(_BLOCK, dtype=np.int64)
    x1 = Xc[:, 0].copy()
    _hard_stats(Xc, np.zeros(d), z, cnt, s1, s2)
    for t in range(burn + S):
        _draw_params(cnt, s1, s2, alpha0, beta0, m0c, nu0, w0inv, pi, mu, ld, M, cov, U, A, Ui, G, v, e)
        if t >= burn:
            s = t - burn
            # stable insertion sort of the components by mu[:, 0] (K is small)
            for k in range(K):
                order[k] = k
            for k in range(1, K):
                o = order[k]
                j = k - 1
                while j >= 0 and mu[order[j], 0] > mu[o, 0]:
                    order[j + 1] = order[j]
                    j -= 1
                order[j + 1] = o
            for k in range(K):
                o = order[k]
                cw[s, k] = pi[o]
                for a in range(d):
                    cm[s, k, a] = mu[o, a]
                    for b in range(d):
                        cc[s, k, a, b] = cov[o, a, b]
        if t < burn + S - 1:      # the labels after the last kept draw are not needed
            if d == 1:
                _label_pass1(x1, z, pi, mu, ld, M, cnt, s1, s2, lr, tmp, mx, ibuf, kb)
            else:
                _label_pass(Xc, z, pi, mu, ld, M, cnt, s1, s2, lp, y)


def relabel_to_pivot(cw, cm, cc, max_passes: int = 20) -> int:
    """Relabel the draws in place to match a pivot (module docstring); returns the passes.

    The cost of giving component ``k`` of a draw the label ``j`` of the pivot is
    ``sum_i (mu_ki - mu*_ji)^2 / v_i + (log S_k,ii - log S*_j,ii)^2`` with ``v_i``
    the pivot's mean variance of dimension ``i``; each draw takes the
    permutation of least total cost (all ``K!`` for ``K <= 6``, else the
    assignment problem per draw).
    """
    from itertools import permutations
    S, K, d = cm.shape
    if K == 1 or S == 0:
        return 0
    logv = np.log(np.maximum(np.diagonal(cc, axis1=2, axis2=3), 1e-300))      # (S, K, d)
    piv_m, piv_lv = cm[-1].copy(), logv[-1].copy()
    perms = np.array(list(permutations(range(K)))) if K <= 6 else None
    current = np.tile(np.arange(K), (S, 1))
    for npass in range(1, max_passes + 1):
        scale = np.exp(piv_lv).mean(axis=0)                                      # (d,)
        cost = (((cm[:, :, None, :] - piv_m[None, None]) ** 2) / scale).sum(-1) + \
            ((logv[:, :, None, :] - piv_lv[None, None]) ** 2).sum(-1)          # (S, k, j)
        if perms is not None:
            # perm p gives label perms[p, k] to component k; total cost per draw and perm
            tot = cost[:, np.arange(K)[None, :], perms].sum(-1)                 # (S, P)
            best = perms[np.argmin(tot, axis=1)]                                  # (S, K): label of k
        else:
            from scipy.optimize import linear_sum_assignment
            best = np.array([linear_sum_assignment(c)[1] for c in cost])
        order = np.argsort(best, axis=1)                                         # component of label j
        if np.array_equal(order, np.tile(np.arange(K), (S, 1))) and npass > 1:
            return npass
        idx = np.arange(S)[:, None]
        cw[:] = cw[idx, order]
        cm[:] = cm[idx, order]
        cc[:] = cc[idx, order]
        logv = logv[idx, order]
        current = current[idx, order]
        piv_m, piv_lv = cm.mean(axis=0), logv.mean(axis=0)
    return max_passes


class GibbsGaussianMixture(MixtureLearner):
    """Posterior-mean Gaussian mixture from a Gibbs sampler.

    Parameters
    ----------
    n_components : int, default 4
    n_samples : int, default 1000
        Number of kept draws (sweeps after burn-in).
    burn_in : None or int
        Discarded sweeps before the kept ones; ``None``: ``max(100, n_samples // 2)``.
    alpha0, beta0, nu0, W0, m0 : priors, as for VariationalGaussianMixture
    prune_threshold : float, default 0.01
        Used by :attr:`mixture_` only (drops components of small posterior-mean weight).
    random_state : None, int or numpy Generator
    relabel : {"pivot", "mean"}, default "pivot"
        How label switching is undone before averaging the draws (module
        docstring): ``"pivot"`` matches every draw to a pivot in means and
        variances; ``"mean"`` only orders the components by the first mean.
    backend : {"numba", "numpy"}, default "numba"
        ``"numba"``: the compiled sweep (default: the same posterior, about 9x
        faster in 1-D; module docstring); ``"numpy"``: the vectorised numpy reference.
        The two give different chains from the same ``random_state``.

    Attributes
    ----------
    weights_ : ndarray (K,)
    means_ : ndarray (K, d)
    covariances_ : ndarray (K, d, d)
        Posterior means over the kept, relabelled draws.
    chain_weights_ : ndarray (n_samples, K)
    chain_means_ : ndarray (n_samples, K, d)
    chain_covariances_ : ndarray (n_samples, K, d, d)
        The kept draws, relabelled (``relabel``).
    relabel_passes_ : int
        Passes of the pivot relabelling (0 with ``relabel="mean"``).
    burn_in_ : int
    prior_ : dict
    """

    def __init__(self, n_components=4, n_samples=1000, burn_in=None, alpha0=1.0, beta0=1.0, nu0=None,
                 W0=None, m0=None, prune_threshold=0.01, random_state=None, backend="numba",
                 relabel="pivot"):
        self.n_components = n_components
        self.n_samples = n_samples
        self.burn_in = burn_in
        self.alpha0 = alpha0
        self.beta0 = beta0
        self.nu0 = nu0
        self.W0 = W0
        self.m0 = m0
        self.prune_threshold = prune_threshold
        self.random_state = random_state
        self.backend = backend
        self.relabel = relabel

    def fit(self, X, sample_weight=None):
        """Run the chain on samples ``X`` (n, d) or (n,); returns self.

        ``sample_weight`` is not supported (hard labels need integer counts) and
        must be ``None``.
        """
        if sample_weight is not None:
            raise NotImplementedError("GibbsGaussianMixture does not support sample_weight")
        if self.backend not in _BACKENDS:
            raise ValueError(f"backend={self.backend!r}: use one of {_BACKENDS}")
        if self.relabel not in ("pivot", "mean"):
            raise ValueError(f"relabel={self.relabel!r}: use 'pivot' or 'mean'")
        K = int(self.n_components)
        X = validate_data(X, K)
        n, d = X.shape
        ones = np.ones(n)
        rng = check_random_state(self.random_state)
        vb = VariationalGaussianMixture(K, alpha0=self.alpha0, beta0=self.beta0, nu0=self.nu0, W0=self.W0,
                                        m0=self.m0)
        prior = vb._resolve_prior(X, ones)
        burn = max(100, int(self.n_samples) // 2) if self.burn_in is None else int(self.burn_in)
        S = int(self.n_samples)
        if S < 1 or burn < 0:
            raise ValueError("n_samples must be >= 1 and burn_in >= 0")
        z = np.argmax(kmeanspp_resp(X, K, rng), axis=1)
        cw = np.empty((S, K))
        cm = np.empty((S, K, d))
        cc = np.empty((S, K, d, d))
        if self.backend == "numpy":
            _gibbs_loop_numpy(X, z, prior, burn, rng, cw, cm, cc)
        else:
            alpha0, beta0, m0, nu0, W0inv = prior
            c = X.mean(axis=0)                  # sums about the mean: no cancellation in N_k S_k
            seed = int(rng.integers(0, 2**32 - 1))
            _gibbs_loop(np.ascontiguousarray(X - c), z.astype(np.int64), alpha0, beta0, m0 - c, nu0,
                        np.ascontiguousarray(W0inv), burn, seed, cw, cm, cc)
            cm += c
        self.relabel_passes_ = relabel_to_pivot(cw, cm, cc) if self.relabel == "pivot" else 0
        self.chain_weights_, self.chain_means_, self.chain_covariances_ = cw, cm, cc
        self.weights_ = cw.mean(axis=0)
        self.means_ = cm.mean(axis=0)
        cov = cc.mean(axis=0)
        self.covariances_ = 0.5 * (cov + np.swapaxes(cov, 1, 2))
        self.burn_in_ = burn
        self.prior_ = dict(alpha0=prior[0], beta0=prior[1], m0=prior[2], nu0=prior[3], W0=np.linalg.inv(prior[4]))
        return self

    @property
    def mixture_(self) -> GaussianMixture:
        """Posterior-mean mixture, pruned at ``prune_threshold``."""
        w = self.weights_ / self.weights_.sum()
        return GaussianMixture(w, self.means_, self.covariances_).prune(self.prune_threshold)
