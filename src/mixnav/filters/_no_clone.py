"""The estimator-protocol parts shared by the estimators that carry no stochastic clone
(TDCP) and report no diagnostics or outputs of their own: the UKF, DD2, the particle
filter and the GMPF (each names itself in ``label``; the UKF overrides what its VB noise
adds)."""

from __future__ import annotations

from ..errors import ArgumentError


class NoCloneEstimator:
    """Mixin: the clone refusal, the counted covariance repair and empty diagnostics and
    outputs. The class needs ``label`` (e.g. ``"the DD2 filter"``) and a ``counts`` dict."""

    label = "this estimator"

    def refuse_clone(self, n_clone: int) -> None:
        """Called by ``init``: a stochastic clone (TDCP) is an ArgumentError on ``estimator``."""
        if n_clone:
            raise ArgumentError(f"{self.label} does not carry a stochastic clone (TDCP)", argument="estimator")

    def replace_clone(self, J) -> None:  # pragma: no cover (init refuses clones)
        raise ArgumentError(f"{self.label} does not carry a stochastic clone", argument="estimator")

    def repair(self) -> None:  # pragma: no cover (their updates never ask for one)
        self.counts["covariance_repair"] += 1

    def diagnostics(self) -> dict:
        return {}

    def outputs(self) -> dict:
        return {}
