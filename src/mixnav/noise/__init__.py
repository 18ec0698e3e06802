"""Non-Gaussian noise: the Gaussian-mixture type and its reduction.

``mixture``  GaussianMixture (stacked weights/means/covariances with their
             Cholesky factors), logpdf/pdf, sampling, moments, marginals,
             pruning and Runnalls' moment-preserving merge.
"""

from .mixture import GaussianMixture

__all__ = ["GaussianMixture"]
