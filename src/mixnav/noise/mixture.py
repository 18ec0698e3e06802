"""The Gaussian-mixture type every mixture filter and learner in mixnav uses.

Components are stacked arrays (a bank of K components is one array with K in
front), densities are computed in log space with ``logsumexp``, and the
Cholesky factors are kept so that no covariance is ever inverted.

Reduction (keeping a filter's mixture bounded): :meth:`GaussianMixture.prune`
drops components below a weight, :meth:`GaussianMixture.reduce` merges pairs
until at most ``max_components`` remain, each time the pair with the smallest
Runnalls upper bound on the KL divergence of the merge (Runnalls 2007, eq. 21):

    B(i, j) = 1/2 [ (w_i + w_j) log|P_ij| - w_i log|P_i| - w_j log|P_j| ]

where the merged component keeps the pair's weight, mean and covariance
exactly (moment-preserving merge).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import logsumexp

from ..errors import ArgumentError

_LOG2PI = np.log(2.0 * np.pi)


class MixtureError(ValueError):
    """Invalid mixture parameters (names the component and what is wrong)."""


class GaussianMixture:
    """A mixture of K Gaussians in d dimensions.

    Parameters
    ----------
    weights : array_like (K,)
        Non-negative, summing to 1 (within 1e-9).
    means : array_like (K, d)
    covariances : array_like (K, d, d)
        Symmetric positive definite.

    Attributes
    ----------
    weights, means, covariances : ndarray
    cholesky : ndarray (K, d, d)
        Lower Cholesky factors of the covariances.
    """

    __slots__ = ("weights", "means", "covariances", "cholesky")

    def __init__(self, weights, means, covariances):
        w = np.atleast_1d(np.asarray(weights, dtype=float))
        mu = np.asarray(means, dtype=float)
        cov = np.asarray(covariances, dtype=float)
        if mu.ndim == 1:
            mu = mu[:, None]
        if cov.ndim == 1:
            cov = cov[:, None, None]
        k, d = mu.shape
        if w.shape != (k,) or cov.shape != (k, d, d):
            raise MixtureError(f"shapes disagree: weights {w.shape}, means {mu.shape}, covariances {cov.shape}; "
                               "expected (K,), (K, d), (K, d, d)")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(mu)) and np.all(np.isfinite(cov))):
            raise MixtureError("weights, means and covariances must be finite")
        if np.any(w < 0):
            raise MixtureError(f"weight of component {int(np.argmax(w < 0))} is negative ({w.min():g})")
        if abs(w.sum() - 1.0) > 1e-9:
            raise MixtureError(f"weights sum to {w.sum():.12g}, not 1")
        if not np.allclose(cov, np.swapaxes(cov, 1, 2), rtol=1e-10, atol=1e-14):
            raise MixtureError("covariances must be symmetric")
        chol = np.empty_like(cov)
        for i in range(k):
            try:
                chol[i] = np.linalg.cholesky(cov[i])
            except np.linalg.LinAlgError:
                raise MixtureError(f"covariance of component {i} is not positive definite "
                                   f"(eigenvalues {np.linalg.eigvalsh(cov[i])})") from None
        self.weights, self.means, self.covariances, self.cholesky = w, mu, cov, chol

    def standardised(self, sigma: float = 1.0) -> "StandardMixture":
        """The 1-D mixture in units of ``sigma`` (:class:`StandardMixture`, the filters' view)."""
        return StandardMixture.from_mixture(self, sigma)

    # --- basic properties -------------------------------------------------
    @property
    def n_components(self) -> int:
        return len(self.weights)

    @property
    def dim(self) -> int:
        return self.means.shape[1]

    def __repr__(self) -> str:
        return f"GaussianMixture(K={self.n_components}, d={self.dim}, weights={np.round(self.weights, 4)})"

    # --- densities ----------------------------------------------------------
    def component_logpdf(self, x) -> np.ndarray:
        """``log N(x; mu_k, P_k)`` for every sample and component, shape (n, K)."""
        x = self._as_samples(x)
        diff = x[:, None, :] - self.means[None, :, :]                      # (n, K, d)
        # whiten with the Cholesky factors: solve L z = diff per component
        z = np.linalg.solve(self.cholesky[None], diff[..., None])[..., 0]   # (n, K, d)
        log_det = 2.0 * np.sum(np.log(np.diagonal(self.cholesky, axis1=1, axis2=2)), axis=1)
        return -0.5 * (np.sum(z * z, axis=-1) + log_det[None, :] + self.dim * _LOG2PI)

    def logpdf(self, x) -> np.ndarray:
        """Log density at samples ``x`` of shape (n, d) (or (n,) when d = 1)."""
        with np.errstate(divide="ignore"):
            return logsumexp(self.component_logpdf(x) + np.log(self.weights)[None, :], axis=1)

    def pdf(self, x) -> np.ndarray:
        return np.exp(self.logpdf(x))

    def _as_samples(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim == 1 and self.dim == 1:
            x = x[:, None]
        if x.ndim == 1:
            x = x[None, :]
        if x.shape[-1] != self.dim:
            raise MixtureError(f"samples have dimension {x.shape[-1]}, the mixture {self.dim}")
        return x

    # --- sampling and moments -------------------------------------------------
    def sample(self, n: int, rng: np.random.Generator, return_labels: bool = False):
        """``n`` samples (n, d) drawn with the given generator (and their components)."""
        if not isinstance(rng, np.random.Generator):
            raise TypeError("pass an explicit numpy Generator (np.random.default_rng(seed))")
        labels = rng.choice(self.n_components, size=n, p=self.weights)
        z = rng.standard_normal((n, self.dim))
        x = self.means[labels] + np.einsum("nij,nj->ni", self.cholesky[labels], z)
        return (x, labels) if return_labels else x

    def mean(self) -> np.ndarray:
        """Mixture mean (d,)."""
        return self.weights @ self.means

    def cov(self) -> np.ndarray:
        """Mixture covariance (d, d): within-component plus spread of the means."""
        m = self.mean()
        dev = self.means - m
        return (np.einsum("k,kij->ij", self.weights, self.covariances)
                + np.einsum("k,ki,kj->ij", self.weights, dev, dev))

    def marginal(self, dims) -> "GaussianMixture":
        """The mixture of the chosen dimensions (a list of indices)."""
        dims = np.atleast_1d(dims)
        return GaussianMixture(self.weights, self.means[:, dims], self.covariances[:, dims][:, :, dims])

    # --- reduction -------------------------------------------------------------
    def prune(self, threshold: float) -> "GaussianMixture":
        """Drop components with weight below ``threshold`` (the largest is always kept)."""
        keep = self.weights >= threshold
        keep[np.argmax(self.weights)] = True
        w = self.weights[keep]
        return GaussianMixture(w / w.sum(), self.means[keep], self.covariances[keep])

    def reduce(self, max_components: int) -> "GaussianMixture":
        """Merge pairs (smallest Runnalls bound first) until ``max_components`` remain."""
        if max_components < 1:
            raise MixtureError("max_components must be at least 1")
        w, mu, P = self.weights.copy(), self.means.copy(), self.covariances.copy()
        while len(w) > max_components:
            cost, wm, mm, Pm = _pair_costs(w, mu, P)
            i, j = np.unravel_index(np.argmin(cost), cost.shape)
            keep = np.ones(len(w), dtype=bool)
            keep[j] = False
            w[i], mu[i], P[i] = wm[i, j], mm[i, j], Pm[i, j]
            w, mu, P = w[keep], mu[keep], P[keep]
        return GaussianMixture(w / w.sum(), mu, 0.5 * (P + np.swapaxes(P, 1, 2)))


def merge_moments(w, mu, P):
    """Weight, mean and covariance of the moment-preserving merge of components."""
    W = w.sum()
    m = (w @ mu) / W
    dev = mu - m
    cov = (np.einsum("k,kij->ij", w, P) + np.einsum("k,ki,kj->ij", w, dev, dev)) / W
    return W, m, cov


def _pair_costs(w, mu, P):
    """Runnalls' bound for every pair, with the merged moments (vectorised)."""
    wij = w[:, None] + w[None, :]
    a = w[:, None] / wij
    b = w[None, :] / wij
    mij = a[..., None] * mu[:, None, :] + b[..., None] * mu[None, :, :]
    d = mu[:, None, :] - mu[None, :, :]
    Pij = (a[..., None, None] * P[:, None] + b[..., None, None] * P[None, :]
           + (a * b)[..., None, None] * d[..., :, None] * d[..., None, :])
    _, ld = np.linalg.slogdet(P)
    _, ldij = np.linalg.slogdet(Pij)
    cost = 0.5 * (wij * ldij - w[:, None] * ld[:, None] - w[None, :] * ld[None, :])
    np.fill_diagonal(cost, np.inf)
    return cost, wij, mij, Pij


@dataclass(frozen=True)
class StandardMixture:
    """The standardised view of a 1-D :class:`GaussianMixture`: weights, means and
    variance *scales* of a noise in units of a model's sigma (``sigma (mu_l +
    sqrt(v_l) N(0, 1))``), the form the filters' per-kind tables read.

    ``GaussianMixture.standardised(sigma)`` gives it, :meth:`mixture` goes back.
    """

    weights: tuple
    means: tuple
    scales: tuple

    def __post_init__(self):
        w, mu, v = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (self.weights, self.means, self.scales))
        if not (w.shape == mu.shape == v.shape) or w.ndim != 1 or len(w) == 0:
            raise ArgumentError(f"weights, means and scales need one entry per component, got "
                                f"{len(w)}, {len(mu)}, {len(v)}", argument="weights")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(mu)) and np.all(np.isfinite(v))):
            raise ArgumentError("weights, means and scales must be finite", argument="weights")
        if np.any(w < 0) or abs(w.sum() - 1.0) > 1e-6:
            raise ArgumentError(f"weights must be non-negative and sum to 1, got {w.tolist()}", argument="weights")
        if np.any(v <= 0):
            raise ArgumentError(f"variance scales must be positive, got {v.tolist()}", argument="scales")
        object.__setattr__(self, "weights", tuple(w / w.sum()))
        object.__setattr__(self, "means", tuple(mu))
        object.__setattr__(self, "scales", tuple(v))

    @classmethod
    def gaussian(cls) -> "StandardMixture":
        return cls((1.0,), (0.0,), (1.0,))

    @classmethod
    def from_mixture(cls, gm: "GaussianMixture", sigma: float = 1.0) -> "StandardMixture":
        """From a fitted 1-D :class:`GaussianMixture` of residuals in units of ``sigma``."""
        if gm.dim != 1:
            raise ArgumentError(f"a noise mixture must be one-dimensional, got d = {gm.dim}", argument="gm")
        return cls(tuple(gm.weights), tuple(gm.means[:, 0] / sigma), tuple(gm.covariances[:, 0, 0] / sigma ** 2))

    def mixture(self, sigma: float = 1.0) -> "GaussianMixture":
        """The :class:`GaussianMixture` of the noise for a model sigma ``sigma``."""
        return GaussianMixture(np.asarray(self.weights), sigma * np.asarray(self.means),
                               sigma ** 2 * np.asarray(self.scales))

    @property
    def n_components(self) -> int:
        return len(self.weights)

    @property
    def mean_scale(self) -> float:
        return float(np.dot(self.weights, self.scales))

    def variance(self) -> float:
        w, mu, v = map(np.asarray, (self.weights, self.means, self.scales))
        m = w @ mu
        return float(w @ (v + mu ** 2) - m ** 2)


@dataclass(frozen=True)
class BankMixtures:
    """The three mixtures of a Gaussian-mixture EKF.

    ``measurement`` maps an observable kind name (``"pseudorange"``, ``"tdcp"``,
    ``"range_rate"``, ``"position"``, ``"velocity"``, any registered kind; the
    filter checks the names against :mod:`mixnav.measurements.kinds`) to its
    standardised noise mixture; kinds not listed are Gaussian with the model's sigma.
    """

    measurement: dict = field(default_factory=dict)
    process: StandardMixture = field(default_factory=StandardMixture.gaussian)
    prior: StandardMixture = field(default_factory=StandardMixture.gaussian)

    def __post_init__(self):
        if any(m != 0.0 for m in self.process.means):
            raise ArgumentError("process-noise mixture means must be zero", argument="process.means")
        if any(m != 0.0 for m in self.prior.means):
            raise ArgumentError("prior mixture means must be zero", argument="prior.means")

    def tables(self, codes: dict):
        """``(log_w, mu, var)``, each (len(codes), L_max), one row per kind code
        (``codes``: kind name -> code, e.g. :data:`mixnav.measurements.kinds.KINDS`)."""
        L = max([m.n_components for m in self.measurement.values()] + [1])
        nk = len(codes)
        lw = np.full((nk, L), -np.inf)
        mu = np.zeros((nk, L))
        var = np.ones((nk, L))
        for name, code in codes.items():
            m = self.measurement.get(name, StandardMixture.gaussian())
            k = m.n_components
            with np.errstate(divide="ignore"):
                lw[code, :k] = np.log(m.weights)
            mu[code, :k] = m.means
            var[code, :k] = m.scales
        return lw, mu, var
