"""Maximum likelihood EM for a full-covariance Gaussian mixture, with sample weights.

Also holds the input validation and initialisation shared by all learners in
:mod:`mixnav.noise.learn`.

Weighted EM (needed by paper P3) treats a sample weight ``w_n`` as a
replication count: every sum over samples becomes ``sum_n w_n (...)``, so
integer weights give exactly the fit of the data with rows repeated.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.special import logsumexp

from mixnav.noise.learn import ConvergenceWarning
from mixnav.noise.learn.base import MixtureLearner
from mixnav.noise.mixture import GaussianMixture

_LOG2PI = np.log(2.0 * np.pi)


# --------------------------------------------------------------------------
# shared helpers
# --------------------------------------------------------------------------
def check_random_state(random_state) -> np.random.Generator:
    """A numpy Generator from ``None``, an int or a Generator."""
    if isinstance(random_state, np.random.Generator):
        return random_state
    if random_state is None or isinstance(random_state, (int, np.integer)):
        return np.random.default_rng(random_state)
    raise TypeError(f"random_state must be None, an int or a numpy Generator, not {type(random_state).__name__}")


def validate_data(X, n_components: int) -> np.ndarray:
    """Check samples and return them as a float array (n, d).

    Raises ``ValueError`` for non-finite values (naming the first bad row),
    fewer samples than components, or data with zero variance.
    """
    X = np.asarray(X, dtype=float)
    if X.ndim == 1:
        X = X[:, None]
    if X.ndim != 2:
        raise ValueError(f"X must have shape (n,) or (n, d), got {X.shape}")
    finite = np.isfinite(X).all(axis=1)
    if not finite.all():
        row = int(np.argmin(finite))
        raise ValueError(f"X contains NaN or inf; first bad row is {row}: {X[row]}")
    n = X.shape[0]
    if n < n_components:
        raise ValueError(f"n_samples={n} is smaller than n_components={n_components}")
    if n_components < 1:
        raise ValueError("n_components must be at least 1")
    if np.all(np.ptp(X, axis=0) == 0.0):
        raise ValueError("the data has zero variance (all samples are identical); cannot fit a mixture")
    return X


def validate_weights(sample_weight, n: int) -> np.ndarray:
    """Sample weights (n,) (ones when ``None``); negative or non-finite -> ValueError."""
    if sample_weight is None:
        return np.ones(n)
    w = np.asarray(sample_weight, dtype=float).reshape(-1)
    if w.shape != (n,):
        raise ValueError(f"sample_weight has shape {w.shape}, expected ({n},)")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"sample_weight is not finite at index {int(np.argmin(np.isfinite(w)))}")
    if np.any(w < 0):
        raise ValueError(f"sample_weight is negative at index {int(np.argmax(w < 0))}")
    if w.sum() <= 0:
        raise ValueError("sample_weight sums to zero")
    return w


def kmeanspp_resp(X: np.ndarray, k: int, rng: np.random.Generator, w: np.ndarray | None = None) -> np.ndarray:
    """Hard responsibilities (n, K) from k-means++ seeding (D^2 sampling).

    Centres are picked with probability proportional to ``w_n * D_n^2``; each
    sample is then assigned to its nearest centre.
    """
    n = X.shape[0]
    w = np.ones(n) if w is None else w
    centres = np.empty((k, X.shape[1]))
    p = w / w.sum()
    centres[0] = X[rng.choice(n, p=p)]
    d2 = np.sum((X - centres[0]) ** 2, axis=1)
    for j in range(1, k):
        q = w * d2
        s = q.sum()
        idx = rng.choice(n, p=q / s) if s > 0 else rng.choice(n, p=p)
        centres[j] = X[idx]
        d2 = np.minimum(d2, np.sum((X - centres[j]) ** 2, axis=1))
    dist = np.sum((X[:, None, :] - centres[None]) ** 2, axis=2)
    resp = np.zeros((n, k))
    resp[np.arange(n), np.argmin(dist, axis=1)] = 1.0
    return resp


def random_resp(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """Random soft responsibilities (n, K) (uniform draws, normalised)."""
    r = rng.uniform(size=(n, k))
    return r / r.sum(axis=1, keepdims=True)


def check_resp(resp, n: int, k: int) -> np.ndarray:
    r = np.asarray(resp, dtype=float)
    if r.shape != (n, k):
        raise ValueError(f"initial responsibilities have shape {r.shape}, expected ({n}, {k})")
    if not np.all(np.isfinite(r)) or np.any(r < 0):
        raise ValueError("initial responsibilities must be finite and non-negative")
    s = r.sum(axis=1, keepdims=True)
    if np.any(s <= 0):
        raise ValueError("every row of the initial responsibilities needs a positive sum")
    return r / s


def weighted_moments(X: np.ndarray, wr: np.ndarray):
    """Soft counts, means and scatter of weighted responsibilities.

    Parameters
    ----------
    X : ndarray (n, d)
    wr : ndarray (n, K)
        ``sample_weight[:, None] * resp``.

    Returns
    -------
    nk : ndarray (K,)
    xbar : ndarray (K, d)
    S : ndarray (K, d, d)
        ``sum_n wr_nk (x_n - xbar_k)(x_n - xbar_k)^T / nk`` (P1 eq. (25)'s S_k).
    """
    nk = wr.sum(axis=0) + 10 * np.finfo(float).eps
    xbar = (wr.T @ X) / nk[:, None]
    diff = X[None, :, :] - xbar[:, None, :]                       # (K, n, d)
    S = np.matmul(np.swapaxes(diff * wr.T[:, :, None], 1, 2), diff) / nk[:, None, None]
    return nk, xbar, S


def gaussian_logpdf(X: np.ndarray, means: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """``log N(x_n; mu_k, L_k L_k^T)`` for all samples and components, (n, K)."""
    d = X.shape[1]
    Linv = np.linalg.inv(chol)                                     # (K, d, d), tiny
    LinvT = np.swapaxes(Linv, 1, 2)
    y = np.matmul(X[None], LinvT) - np.matmul(means[:, None, :], LinvT)   # (K, n, d)
    maha = np.einsum("kni,kni->nk", y, y)
    log_det = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
    return -0.5 * (maha + log_det[None, :] + d * _LOG2PI)


# --------------------------------------------------------------------------
# EM
# --------------------------------------------------------------------------
class EMGaussianMixture(MixtureLearner):
    """Maximum likelihood Gaussian mixture by EM, with sample weights.

    Parameters
    ----------
    n_components : int, default 4
    tol : float, default 1e-6
        Convergence when the weighted mean log-likelihood per unit weight
        changes by less than ``tol`` between iterations.
    max_iter : int, default 500
    reg_covar : float, default 1e-9
        Added to the diagonal of every covariance.
    init : {"kmeans++", "random"} or array_like (n, K)
        Initial responsibilities: hard k-means++ seeding, random soft
        responsibilities, or given responsibilities.
    random_state : None, int or numpy Generator

    Attributes
    ----------
    weights_ : ndarray (K,)
    means_ : ndarray (K, d)
    covariances_ : ndarray (K, d, d)
    converged_ : bool
    n_iter_ : int
    lower_bound_ : float
        Final weighted mean log-likelihood ``sum_n w_n log p(x_n) / sum_n w_n``.
    lower_bounds_ : list of float
        That quantity at every iteration (non-decreasing for EM).
    """

    def __init__(self, n_components=4, tol=1e-6, max_iter=500, reg_covar=1e-9, init="kmeans++",
                 random_state=None):
        self.n_components = n_components
        self.tol = tol
        self.max_iter = max_iter
        self.reg_covar = reg_covar
        self.init = init
        self.random_state = random_state

    def fit(self, X, sample_weight=None):
        """Fit to samples ``X`` (n, d) or (n,), with optional weights (n,). Returns self."""
        K = int(self.n_components)
        X = validate_data(X, K)
        n, d = X.shape
        w = validate_weights(sample_weight, n)
        rng = check_random_state(self.random_state)
        if isinstance(self.init, str):
            if self.init == "kmeans++":
                resp = kmeanspp_resp(X, K, rng, w)
            elif self.init == "random":
                resp = random_resp(n, K, rng)
            else:
                raise ValueError(f"init must be 'kmeans++', 'random' or an array, not {self.init!r}")
        else:
            resp = check_resp(self.init, n, K)
        wsum = w.sum()
        self._m_step(X, w[:, None] * resp, wsum)
        self.lower_bounds_ = []
        self.converged_ = False
        prev = -np.inf
        for it in range(1, self.max_iter + 1):
            log_prob = gaussian_logpdf(X, self.means_, self._chol) + np.log(self.weights_)[None, :]
            log_norm = logsumexp(log_prob, axis=1)                          # log p(x_n)
            ll = float(w @ log_norm) / wsum
            self.lower_bounds_.append(ll)
            resp = np.exp(log_prob - log_norm[:, None])                     # E-step, log space
            self._m_step(X, w[:, None] * resp, wsum)
            self.n_iter_ = it
            if abs(ll - prev) < self.tol:
                self.converged_ = True
                break
            prev = ll
        self.lower_bound_ = self.lower_bounds_[-1]
        if not self.converged_:
            warnings.warn(f"EM did not converge in {self.max_iter} iterations (tol={self.tol})",
                          ConvergenceWarning, stacklevel=2)
        return self

    def _m_step(self, X, wr, wsum):
        d = X.shape[1]
        nk, xbar, S = weighted_moments(X, wr)
        S = S + self.reg_covar * np.eye(d)[None]
        S = 0.5 * (S + np.swapaxes(S, 1, 2))
        try:
            self._chol = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            raise ValueError("a component collapsed (singular covariance); increase reg_covar "
                             "or reduce n_components") from None
        self.weights_ = nk / nk.sum()
        self.means_ = xbar
        self.covariances_ = S

    @property
    def mixture_(self) -> GaussianMixture:
        """The fitted mixture."""
        w = self.weights_ / self.weights_.sum()
        return GaussianMixture(w, self.means_, self.covariances_)

