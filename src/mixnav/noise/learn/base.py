"""What every mixture learner shares: scikit-learn's estimator interface.

``get_params`` / ``set_params`` come from :class:`sklearn.base.BaseEstimator`
(so ``sklearn.base.clone`` works: each ``__init__`` stores its arguments
unchanged), the estimator type from :class:`sklearn.base.DensityMixin`; the rest reads
the fitted :class:`~mixnav.noise.mixture.GaussianMixture` (``mixture_``).
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp
from sklearn.base import BaseEstimator, DensityMixin
from sklearn.exceptions import NotFittedError


class MixtureLearner(DensityMixin, BaseEstimator):
    """Base of :class:`EMGaussianMixture`, :class:`VariationalGaussianMixture`,
    :class:`GibbsGaussianMixture`: prediction, scoring and sampling of the fit."""

    def _fitted(self):
        if not hasattr(self, "weights_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet: call fit(X) first")
        return self.mixture_

    def score_samples(self, X) -> np.ndarray:
        """Log density of each sample (n, d) or (n,) under the fitted mixture, (n,)."""
        return self._fitted().logpdf(X)

    def score(self, X, y=None) -> float:
        """Mean log density per sample (scikit-learn's ``GaussianMixture.score``)."""
        return float(np.mean(self.score_samples(X)))

    def predict_proba(self, X) -> np.ndarray:
        """Responsibilities (n, K): the posterior probability of each component per sample."""
        gm = self._fitted()
        with np.errstate(divide="ignore"):
            lp = gm.component_logpdf(X) + np.log(gm.weights)[None, :]
        return np.exp(lp - logsumexp(lp, axis=1, keepdims=True))

    def predict(self, X) -> np.ndarray:
        """The most probable component of each sample, (n,) int."""
        return np.argmax(self.predict_proba(X), axis=1)

    def sample(self, n_samples: int = 1, random_state=None):
        """``(X (n_samples, d), labels (n_samples,))`` drawn from the fitted mixture
        (scikit-learn's order); ``random_state`` an int, a Generator or None."""
        gm = self._fitted()
        if int(n_samples) < 1:
            raise ValueError(f"n_samples must be at least 1, got {n_samples}")
        rng = random_state if isinstance(random_state, np.random.Generator) else np.random.default_rng(random_state)
        return gm.sample(int(n_samples), rng, return_labels=True)
