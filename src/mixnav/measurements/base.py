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
states sets ``batch_aux`` and is given each member's).
"""

from __future__ import annotations

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

    def warm_up(self, nav: np.ndarray, aux: dict | None = None) -> None:
        """Compile (or load from numba's cache) the model's kernels outside the timed loop."""
        if len(self.times):
            if aux:
                self.rows(0, np.array(nav, dtype=float), np.zeros(3), np.zeros(2), None, aux=aux)
            else:
                self.rows(0, np.array(nav, dtype=float), np.zeros(3), np.zeros(2), None)
