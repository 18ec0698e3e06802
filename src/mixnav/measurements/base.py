"""The measurement-model protocol: what the engine asks of every model.

A model turns the measurements of one epoch and the nominal INS state into
typed rows (:class:`Rows`): the innovation ``z`` (measured minus predicted,
the error-state convention ``dx = x_true - x_est``), its Jacobian ``H`` over
the error state, the noise ``R``, the registered observable kind of each row
and, optionally, a channel id per row (the same satellite/axis at every
epoch). It returns ``None`` when it has no data at that epoch.

Models keep **no state between calls**: one object can serve two filters (or
two modes of an IMM) at once. A model that needs its previous epoch (TDCP, a
differenced measurement) says so with ``remembers = True``; the engine then
calls :meth:`MeasurementModel.remember` after the updates of each of the
model's epochs, holds the returned *memory* and hands it back to the next
:meth:`MeasurementModel.rows`. A model that needs the previous error state
*with its uncertainty* also sets ``clone_size = c > 0``: the engine then
carries a stochastic clone ``x_c = J x`` (``J = clone_rows(nav)``, (c, n))
beside the error state, ``H`` may have ``n + c`` columns (the clone last),
and the clone part of each correction is handed to
:meth:`correct_memory`, which returns the memory moved by it (see
:mod:`mixnav.engine`).

The ensemble family (UKF, particle filters) evaluates ``h`` on a batch of
full states instead of linearising: :meth:`predict_batch` (the loose, tight
and multi-system pseudorange models have it; a model that reads auxiliary
states sets ``batch_aux`` and is given each member's). A model may also offer
a fused update of a weighted ensemble straight from the members' error states
(:meth:`MeasurementModel.member_update`, a :class:`MemberUpdate`; the loose
model does, for the particle filter): the estimator asks for it and falls back
on :meth:`predict_batch` where the answer is None, and never names the model.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np


class Rows(NamedTuple):
    """The linearised rows of one measurement epoch.

    Attributes
    ----------
    z : ndarray (m,)
        Innovation, measured minus predicted [unit of each row].
    H : ndarray (m, n) or (m, n + c)
        Jacobian over the error state (and the clone, last ``c`` columns).
    R : ndarray (m,) or (m, m)
        Noise variances (independent rows) or full covariance.
    kinds : ndarray of int64 (m,)
        Registered kind code of each row (:mod:`mixnav.measurements.kinds`).
    channels : ndarray of int64 (m,) or None
        A channel id per row, the same for the same satellite/axis and
        observable at every epoch (:func:`~mixnav.measurements.kinds.channel_id`).
    """

    z: np.ndarray
    H: np.ndarray
    R: np.ndarray
    kinds: np.ndarray
    channels: np.ndarray | None = None


class MemberUpdate(NamedTuple):
    """A model's fused update of a weighted ensemble at one epoch
    (:meth:`MeasurementModel.member_update`): the members' predictions, log-weights,
    weights and moments in one compiled call, with no full state built.

    The estimator calls ``kernel(D, nav, w_b, logw0, w0, threshold, YT, logw, w, ym, Pyy, x,
    P, yp, pa, part, work, *constants)`` with the members ``D`` (N, n) (error states about
    the nominal ``nav`` (10,), body rate ``w_b`` (3,) [rad/s]), their prior log-weights
    ``logw0`` and weights ``w0`` (N,) and the degeneracy bound ``threshold`` on the smallest
    squared normalised innovation; it receives the predictions ``YT`` (m, N), the new
    log-weights ``logw`` and normalised weights ``w`` (N,), the prior-weighted mean ``ym``
    (m,) and covariance ``Pyy`` (m, m) of the predictions, the weighted mean ``x`` (n,) and
    covariance ``P`` (n, n) of the members; scratch ``yp`` (CHUNKS, >= 2 + m + m m), ``pa``
    (CHUNKS, >= 2 + n), ``part`` (CHUNKS, >= n + n n), ``work`` (n + 1, N)
    (``mixnav.linalg.CHUNKS``). It returns ``(best, ess, nis)``: the smallest squared
    normalised innovation, the effective sample size (0 when degenerate: ``w``, ``x``,
    ``P`` then unset) and the NIS of the prior-weighted mean prediction.

    Attributes
    ----------
    rows : int
        ``m``, the epoch's measurement rows.
    kernel : callable
        The compiled update (serial or parallel twin, as asked).
    constants : tuple
        The model's own arguments for this epoch, passed last.
    """

    rows: int
    kernel: Callable
    constants: tuple


def warm_member_updates(layout, parallel: bool = False) -> None:
    """Compile (or load from numba's cache) the fused member updates of every measurement-model
    class defined so far (each subclass's own :meth:`MeasurementModel.warm_up_members`) for
    members over ``layout``: an ensemble estimator's warm-up, outside the timed loop, naming
    no model (a model class defined later compiles on its first epoch)."""
    seen, todo = set(), [MeasurementModel]
    while todo:
        for sub in todo.pop().__subclasses__():
            if sub not in seen:
                seen.add(sub)
                todo.append(sub)
                if "warm_up_members" in vars(sub):
                    sub.warm_up_members(layout, parallel)


class MeasurementModel:
    """Base class of the measurement models (see the module docstring).

    Subclasses set :attr:`kinds` (the registered kind names their rows can
    have) and implement :attr:`times` and :meth:`rows`.
    """

    #: registered kind names this model's rows can have
    kinds: tuple = ()
    #: size of the stochastic clone the model needs (0: none)
    clone_size: int = 0
    #: the model needs a memory of its previous epoch (held by the engine)
    remembers: bool = False
    #: predict_batch takes ``aux``: each member's auxiliary states, name -> (N, size)
    batch_aux: bool = False

    @property
    def times(self) -> np.ndarray:
        """Epoch times [s], (M,), increasing."""
        raise NotImplementedError

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock: np.ndarray, memory=None,
             aux: dict | None = None) -> Rows | None:
        """The rows of epoch ``i``.

        Parameters
        ----------
        i : int
            Index into :attr:`times`.
        nav : ndarray (10,)
            Nominal INS state ``[q_nb(4), v_n(3), lat, lon, h]`` (rad, m/s, m).
        w_b : ndarray (3,)
            Compensated body angular rate of the last IMU increment [rad/s].
        clock : ndarray (2,)
            Receiver clock bias [m] and drift [m/s] estimates (zeros without a clock).
        memory : object or None
            What :meth:`remember` returned at this model's previous epoch.
        aux : dict, optional
            Estimates of the layout's auxiliary blocks (name -> ndarray), passed
            only when the layout has any (e.g. an odometer scale factor).
        """
        raise NotImplementedError

    def measure(self, i, nav, w_b, clock=None, memory=None):
        """``(z, H, R)`` of :meth:`rows` (a convenience for tests and notebooks), or None."""
        r = self.rows(i, nav, w_b, np.zeros(2) if clock is None else clock, memory)
        return None if r is None else (r.z, r.H, r.R)

    def remember(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock: np.ndarray):
        """The memory of epoch ``i`` after its update (models with ``remembers``)."""
        return None

    def correct_memory(self, memory, dx_c: np.ndarray):
        """The memory moved by the clone part ``dx_c`` (c,) of a correction."""
        return memory

    def clone_rows(self, nav: np.ndarray) -> np.ndarray:
        """``J`` (c, n): the clone as a linear function of the error state."""
        raise NotImplementedError(f"{type(self).__name__} has no clone")

    def predict_batch(self, i: int, navs: np.ndarray, w_b: np.ndarray, clocks=None):
        """``h`` at a batch of full states, for the ensemble estimators (UKF, particle
        filters): ``(y (m,), Y (N, m), R (m,))`` with ``y - Y[j]`` the innovation of state
        ``navs[j]`` (N, 10) with body rate ``w_b`` (3,) or (N, 3) and receiver clock
        ``clocks`` (2,) or (N, 2) (models without a clock ignore it), or None when the
        epoch has no data. Implemented by the loose and tight models; the TDCP and
        differenced models add it with the particle-filter issue. A model with
        :attr:`batch_aux` also takes ``aux=`` (name -> (N, size) per member)."""
        raise NotImplementedError(f"{type(self).__name__} does not evaluate h on a batch of states yet")

    def member_update(self, i: int, layout, parallel: bool = False) -> MemberUpdate | None:
        """The fused ensemble update of epoch ``i`` (:class:`MemberUpdate`) for members that
        are error states over ``layout`` (a ``StateLayout``; ``parallel``: the kernel twin on
        numba's threads), or None: the model has none for that layout or that epoch, and the
        estimator takes :meth:`predict_batch`. None here; the loose model has one."""
        return None

    @classmethod
    def warm_up_members(cls, layout, parallel: bool = False) -> None:
        """Compile (or load) the kernels :meth:`member_update` hands out for members over
        ``layout`` (none here). A class method: an estimator's warm-up runs before it sees
        the models (:func:`warm_member_updates`)."""

    def warm_up(self, nav: np.ndarray, aux: dict | None = None) -> None:
        """Compile (or load from numba's cache) the model's kernels outside the timed loop."""
        if len(self.times):
            if aux:
                self.rows(0, np.array(nav, dtype=float), np.zeros(3), np.zeros(2), None, aux=aux)
            else:
                self.rows(0, np.array(nav, dtype=float), np.zeros(3), np.zeros(2), None)
