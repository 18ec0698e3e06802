"""The closed-loop error-state EKF (method M1): its estimator and its filter.

:class:`KalmanEstimator` carries one Gaussian (``P``, and the stochastic-clone
blocks) and implements the engine's estimator protocol
(:mod:`mixnav.engine.protocols`): the engine mechanizes, calls ``predict``
with each step's transition and ``update`` with each measurement epoch, and
feeds the returned correction back. Subclasses change only :meth:`correct`
(the robust adaptive EKF, :mod:`mixnav.filters.robust_adaptive`) or the whole belief
(the Gaussian-mixture bank, :mod:`mixnav.filters.gmekf`).

:class:`ErrorStateEkf` is the filter a user runs: the strapdown motion model
(:class:`mixnav.ins.strapdown.StrapdownMotion`), an estimator and the
:class:`mixnav.engine.Engine`, behind ``run(imu, init, measurements)``.
The recoveries the run counts are listed in :mod:`mixnav.engine.engine`.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from ..data import ImuData, InitialState  # noqa: F401  (InitialState re-exported)
from ..engine import Engine
from ..engine.engine import check_covariance_interval
from ..engine.protocols import Correction, Epoch, Transition
from ..engine.result import FilterResult  # noqa: F401  (re-exported)
from ..errors import ArgumentError, NumericalError
from ..ins.error_model import ClockModel, StateLayout
from ..ins.imu_model import ImuErrorModel
from ..ins._error_kernels import covariance_predict
from ..ins.strapdown import StrapdownMotion
from ._ekf_kernels import NEEDS_REPAIR, OK, kalman_correct
from .kalman import innovation_logdet
from .registry import GateOptions, register_estimator
from .registry import ABSURD_SIGMA

_WARM: set = set()


@contextmanager
def innovation_likelihood():
    """Within it, every :class:`KalmanEstimator` correction (its subclasses' too) also
    gives ``log det S`` of its innovation covariance (``Correction.logdet``, recorded as
    ``FilterResult.nis_logdet``): with the NIS and the row count, each update's Gaussian
    innovation log-likelihood ``-(nis + logdet + m log 2 pi) / 2``, the criterion of
    :mod:`mixnav.experiment.tuning`. Off by default: it costs a small dense product per
    update. Process-wide (a class attribute), so a worker process sets it for itself."""
    before = KalmanEstimator.record_logdet
    KalmanEstimator.record_logdet = True
    try:
        yield
    finally:
        KalmanEstimator.record_logdet = before


def _logdet(P, H, r) -> float:
    """log det (H P H^T + R) (``r``: the variances or R); NaN when it is not positive
    definite (then the correction is refused anyway). Compiled
    (:func:`.kalman.innovation_logdet`)."""
    return float(innovation_logdet(np.ascontiguousarray(P), np.ascontiguousarray(H), np.asarray(r, dtype=float)))


def repair_covariance(P: np.ndarray) -> None:
    """Rebuild P (in place) from its eigen-decomposition with eigenvalues floored
    at 1e-12 of the largest."""
    w, v = np.linalg.eigh(P)
    w = np.maximum(w, 1e-12 * w.max())
    P[:, :] = (v * w) @ v.T


class EkfOptions(GateOptions):
    """``[methods.options]`` of ``estimator = "ekf"``: the blunder gate only."""


@register_estimator("ekf", options=EkfOptions, description="M1 extended Kalman filter (the default)",
                    build=lambda options, absurd_sigma, context: KalmanEstimator(absurd_sigma),
                    imm_child=lambda options, absurd_sigma, context: lambda: KalmanEstimator(absurd_sigma,
                                                                                             carry_mean=True))
class KalmanEstimator:
    """One Gaussian about the nominal state: ``P``, and the stochastic-clone blocks.

    Parameters
    ----------
    absurd_sigma : float
        Innovations beyond this many predicted standard deviations are
        rejected as blunders (counted as ``rejected_absurd``).
    carry_mean : bool
        Carry an error-state mean ``x`` instead of assuming it zero (closed loop).
        A composite estimator (an IMM) needs it for its children: each child
        predicts its own ``x`` and ``P`` (``Phi x``, ``Phi P Phi^T + Qd``), its
        correction is its posterior mean, and after the composite's combined
        ``dx`` is fed back it calls :meth:`recentre` (``x -= dx``). Alone, with
        the engine, it gives the closed-loop filter's numbers.
    """

    #: give each correction's log det S (:func:`innovation_likelihood` sets it)
    record_logdet = False

    def __init__(self, absurd_sigma: float = ABSURD_SIGMA, carry_mean: bool = False):
        if not absurd_sigma > 0:
            raise ArgumentError(f"must be positive, got {absurd_sigma}", argument="absurd_sigma")
        self.absurd_sigma = float(absurd_sigma)
        self.carry_mean = bool(carry_mean)
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0}

    # --- the estimator protocol --------------------------------------------------------------
    def init(self, motion, P0: np.ndarray, n_clone: int, rng: np.random.Generator) -> None:
        n = motion.layout.n
        self.n = n
        self.P = np.array(P0, dtype=float)
        self.nc = n_clone
        self.P_xc = np.zeros((n, n_clone))  # cross-covariance of the error state and the clone
        self.P_cc = np.zeros((n_clone, n_clone))
        self.have_clone = False
        self.rng = rng
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0}
        if self.carry_mean:
            if n_clone:
                raise ArgumentError("a mean-carrying estimator does not carry a stochastic clone",
                                    argument="carry_mean")
            self.x = np.zeros(n)
            self._scratch = np.zeros((n, n))
            self._tmp = np.empty((n, n))

    @property
    def kernel_covariance(self) -> np.ndarray:
        """``P`` itself: the motion model's compiled step propagates it in place (a
        mean-carrying child propagates its own: a zeroed scratch then)."""
        return self._scratch if self.carry_mean else self.P

    def predict(self, step: Transition) -> None:
        """``P`` was propagated by the motion model's kernel; move the clone's cross block."""
        if self.carry_mean:
            self._scratch[:, :] = 0.0
            covariance_predict(self.P, step.Phi, step.Qd, self._tmp)
            self.x = step.Phi @ self.x
        if self.have_clone:
            self.P_xc = step.Phi @ self.P_xc

    def recentre(self, dx: np.ndarray) -> None:
        """The nominal moved by ``dx`` (fed back by the engine): ``x -= dx``."""
        self.x = self.x - dx[:self.n]

    def correct(self, P, z, H, r):
        """One gated Kalman correction: ``(P_post, dx, nis, status)`` (no feedback)."""
        # C order always (an epoch's rows are, Epoch.rows; a caller's H may not be): a sliced H
        # (layout 'A') would compile kalman_correct and its callees a second time (about 8 s on
        # a cold cache); a contiguous H is not copied
        return kalman_correct(P, z, np.ascontiguousarray(H), r, self.absurd_sigma)

    def update(self, epoch: Epoch) -> Correction | None:
        """Apply one measurement epoch; the correction is for the engine to feed back."""
        return self.update_rows(epoch.rows())

    def update_rows(self, rows) -> Correction | None:
        """Apply one epoch's :class:`~mixnav.measurements.base.Rows` (None: no data)."""
        if rows is None:
            return None
        z, H, r = rows.z, rows.H, rows.R
        n, nc = self.n, self.nc
        if self.have_clone:
            Pa = self.augmented_covariance()
            if H.shape[1] == n:
                H = np.hstack([H, np.zeros((len(z), nc))])
            ld = _logdet(Pa, H, r) if self.record_logdet else float("nan")
            Pa_new, dx, nis, status = self.correct(Pa, z, H, r)
            if status == OK or status == NEEDS_REPAIR:  # applied: split the blocks back
                self.P = np.ascontiguousarray(Pa_new[:n, :n])
                self.P_xc = Pa_new[:n, n:].copy()
                self.P_cc = Pa_new[n:, n:].copy()
            return Correction(dx, nis, status, len(z), ld)
        if H.shape[1] != n:
            raise NumericalError("a measurement model returned H for a clone the "
                                 "filter does not carry")  # a bug, not bad input
        ld = _logdet(self.P, H, r) if self.record_logdet else float("nan")
        if self.carry_mean:  # the innovation about the mean, and the posterior mean
            P_new, dx, nis, status = self.correct(self.P, z - H @ self.x, H, r)
            if status == OK or status == NEEDS_REPAIR:
                self.P = P_new
                self.x = self.x + dx
            return Correction(self.x.copy(), nis, status, len(z), ld)
        P_new, dx, nis, status = self.correct(self.P, z, H, r)
        if status == OK or status == NEEDS_REPAIR:
            self.P = P_new
        return Correction(dx, nis, status, len(z), ld)

    def augmented_covariance(self) -> np.ndarray:
        """``[[P, P_xc], [P_xc^T, P_cc]]`` (n + c, n + c): the error state and its clone."""
        n, nc = self.n, self.nc
        Pa = np.empty((n + nc, n + nc))
        Pa[:n, :n] = self.P
        Pa[:n, n:] = self.P_xc
        Pa[n:, :n] = self.P_xc.T
        Pa[n:, n:] = self.P_cc
        return Pa

    def replace_clone(self, J: np.ndarray) -> None:
        """The clone becomes ``J x`` of the current (updated) state."""
        self.P_xc = self.P @ J.T
        self.P_cc = J @ self.P_xc
        self.have_clone = True

    def repair(self) -> None:
        repair_covariance(self.P)
        self.counts["covariance_repair"] += 1

    def covariance(self) -> np.ndarray:
        return self.P

    def diagnostics(self) -> dict:
        """Timing and size entries beyond the engine's own (none here)."""
        return {}

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) the correction kernel once per process."""
        if "kalman" in _WARM:
            return
        n = 15
        H = np.zeros((3, n))
        H[:, 6:9] = np.eye(3)
        kalman_correct(np.eye(n), np.zeros(3), H, np.ones(3), 1e4)
        kalman_correct(np.eye(n), np.zeros(3), H, np.eye(3), 1e4)
        _WARM.add("kalman")


#: The old name of :class:`KalmanEstimator` (the run loop's "belief").
GaussianBelief = KalmanEstimator


class ErrorStateEkf:
    """Closed-loop error-state EKF on the strapdown INS (method M1).

    Parameters
    ----------
    layout : StateLayout
        Which error states to carry (15, 17, 21, 23 or a layout of your blocks).
    imu_model : ImuErrorModel
        The filter's model of the IMU (sets Q and the initial sensor sigma).
    covariance_interval : float
        Longest covariance propagation step [s] (at most 1 s; see
        :func:`mixnav.ins._error_kernels.discretize`).
    absurd_sigma : float
        Innovations beyond this many standard deviations are rejected as
        blunders (counted).
    clock : ClockModel, optional
        Receiver clock noise (layouts with the clock block).

    A subclass with another belief overrides :meth:`make_estimator` only.
    """

    #: the RTS smoother applies (one Gaussian belief per event: ``FilterResult.history``)
    can_smooth = True

    def __init__(self, layout: StateLayout, imu_model: ImuErrorModel,
                 covariance_interval: float = 1.0, absurd_sigma: float = ABSURD_SIGMA,
                 clock: ClockModel | None = None):
        check_covariance_interval(covariance_interval)  # now, not at the first run
        KalmanEstimator(absurd_sigma)                    # checks absurd_sigma
        self.layout = layout
        self.imu_model = imu_model
        self.covariance_interval = float(covariance_interval)
        self.absurd_sigma = float(absurd_sigma)
        self.motion = StrapdownMotion(layout, imu_model, clock)
        self.qc, self.tau, self.sensor_sigma0 = self.motion.qc, self.motion.tau, self.motion.sensor_sigma0
        self.estimator = None

    def make_estimator(self):
        """A fresh estimator for one run."""
        return KalmanEstimator(self.absurd_sigma)

    def initial_covariance(self, init: InitialState) -> np.ndarray:
        return self.motion.initial_covariance(init)

    def engine(self, measurements=(), rng=None, history: bool = False) -> Engine:
        """An :class:`~mixnav.engine.Engine` for this filter (for the step API)."""
        self.estimator = self.make_estimator()
        return Engine(self.motion, self.estimator, measurements, self.covariance_interval, rng=rng,
                      history=history)

    def run(self, imu: ImuData, init: InitialState, measurements=(),
            output_times: np.ndarray | None = None, rng=None, history: bool = False) -> FilterResult:
        """Run the filter over the IMU data.

        Parameters
        ----------
        imu : ImuData
            Raw increments.
        init : InitialState
        measurements : sequence of MeasurementModel
            :mod:`mixnav.measurements` (loose, tight, TDCP, differenced, yours).
        output_times : ndarray, optional
            Where to record the state [s]; default: every measurement epoch and
            every ``covariance_interval``.
        rng : numpy.random.Generator or int, optional
            The estimator's random stream (none of the Gaussian estimators draws).
        history : bool
            Also keep what a smoother needs (``FilterResult.history``).
        """
        return self.engine(measurements, rng, history).run(imu, init, output_times)


def _warm_up(layout: StateLayout) -> None:
    """Compile the EKF's kernels for this layout (benchmarks call it before timing)."""
    from ..ins.imu_model import ImuErrorModel as _M
    StrapdownMotion(layout, _M()).warm_up()
    KalmanEstimator().warm_up()
    from ._ekf_kernels import ekf_correct
    nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.5, 0.5, 0.0])
    n = layout.n
    H = np.zeros((3, n))
    H[:, 6:9] = np.eye(3)
    ekf_correct(np.eye(n), np.zeros(3), H, np.ones(3), 1e4, nav, np.zeros(12), np.zeros(2), layout.as_array())
