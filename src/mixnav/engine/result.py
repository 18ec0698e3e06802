"""What a run of the engine produces: the solution, and optionally its history."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class FilterResult:
    """What a filter run produces.

    Attributes
    ----------
    time : ndarray (K,)
        Output epochs [s].
    nav : ndarray (K, 10)
        State at each output epoch (after any update there).
    sigma : ndarray (K, n)
        1-sigma of each error state.
    gnss_used : ndarray of bool (K,)
        An update was applied at this epoch or since the previous output epoch.
    sensor : ndarray (K, 12)
        Sensor-error estimates ``[bg, ba, sg, sa]``.
    nis : ndarray (M,)
        NIS of each applied update, and ``nis_dim`` its dimension.
    pv_cov : ndarray (K, 6, 6)
        Covariance of the velocity and position errors (for NEES).
    w_b : ndarray (K, 3)
        Compensated body angular rate of the last increment [rad/s] (for
        lever-arm velocities).
    recoveries : dict
        Counts of each numerical recovery (:mod:`mixnav.engine.engine`).
    timing : dict
        ``epoch_time_mean_us`` (all filter work, mechanization included,
        divided by the number of measurement epochs), ``update_time_mean_us``
        (measurement model, correction and feedback only), ``wall_time_s``,
        and what the estimator adds (e.g. ``learning_time_s``).
    layout : StateLayout
    P : ndarray (n, n) or None
        Final error covariance.
    estimates : dict
        Estimates per state block beyond the navigation states, each (K, size):
        ``gyro_bias``, ``accel_bias`` (and ``gyro_scale``, ``accel_scale``,
        ``clock``, auxiliary blocks when the layout has them).
    nis_kind : ndarray (M,) of object
        The observable kinds of each applied update, as a ``+``-joined string
        of kind names (``"position+velocity"``): NIS per kind is a groupby.
    nis_time : ndarray (M,) or None
        The time [s] of each applied update.
    nis_logdet : ndarray (M,) or None
        log det of each applied update's innovation covariance (NaN unless the
        estimator gives it: :func:`mixnav.filters.ekf.innovation_likelihood`).
    outputs : dict
        Estimator-specific series (model probabilities, tracked noise...):
        name -> array, documented by the estimator.
    history : History or None
        What a smoother needs, when the run was asked for it.
    motion : MotionModel or None
        The motion model of the run (its ``inject`` is what a smoother feeds a
        smoothed error back with, for a layout that is not the INS's).
    """

    time: np.ndarray
    nav: np.ndarray
    sigma: np.ndarray
    gnss_used: np.ndarray
    sensor: np.ndarray
    nis: np.ndarray
    nis_dim: np.ndarray
    pv_cov: np.ndarray
    w_b: np.ndarray
    recoveries: dict
    timing: dict
    layout: object
    P: np.ndarray | None = None
    estimates: dict = field(default_factory=dict)
    nis_kind: np.ndarray | None = None
    outputs: dict = field(default_factory=dict)
    history: "History | None" = None
    motion: object = None
    nis_time: np.ndarray | None = None
    nis_logdet: np.ndarray | None = None


@dataclass
class History:
    """Per event of the run (propagation step, with its updates), what a fixed-interval
    smoother of the closed-loop error-state filter needs.

    Attributes
    ----------
    time : ndarray (E,)
        Event times [s].
    Phi : ndarray (E, n, n)
        Transition of the error state from the previous event to this one.
    P_pred : ndarray (E, n, n)
        Covariance after the propagation, before the event's updates.
    P_filt : ndarray (E, n, n)
        Covariance after the event's updates (= ``P_pred`` without one).
    dx : ndarray (E, n)
        Sum of the corrections fed back at the event (zero without an update):
        the smoother adds it back to move between the nominal before and after
        the feedback reset.
    nav : ndarray (E, 10)
        Nominal state after the event.
    updated : ndarray of bool (E,)

    Memory: exactly ``3 n^2 + n + 11`` doubles and one byte (``updated``) per event,
    in one preallocated array per field (the engine writes each event's row in
    place; no per-event Python objects):

    ====  =====================  ==============================
    n     per event              one hour at 4 events/s (14400)
    ====  =====================  ==============================
    15    701 doubles, 5.61 kB   80.8 MB
    17    895 doubles, 7.16 kB   103.1 MB
    21    1355 doubles, 10.84 kB 156.1 MB
    23    1621 doubles, 12.97 kB 186.8 MB
    ====  =====================  ==============================

    (1 s events: a quarter of that.) The stochastic-clone blocks are not stored:
    the smoother (:func:`mixnav.engine.smoother.rts_smooth`) works on the marginal
    of the error state, an approximation for a cloning model (docs/smoother.md).
    """

    time: np.ndarray
    Phi: np.ndarray
    P_pred: np.ndarray
    P_filt: np.ndarray
    dx: np.ndarray
    nav: np.ndarray
    updated: np.ndarray
