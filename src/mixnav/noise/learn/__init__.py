"""Learning Gaussian mixtures from samples (EM, variational Bayes, Gibbs).

All learners follow scikit-learn's ``sklearn.mixture`` conventions:
``__init__`` stores settings only, ``fit(X, sample_weight=None)`` does the
work and returns ``self``, fitted attributes end in ``_`` and
``mixture_`` returns a :class:`mixnav.noise.mixture.GaussianMixture`.

* :class:`EMGaussianMixture` -- maximum likelihood EM with sample weights.
* :class:`VariationalGaussianMixture` -- variational Bayes with a Dirichlet /
  Gaussian-Wishart prior (paper P1 eqs. 10-29, Bishop PRML 10.2), component
  pruning and warm start.
* :class:`GibbsGaussianMixture` -- Gibbs sampling of the same conjugate model.
"""


class ConvergenceWarning(UserWarning):
    """A learner stopped at ``max_iter`` before its convergence test passed."""


# The submodules import ConvergenceWarning from here, so it is defined first.
from mixnav.noise.learn.em import EMGaussianMixture  # noqa: E402
from mixnav.noise.learn.vb import VariationalGaussianMixture  # noqa: E402
from mixnav.noise.learn.gibbs import GibbsGaussianMixture  # noqa: E402

__all__ = ["ConvergenceWarning", "EMGaussianMixture", "VariationalGaussianMixture", "GibbsGaussianMixture"]
