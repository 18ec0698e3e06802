"""Sage-Husa adaptive EKF: the EKF with the measurement-noise level learned online.

The classical adaptive baseline (Sage & Husa 1969; in navigation e.g. Yang &
Gao 2006's comparison): the measurement noise is re-estimated from the
filter's own residuals with a fading memory. Here it estimates one *variance
scale* ``s_k`` per observable kind (the model's ``R`` is right in shape and
relative size, wrong in level, which is what urban multipath or a changing
receiver does to a whole kind at once), in the residual form, which is
positive by construction::

    e = z - H dx                                  (post-fit residual)
    u = mean_i (e_i^2 + (H P+ H^T)_ii) / r_i      (its variance in units of r)
    s_k <- (1 - d) s_k + d u,   d = (1 - b) / (1 - b^(j+1))

with ``j`` the number of updates of that kind so far and ``b`` the fading
factor (0 < b < 1; ``d`` tends to ``1 - b``, memory ``1 / (1 - b)`` epochs).
For a filter whose ``R`` is right, ``E[e e^T + H P+ H^T] = R`` and ``s`` stays
near 1 (tested); the update of each epoch uses ``s R`` with the scale
learned up to the previous epoch.

This file is the whole estimator: it implements the engine's protocol
(:mod:`mixnav.engine.protocols`) through :class:`~mixnav.filters.ekf.KalmanEstimator`
and registers itself (:mod:`mixnav.filters.registry`) with its options model.
"""

from __future__ import annotations

import numpy as np

from ..engine.protocols import Correction, Epoch
from ..engine.status import NEEDS_REPAIR, OK
from ..errors import ArgumentError
from pydantic import Field

from .ekf import KalmanEstimator
from .facade import facade
from .registry import GateOptions, register_estimator
from .registry import ABSURD_SIGMA

__all__ = ["SageHusaEstimator", "SageHusaEkf"]


class SageHusaOptions(GateOptions):
    """``[methods.options]`` of ``estimator = "sage-husa"``."""

    fading: float = Field(default=0.98, gt=0, lt=1, description="fading factor b in (0, 1): a memory of "
                          "about 1 / (1 - b) epochs")
    scale0: float = Field(default=1.0, gt=0, description="initial variance scale of every kind (dimensionless)")


@register_estimator("sage-husa", options=SageHusaOptions,
                    description="Sage-Husa adaptive EKF: a measurement-noise variance scale per observable kind, "
                    "learned online with a fading memory (options: fading, scale0)",
                    build=lambda o, absurd_sigma, context: SageHusaEstimator(o.fading, o.scale0, absurd_sigma))
class SageHusaEstimator(KalmanEstimator):
    """The EKF's Gaussian with a Sage-Husa variance scale per observable kind.

    Parameters
    ----------
    fading : float
        Fading factor ``b`` in (0, 1) (module docstring); default 0.98, a memory
        of about 50 epochs.
    scale0 : float
        Initial variance scale of every kind (> 0).
    absurd_sigma : float
        As :class:`~mixnav.filters.ekf.KalmanEstimator`.
    """

    def __init__(self, fading: float = 0.98, scale0: float = 1.0, absurd_sigma: float = ABSURD_SIGMA):
        super().__init__(absurd_sigma)
        if not 0.0 < fading < 1.0:
            raise ArgumentError(f"must be in (0, 1), got {fading}", argument="fading")
        if not scale0 > 0.0:
            raise ArgumentError(f"must be positive, got {scale0}", argument="scale0")
        self.fading = float(fading)
        self.scale0 = float(scale0)

    def init(self, motion, P0, n_clone, rng):
        super().init(motion, P0, n_clone, rng)
        self.scale = {}      # kind code -> variance scale
        self.updates = {}    # kind code -> number of updates that kind has had
        self.trace = []      # (kind code, scale after each update)

    def update(self, epoch: Epoch) -> Correction | None:
        rows = epoch.rows()
        if rows is None:
            return None
        r = np.asarray(rows.R, dtype=float)
        if r.ndim != 1:
            raise ArgumentError("the Sage-Husa EKF estimates a scale of independent rows: R must be diagonal",
                                argument="R")
        kinds = rows.kinds
        s = np.array([self.scale.get(int(k), self.scale0) for k in kinds])
        scaled = rows._replace(R=r * s)
        corr = super().update(_Scaled(epoch, scaled))
        if corr is None or corr.status not in (OK, NEEDS_REPAIR):  # rejected: nothing learned
            return corr
        H = scaled.H
        ncol = H.shape[1]  # n, or n + c when the rows reach the clone
        e = rows.z - H @ corr.dx[:ncol]
        P = self.P if ncol == self.n else self.augmented_covariance()
        hph = np.einsum("ij,jk,ik->i", H, P, H)
        u_row = (e * e + hph) / r
        b = self.fading
        for k in np.unique(kinds):
            sel = kinds == k
            j = self.updates.get(int(k), 0)
            d = (1.0 - b) / (1.0 - b ** (j + 1))
            self.scale[int(k)] = (1.0 - d) * self.scale.get(int(k), self.scale0) + d * float(u_row[sel].mean())
            self.updates[int(k)] = j + 1
            self.trace.append((epoch.time, int(k), self.scale[int(k)]))
        return corr

    def diagnostics(self) -> dict:
        from ..measurements.kinds import kind_name
        return {f"sage_husa_scale_{kind_name(k)}": v for k, v in sorted(self.scale.items())}

    def outputs(self) -> dict:
        """The learned scale after each update: ``time``, ``kind``, ``scale`` arrays."""
        if not self.trace:
            return {}
        t, k, v = map(np.array, zip(*self.trace))
        return {"sage_husa_time": t, "sage_husa_kind": k, "sage_husa_scale": v}


class _Scaled:
    """An epoch whose rows are already computed (the scaled ``R``)."""

    __slots__ = ("_rows", "time", "model")

    def __init__(self, epoch, rows):
        self._rows, self.time, self.model = rows, epoch.time, epoch.model

    def rows(self):
        return self._rows


#: The Sage-Husa filter: ``SageHusaEkf(layout, imu_model, fading=0.98, scale0=1.0, ...)``.
SageHusaEkf = facade("sage-husa", "SageHusaEkf")
