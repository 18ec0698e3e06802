"""Gibbs sampling of the conjugate Bayesian Gaussian mixture (same model as the VB learner).

Model: ``pi ~ Dir(alpha0)``, ``Lambda_k ~ Wishart(W0, nu0)``,
``mu_k | Lambda_k ~ N(m0, (beta0 Lambda_k)^-1)``, ``z_n ~ Cat(pi)``,
``x_n | z_n = k ~ N(mu_k, Lambda_k^-1)`` (paper P1 eqs. 13-17).

One sweep samples, in turn:

1. ``pi | z ~ Dir(alpha0 + N_k)``
2. ``Lambda_k | z ~ Wishart(W_k, nu_k)`` and ``mu_k | Lambda_k, z ~ N(m_k, (beta_k Lambda_k)^-1)``,
   with (alpha_k, beta_k, m_k, W_k, nu_k) the conjugate update of P1 eqs. 23-25
   computed from the hard labels (the VB M-step with one-hot responsibilities);
3. ``z_n | pi, mu, Lambda`` ~ Categorical (Gumbel-max trick in log space).

Label switching: every kept draw is relabelled by sorting its components by
the mean of the first dimension, then the draws are averaged.  This is the
usual identifiability constraint; it is adequate when the components are
separated along the first dimension (components overlapping there can still
swap).

The priors default exactly as in :class:`~mixnav.noise.learn.vb.VariationalGaussianMixture`.
"""

from __future__ import annotations

import numpy as np

from mixnav.noise.learn.em import check_random_state, kmeanspp_resp, validate_data
from mixnav.noise.learn.vb import VariationalGaussianMixture, _m_step
from mixnav.noise.mixture import GaussianMixture

_LOG2PI = np.log(2.0 * np.pi)


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


class GibbsGaussianMixture:
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

    Attributes
    ----------
    weights_ : ndarray (K,)
    means_ : ndarray (K, d)
    covariances_ : ndarray (K, d, d)
        Posterior means over the kept, relabelled draws.
    chain_weights_ : ndarray (n_samples, K)
    chain_means_ : ndarray (n_samples, K, d)
    chain_covariances_ : ndarray (n_samples, K, d, d)
        The kept draws, each ordered by the first coordinate of the means.
    prior_ : dict
    """

    def __init__(self, n_components=4, n_samples=1000, burn_in=None, alpha0=1.0, beta0=1.0, nu0=None,
                 W0=None, m0=None, prune_threshold=0.01, random_state=None):
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

    def fit(self, X, sample_weight=None):
        """Run the chain on samples ``X`` (n, d) or (n,); returns self.

        ``sample_weight`` is not supported (hard labels need integer counts) and
        must be ``None``.
        """
        if sample_weight is not None:
            raise NotImplementedError("GibbsGaussianMixture does not support sample_weight")
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
        for t in range(burn + S):
            onehot = np.zeros((n, K))
            onehot[np.arange(n), z] = 1.0
            alpha, beta, m, nu, Winv = _m_step(X, onehot, prior)        # conjugate update, P1 eqs. 23-25
            pi = rng.dirichlet(alpha)
            lam = _sample_wishart(rng, Winv, nu)
            C = np.linalg.cholesky(beta[:, None, None] * lam)            # C C^T = beta_k Lambda_k
            eps = rng.standard_normal((K, d, 1))
            mu = m + np.linalg.solve(np.swapaxes(C, 1, 2), eps)[..., 0]  # cov C^-T C^-1
            # labels: log pi_k + log N(x_n | mu_k, Lambda_k^-1)
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
