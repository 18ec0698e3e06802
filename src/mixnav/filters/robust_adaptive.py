"""Robust adaptive EKF, method M2 (P1 scheme 2: Yang's adaptively robust filter).

Two factors act on the ordinary EKF update of an epoch:

**Equivalent weights (IGG-III).** Each row's standardised predicted
innovation ``t_i = |y_i| / sqrt(S_ii)``, ``S = H P H^T + R``, sets a factor
on its weight (Yang, Song & Xu 2002; the IGG-III scheme of Yang 1994)::

    gamma_i = 1                                        t <= k0   (keep)
    gamma_i = (k0 / t) ((k1 - t) / (k1 - k0))^2        k0 < t <= k1   (down-weight)
    gamma_i = 0                                        t > k1    (reject the row)

and the row's variance becomes ``R_ii / gamma_i``. Defaults ``k0 = 2.5``,
``k1 = 5.0`` (the literature uses k0 in 1.0-2.5 and k1 in 2.5-8). Smaller
``k0`` hurts tightly coupled GNSS: the rows of an epoch share the clock and
prediction errors, so their standardised innovations rise together and
down-weighting them together leaves those errors unobserved. Measured on the
first 100 s of P1-sim1 (one seed, a pilot, not the reproduction runs):
horizontal RMSE 0.81 m with k0 = 1.5, k1 = 3 (13 % of rows touched), 0.39 m
with 2.0/4.0, 0.36 m with 2.5/5.0, against the EKF's 0.39 m.

**Adaptive factor.** The discrepancy of the prediction is measured by the
predicted residuals of the rows kept (Yang & Gao 2006's statistic)::

    d = sqrt( sum_i gamma_i y_i^2 / sum_i gamma_i S_ii )

and the two-segment function ``alpha = 1`` for ``d <= c``, ``alpha = c / d``
beyond, inflates the predicted covariance to ``P / alpha`` before the
update (default ``c = 1.5``). ``d`` is about 1 when prediction and
measurements agree; a disturbed prediction (unmodelled dynamics, a
mismatched Q) gives ``d > c`` and less weight to the prediction.

Counts in ``FilterResult.recoveries``: ``robust_rows_downweighted``,
``robust_rows_rejected``, ``robust_epochs_all_rejected`` (every row of an
epoch rejected: no update), ``adaptive_epochs`` (alpha < 1).
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from ..noise.igg3 import igg3_factors
from ._ekf_kernels import ABSURD, kalman_correct
from pydantic import Field, model_validator

from .ekf import KalmanEstimator
from .facade import facade
from .registry import GateOptions, register_estimator
from .kalman import innovation_is_absurd
from .registry import ABSURD_SIGMA


def adaptive_factor(d: float, c: float) -> float:
    """Yang's two-segment adaptive factor: 1 up to ``c``, then ``c / d``."""
    return 1.0 if d <= c else c / d


class RobustOptions(GateOptions):
    """Settings of ``estimator = "robust-adaptive"`` (a file gives k0, k1, c in the method's
    ``[robust]`` table): IGG-III thresholds ``k0 < k1`` on standardised innovations
    (dimensionless, in predicted standard deviations) and the adaptive-factor threshold ``c``."""

    k0: float = Field(default=2.5, gt=0, description="IGG-III: full weight below (standardised)")
    k1: float = Field(default=5.0, gt=0, description="IGG-III: rejected above (standardised)")
    c: float = Field(default=1.5, gt=0, description="adaptive factor threshold (standardised)")

    @model_validator(mode="after")
    def _order(self):
        if not self.k0 < self.k1:
            raise ValueError(f"need k0 < k1, got k0 = {self.k0}, k1 = {self.k1}")
        return self


@register_estimator("robust-adaptive", options=RobustOptions, table="robust",
                    description="M2 robust adaptive EKF: IGG-III equivalent weights + Yang's adaptive factor",
                    build=lambda o, absurd_sigma, context: RobustEstimator(o.k0, o.k1, o.c, absurd_sigma),
                    imm_child=lambda o, absurd_sigma, context: lambda: RobustEstimator(o.k0, o.k1, o.c, absurd_sigma,
                                                                                       carry_mean=True),
                    keys={"k0": "robust.k0", "k1": "robust.k1", "c": "robust.c"})
class RobustEstimator(KalmanEstimator):
    """The EKF's Gaussian with the robust, adaptive correction (module docstring).

    Parameters
    ----------
    k0, k1 : float
        IGG-III thresholds on standardised innovations, ``0 < k0 < k1``.
    c : float
        Threshold of the adaptive factor, positive.
    absurd_sigma, carry_mean : float, bool
        As :class:`~mixnav.filters.ekf.KalmanEstimator` (``carry_mean`` for a mode of an IMM).
    """

    def __init__(self, k0: float = 2.5, k1: float = 5.0, c: float = 1.5, absurd_sigma: float = ABSURD_SIGMA,
                 carry_mean: bool = False):
        super().__init__(absurd_sigma, carry_mean)
        if not 0.0 < k0 < k1:
            raise ArgumentError(f"need 0 < k0 < k1, got k0 = {k0}, k1 = {k1}", argument="k0")
        if not c > 0.0:
            raise ArgumentError(f"must be positive, got {c}", argument="c")
        self.k0, self.k1, self.c = float(k0), float(k1), float(c)
        self._reset_counts()

    def _reset_counts(self):
        self.counts.update(robust_rows_downweighted=0, robust_rows_rejected=0,
                           robust_epochs_all_rejected=0, adaptive_epochs=0)

    def init(self, motion, P0, n_clone, rng):
        super().init(motion, P0, n_clone, rng)
        self._reset_counts()

    def correct(self, P, z, H, r):
        r = np.diag(r).copy() if np.ndim(r) == 2 else np.asarray(r, dtype=float)
        n = P.shape[0]
        if innovation_is_absurd(z, H, P, r, self.absurd_sigma):
            return P, np.zeros(n), np.inf, ABSURD
        S = np.einsum("ij,jk,ik->i", H, P, H) + r
        t = np.abs(z) / np.sqrt(S)
        g = igg3_factors(t, self.k0, self.k1)
        keep = g > 0.0
        self.counts["robust_rows_rejected"] += int((~keep).sum())
        self.counts["robust_rows_downweighted"] += int((keep & (g < 1.0)).sum())
        if not keep.any():
            self.counts["robust_epochs_all_rejected"] += 1
            return P, np.zeros(n), np.inf, ABSURD
        d = float(np.sqrt(np.sum(g * z * z) / np.sum(g * S)))
        alpha = adaptive_factor(d, self.c)
        if alpha < 1.0:
            self.counts["adaptive_epochs"] += 1
            P = P / alpha
        return kalman_correct(P, z[keep], H[keep], r[keep] / g[keep], self.absurd_sigma)   # a mask's copy: C order


#: The old name of :class:`RobustEstimator`.
RobustBelief = RobustEstimator


#: The filter of M2: ``RobustAdaptiveEkf(layout, imu_model, k0=2.5, k1=5.0, c=1.5, ...)``.
RobustAdaptiveEkf = facade("robust-adaptive", "RobustAdaptiveEkf")
