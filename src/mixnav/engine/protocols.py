"""The small protocols between the engine and what it drives.

- :class:`MotionModel`: the nominal-state propagation (the strapdown INS,
  :class:`mixnav.ins.strapdown.StrapdownMotion`; dead reckoning and constant
  velocity, :mod:`mixnav.motion`), and the ensemble seam: members (sigma
  points, particles) as error states about the nominal, turned into full
  states, propagated and differenced back by the motion model.
- :class:`Estimator`: what carries the belief about the error state (one
  Gaussian, a robust variant, a bank of Gaussians, an IMM of estimators). It
  never touches the nominal state: it returns a :class:`Correction` and the
  engine feeds it back, once.
- The measurement model: :class:`mixnav.measurements.base.MeasurementModel`.

An estimator sees a measurement epoch as an :class:`Epoch`, which gives lazy
access to the linearised rows (``epoch.rows()``) and to the model itself
(``epoch.model``, for ``h`` on a batch of states), so a composite estimator
can route epochs to the children whose measurement set contains the model.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from .status import ABSURD, NEEDS_REPAIR, NON_FINITE, OK, S_NOT_POSITIVE_DEFINITE  # noqa: F401


class StepInputs(NamedTuple):
    """What the motion model started from and was driven by over one step.

    Given (as ``Transition.inputs``) only to an estimator that sets
    ``needs_step_inputs = True`` (the unscented filters, which mechanize their
    sigma points over the same block); for every other estimator the engine
    neither copies nor builds anything.

    ``nav0`` (10,), ``prev0`` (6,), ``clock0`` (2,): the nominal state, the
    previous compensated increments and the receiver clock *before* the step
    (copies in the engine's scratch, valid until the next step); ``sensor``
    (12,) the sensor-error estimates the step compensated with; ``dtheta``,
    ``dvel`` (K, 3), ``dt`` (K,) the raw increments of the block; ``nav`` (10,)
    the nominal *after* the step (the engine's own array: read, never write).
    """

    nav0: np.ndarray
    prev0: np.ndarray
    clock0: np.ndarray
    sensor: np.ndarray
    dtheta: np.ndarray
    dvel: np.ndarray
    dt: np.ndarray
    nav: np.ndarray


class Transition(NamedTuple):
    """One propagation step of the error state, as the motion model gave it.

    ``F``, ``Phi``, ``Qd`` (n, n) are views into the engine's scratch, valid
    until the next step; ``T`` [s] the step length; ``measured`` whether a
    measurement epoch follows at the end of the step; ``inputs`` a
    :class:`StepInputs` for an estimator with ``needs_step_inputs = True``,
    else None.
    """

    F: np.ndarray
    Phi: np.ndarray
    Qd: np.ndarray
    T: float
    measured: bool
    inputs: StepInputs | None = None


class Correction(NamedTuple):
    """What an estimator's update returns.

    ``dx`` (n,) or (n + c,): the error estimate to feed back (error states,
    then the clone's part), zeros when rejected; ``nis`` the normalised
    innovation squared of the epoch (inf when rejected); ``status`` one of
    ``OK``, ``NEEDS_REPAIR`` (applied, the covariance needs repair),
    ``ABSURD``, ``S_NOT_POSITIVE_DEFINITE`` (rejected, counted),
    ``NON_FINITE`` (the engine raises); ``m`` the number of rows; ``logdet``
    the log-determinant of the innovation covariance, NaN unless the estimator
    gives it (:class:`~mixnav.filters.ekf.KalmanEstimator` inside
    :func:`~mixnav.filters.ekf.innovation_likelihood`): with ``nis`` and ``m`` it
    is the epoch's Gaussian innovation log-likelihood.
    """

    dx: np.ndarray
    nis: float
    status: int
    m: int
    logdet: float = float("nan")


class Epoch:
    """One measurement epoch as an estimator sees it (lazy rows)."""

    __slots__ = ("time", "index", "model", "nav", "w_b", "clock", "memory", "aux", "_rows", "_done")

    def __init__(self, time, index, model, nav, w_b, clock, memory, aux=None):
        self.time = time
        self.index = index
        self.model = model
        self.nav = nav
        self.w_b = w_b
        self.clock = clock
        self.memory = memory
        self.aux = aux
        self._done = False
        self._rows = None

    def rows(self):
        """The model's :class:`~mixnav.measurements.base.Rows` at the nominal state (computed
        once), or None when it has no data; ``z``, ``H`` and ``R`` float64 in C order."""
        if not self._done:
            if self.aux:
                rows = self.model.rows(self.index, self.nav, self.w_b, self.clock, self.memory, aux=self.aux)
            else:
                rows = self.model.rows(self.index, self.nav, self.w_b, self.clock, self.memory)
            self._rows = None if rows is None else _c_order(rows)
            self._done = True
        return self._rows


def _c_order(rows):
    """``rows`` with ``z``, ``H`` and ``R`` float64 in C order, once here for every estimator:
    a model's sliced H (layout 'A') would otherwise compile each estimator's kernels a second
    time (about 8 s on a cold cache for ``kalman_correct`` and its callees). An array already
    so is not copied."""
    c = np.ascontiguousarray
    z, H, R = c(rows.z, dtype=np.float64), c(rows.H, dtype=np.float64), c(rows.R, dtype=np.float64)
    if z is rows.z and H is rows.H and R is rows.R:
        return rows
    return rows._replace(z=z, H=H, R=R)


@runtime_checkable
class MotionModel(Protocol):
    """The motion model (ARCHITECTURE.md, "Motion models").

    Error-state family: ``propagate`` the nominal over a block of increments
    (filling ``work = [F, Phi, Qd, scratch]`` and propagating ``P`` in place),
    ``inject`` a correction into the nominal, ``initial_covariance``.

    Ensemble family (UKF, DD2, GMPF): a *member* is an error state ``D_j`` (n,)
    about a nominal; the motion model alone knows what that means as a full state.

    - ``member_states(nav, sensor, D, navs)``: the members ``D`` (N, n) about
      ``nav`` (10,) and the sensor estimates ``sensor`` (12,) as full navigation
      states ``navs`` (N, 10) (``inject`` on copies), for ``h`` on a batch;
    - ``member_rates(w_b, D) -> (N, 3)``: the body rate each member sees;
    - ``propagate_members(inputs, D, substeps, T, Dn)``: members about the nominal
      before a step (``inputs``: :class:`StepInputs`) propagated over its
      increments together with a reference (the nominal, propagated the same way,
      so a common discretisation error cancels), and differenced back: ``Dn``
      (N, n) are their error states about the propagated reference (``T`` [s] the
      step length; ``substeps`` how far the block may be merged, where the model
      merges at all);
    - ``difference_members(navs, ref, D, Dn)``: full states as error states about
      ``ref``, the blocks without a full-state part copied from ``D``: the inverse
      of ``member_states`` (``difference(member_states(nav, D), nav) == D``,
      tests/test_ensemble_motion.py).
    """

    layout: object

    def initial_covariance(self, init) -> np.ndarray: ...

    def propagate(self, nav, prev, sensor, dtheta, dvel, dt, P, work) -> float: ...

    def inject(self, nav, sensor, clock, aux, dx) -> None: ...

    def member_states(self, nav, sensor, D, navs) -> None: ...

    def member_rates(self, w_b, D) -> np.ndarray: ...

    def propagate_members(self, inputs, D, substeps, T, Dn) -> None: ...

    def difference_members(self, navs, ref, D, Dn) -> None: ...

    def warm_up(self) -> None: ...


@runtime_checkable
class Estimator(Protocol):
    """The error-state estimator protocol (see :mod:`mixnav.engine`).

    ``init`` starts a run; ``kernel_covariance`` is the (n, n) array the motion
    model's compiled step propagates in place (an estimator with one
    covariance gives its own, others a zeroed scratch); ``predict`` sees each
    step's transition; ``update`` one measurement epoch; ``replace_clone`` the
    stochastic clone becoming ``J x``; ``covariance`` the (n, n) error
    covariance for the record; ``counts`` the recoveries it counts.

    Optional: an estimator with ``carry_mean = True`` keeps an error-state mean
    and has ``recentre(dx)``, which the engine calls after feeding ``dx`` back.
    A composite (an IMM) holds such children, routes each epoch to those whose
    measurement set holds ``epoch.model``, predicts them all with the one
    transition, and re-centres them all on the combined correction.

    Optional: an estimator with ``needs_step_inputs = True`` gets each step's
    :class:`StepInputs` in ``Transition.inputs`` (the nominal before the step and
    the IMU block: what sigma points are mechanized from); the engine copies the
    pre-step nominal only for such an estimator.
    """

    counts: dict
    kernel_covariance: np.ndarray

    def init(self, motion, P0: np.ndarray, n_clone: int, rng: np.random.Generator) -> None: ...

    def predict(self, step: Transition) -> None: ...

    def update(self, epoch: Epoch) -> Correction | None: ...

    def replace_clone(self, J: np.ndarray) -> None: ...

    def covariance(self) -> np.ndarray: ...

    def repair(self) -> None: ...

    def diagnostics(self) -> dict: ...

    def warm_up(self) -> None: ...
