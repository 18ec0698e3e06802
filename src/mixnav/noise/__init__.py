"""Non-Gaussian noise: mixtures, noise processes, diagnostics (and learners in ``learn``).

``mixture``      GaussianMixture (stacked weights/means/covariances with their
                 Cholesky factors), densities in log space, sampling, moments,
                 marginals, pruning and Runnalls' moment-preserving merge
``processes``    seeded noise processes to inject into any observable: Gaussian,
                 mixture, gross errors, AR(1) (scalar, vector or matrix), bias
                 segments, variance profiles, outages, sums (built from config tables by
                 :mod:`mixnav.config.noise_spec`)
``diagnostics``  Q-Q, autocorrelation, normality tests, kurtosis, AR(1) and
                 mixture fits of a residual series; ``mixnav diagnose``
"""

from .mixture import GaussianMixture
from .processes import (AR1, BiasSegments, Gaussian, GrossErrors, Mixture, NoiseProcess, Outages, Sum,
                        VarianceProfile)

__all__ = ["GaussianMixture", "AR1", "BiasSegments", "Gaussian", "GrossErrors", "Mixture", "NoiseProcess",
           "Outages", "Sum", "VarianceProfile"]
