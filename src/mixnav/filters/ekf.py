"""The closed-loop error-state EKF (method M1) and its run loop.

The loop is the same for every error-state filter in mixnav:

1. collect event times (measurement epochs, output epochs, and a covariance
   step at least every ``covariance_interval``), split the IMU increments at
   them (:mod:`mixnav.filters.timing`);
2. for each event: mechanize the increments up to it and propagate the
   covariance in one compiled call (:func:`propagate_block`);
3. at a measurement epoch: form ``(z, H, R)``, apply the Kalman correction,
   feed the error estimate back into the INS and the sensor-error estimates,
   and reset the error state to zero (closed loop);
4. at an output epoch: record the state and its 1-sigma.

Numerical recoveries (each counted in ``FilterResult.recoveries``):

``rejected_not_pd``   innovation covariance not positive definite: epoch skipped
``rejected_absurd``   innovation beyond ``absurd_sigma`` standard deviations
                      (default 1e4, i.e. a units or timing blunder, not noise):
                      epoch skipped
``covariance_repair`` a variance of P went non-positive: P rebuilt from its
                      symmetric eigen-decomposition with eigenvalues floored
                      at 1e-12 of its largest

A non-finite value in P or the state raises :class:`NumericalError` naming
the epoch: results never silently carry NaN.

Stochastic cloning (TDCP and any other measurement of two epochs). A
measurement model with ``clone_size = c > 0`` asks the engine to carry, beside
the ``n`` error states, a copy ``x_c = J x`` of some of them taken at that
model's previous epoch (``J = model.clone_rows(nav)``, (c, n)). The engine then
keeps the blocks of the augmented covariance::

    [[P,      P_xc],      P_xc <- Phi P_xc over each propagation step
     [P_xc^T, P_cc]]      (the clone is a constant: its own block does not move)

updates every measurement at those epochs in the augmented space (a model's
``H`` has ``n`` or ``n + c`` columns), hands the clone part of each correction
to ``model.correct_clone(dx_c)`` (the model owns the estimate the clone
describes), and after the updates of each of the model's epochs replaces the
clone: ``P_xc = P J^T``, ``P_cc = J P J^T``, ``model.remember(i, nav, clock)``.
At most one cloning model per filter. A model without a clone may still have
``remember`` (called the same way), e.g. to use its previous estimate as if it
were exact.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from ..data import ImuData, InitialState  # noqa: F401  (InitialState re-exported)
from ..errors import ConfigError, NumericalError
from ..ins._error_kernels import propagate_block
from ..ins.error_model import ClockModel, StateLayout, process_noise
from ..ins.imu_model import ImuErrorModel
from ._ekf_kernels import (ABSURD, NON_FINITE, NEEDS_REPAIR, OK, S_NOT_POSITIVE_DEFINITE, ekf_correct,
                           ekf_correct_dx)
from .timing import split_at_times


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
        An update was applied at this epoch.
    sensor : ndarray (K, 12)
        Sensor-error estimates ``[bg, ba, sg, sa]``.
    pv_cov : ndarray (K, 6, 6)
        Covariance of the velocity and position errors (for NEES).
    w_b : ndarray (K, 3)
        Compensated body angular rate of the last increment [rad/s] (for
        lever-arm velocities).
    nis : ndarray (M,)
        NIS of each applied update, and ``nis_dim`` its dimension.
    recoveries : dict
        Counts of each numerical recovery (see module docstring).
    timing : dict
        ``epoch_time_mean_us`` (all filter work, mechanization included,
        divided by the number of measurement epochs), ``update_time_mean_us``
        (measurement model, correction and feedback only), ``wall_time_s``.
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
    layout: StateLayout
    P: np.ndarray | None = None


_WARM = set()


def _event_index(times: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Index in the merged event times of each query time (within 1e-6 s)."""
    k = np.clip(np.searchsorted(times, query - 1e-6), 0, len(times) - 1)
    if query.size and np.abs(times[k] - query).max() > 1e-6:
        raise AssertionError("an event time was lost while merging")  # a bug, not bad input
    return k


def _warm_up(layout: StateLayout) -> None:
    """Compile (or load from the numba cache) the kernels for this layout once
    per process, so that the measured epoch times are steady-state costs, not
    the one-off compilation."""
    if layout.n in _WARM:
        return
    n = layout.n
    nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.5, 0.5, 0.0])
    one = np.zeros((1, 3))
    propagate_block(nav, np.zeros(6), np.zeros(12), one, one, np.full(1, 0.01), np.eye(n),
                    np.zeros(n), layout.as_array(), np.full(4, np.inf), np.empty((4, n, n)))
    H = np.zeros((3, n))
    H[:, 6:9] = np.eye(3)
    ekf_correct(np.eye(n), np.zeros(3), H, np.ones(3), 1e4, nav, np.zeros(12), np.zeros(2),
                layout.as_array())
    ekf_correct_dx(np.eye(n), np.zeros(3), H, np.ones(3), 1e4, nav, np.zeros(12), np.zeros(2),
                   layout.as_array())
    _WARM.add(n)


class ErrorStateEkf:
    """Closed-loop error-state EKF on the strapdown INS (method M1).

    Parameters
    ----------
    layout : StateLayout
        Which error states to carry (15, 17 or 21).
    imu_model : ImuErrorModel
        The filter's model of the IMU (sets Q and the initial sensor sigma).
    covariance_interval : float
        Longest covariance propagation step [s] (at most 1 s; see
        :func:`mixnav.ins._error_kernels.discretize`).
    absurd_sigma : float
        Innovations beyond this many standard deviations are rejected as
        blunders (counted).
    clock : ClockModel, optional
        Receiver clock noise (17-state layout).
    """

    def __init__(self, layout: StateLayout, imu_model: ImuErrorModel,
                 covariance_interval: float = 1.0, absurd_sigma: float = 1e4,
                 clock: ClockModel | None = None):
        if not 0.0 < covariance_interval <= 1.0:
            raise ConfigError("must be in (0, 1] s", key="covariance_interval")
        self.layout = layout
        self.imu_model = imu_model
        self.covariance_interval = float(covariance_interval)
        self.absurd_sigma = float(absurd_sigma)
        self.qc, self.tau, self.sensor_sigma0 = process_noise(layout, imu_model, clock)

    def initial_covariance(self, init: InitialState) -> np.ndarray:
        lay = self.layout
        s = self.sensor_sigma0.copy()
        s[lay.att] = init.sigma_att
        s[lay.vel] = init.sigma_vel
        s[lay.pos] = init.sigma_pos
        if lay.clk >= 0:
            s[lay.clk:lay.clk + 2] = init.sigma_clock
        return np.diag(s ** 2)

    def _belief(self, P0: np.ndarray, n_clone: int) -> "GaussianBelief":
        """The covariance (or bank of covariances) the run loop carries.

        Subclasses return their own kind (robust updates, a Gaussian sum)."""
        return GaussianBelief(P0, n_clone, self.layout, self.absurd_sigma)

    def run(self, imu: ImuData, init: InitialState, measurements=(),
            output_times: np.ndarray | None = None) -> FilterResult:
        """Run the filter over the IMU data.

        Parameters
        ----------
        imu : ImuData
            Raw increments.
        init : InitialState
        measurements : sequence of measurement models
            Each has ``times`` and ``measure(i, nav, w_b, clock) -> (z, H, R) | None``
            (``R`` full, or its diagonal as a 1-D array).
        output_times : ndarray, optional
            Where to record the state; default: every measurement epoch and
            every ``covariance_interval``.
        """
        lay = self.layout
        _warm_up(lay)
        cloners = [m for m in measurements if getattr(m, "clone_size", 0) > 0]
        if len(cloners) > 1:
            raise ConfigError("at most one measurement model per filter may use a stochastic clone")
        cloner = cloners[0] if cloners else None
        nc = cloner.clone_size if cloner is not None else 0
        for model in measurements:  # compile their kernels outside the timed loop too
            if len(model.times):
                model.measure(0, np.array(init.nav, dtype=float), np.zeros(3), np.zeros(2))
        t0, t1 = init.time, float(imu.time[-1])
        if t0 < imu.start_time - 1e-9:
            raise ConfigError(f"initial time {t0} is before the first IMU sample {imu.start_time}",
                              key="init.time")
        grid = np.arange(t0 + self.covariance_interval, t1 + 1e-9, self.covariance_interval)
        meas_events = []  # (time, model index, sample index)
        for mi, model in enumerate(measurements):
            mt = np.asarray(model.times)
            sel = np.nonzero((mt > t0) & (mt <= t1))[0]
            meas_events += [(float(mt[i]), mi, int(i)) for i in sel]
        meas_events.sort()
        out_t = grid if output_times is None else np.asarray(output_times, dtype=float)
        out_t = out_t[(out_t > t0) & (out_t <= t1)]
        if output_times is None and meas_events:
            out_t = np.union1d(out_t, [e[0] for e in meas_events])
        times = np.union1d(np.union1d(grid, out_t), [e[0] for e in meas_events])
        times = times[np.concatenate([[True], np.diff(times) > 1e-6])] if len(times) else times
        # Start at the first IMU sample at or after t0.
        k0 = int(np.searchsorted(imu.time, t0 - 1e-6))
        if k0 > 0 and abs(imu.time[k0 - 1] - t0) > 1e-6 and abs(imu.time[k0] - t0) > 1e-6:
            imu, _ = split_at_times(imu, np.array([t0]))
            k0 = int(np.searchsorted(imu.time, t0 - 1e-6))
        elif abs(imu.time[k0] - t0) <= 1e-6:
            k0 += 1
        imu_s, ends = split_at_times(imu, times)

        nav = np.array(init.nav, dtype=float)
        prev = np.zeros(6)
        sensor = np.zeros(12) if init.sensor0 is None else np.array(init.sensor0, dtype=float)
        clock = np.zeros(2)
        belief = self._belief(self.initial_covariance(init), nc)
        work = np.empty((4, lay.n, lay.n))
        layout_arr = lay.as_array()
        recov = belief.counts
        n_out = len(out_t)
        rec_nav = np.empty((n_out, 10))
        rec_sig = np.empty((n_out, lay.n))
        rec_used = np.zeros(n_out, dtype=bool)
        rec_sensor = np.empty((n_out, 12))
        rec_pv = np.empty((n_out, 6, 6))
        rec_w = np.empty((n_out, 3))
        nis_list, nis_dim = [], []
        # Map outputs and measurements to event indices with the same
        # tolerance that merged the event times (never by float equality).
        is_out = np.zeros(len(times), dtype=bool)
        is_out[_event_index(times, out_t)] = True
        ev_by_index: dict[int, list] = {}
        if meas_events:
            idx = _event_index(times, np.array([e[0] for e in meas_events]))
            for k, e in zip(idx, meas_events):
                ev_by_index.setdefault(int(k), []).append(e)
        update_time = 0.0
        n_updates = 0
        io = 0
        start = k0
        wall0 = _time.perf_counter()
        for ti, t in enumerate(times):
            end = int(ends[ti]) + 1
            T = propagate_block(nav, prev, sensor, imu_s.dtheta[start:end], imu_s.dvel[start:end],
                                imu_s.dt[start:end], belief.P, self.qc, layout_arr, self.tau, work)
            events = ev_by_index.get(ti, ())
            if T > 0.0:
                belief.propagated(work, T, measured=bool(events))
            if lay.clk >= 0:
                clock[0] += clock[1] * T
            start = end
            used = False
            for (_, mi, i) in events:
                tu = _time.perf_counter()
                w_b = prev[0:3] / imu_s.dt[end - 1]
                model = measurements[mi]
                zhr = model.measure(i, nav, w_b, clock)
                if zhr is not None:
                    z, H, r = zhr
                    kinds = model.row_kinds(i, len(z)) if hasattr(model, "row_kinds") else None
                    status, nis = belief.update(z, H, r, kinds, nav, sensor, clock, layout_arr, cloner)
                    if status == ABSURD:
                        recov["rejected_absurd"] += 1
                    elif status == S_NOT_POSITIVE_DEFINITE:
                        recov["rejected_not_pd"] += 1
                    elif status == NON_FINITE:
                        raise NumericalError(f"the update at t = {t:.3f} s gave a non-finite "
                                             "covariance or correction")
                    else:
                        if status == NEEDS_REPAIR:
                            belief.repair()
                        nis_list.append(nis)
                        nis_dim.append(len(z))
                        used = True
                if hasattr(model, "remember"):
                    if model is cloner:  # replace the clone by the current state
                        belief.replace_clone(model.clone_rows(nav))
                    model.remember(i, nav, clock)
                update_time += _time.perf_counter() - tu
                n_updates += 1
            if not np.isfinite(nav).all():
                raise NumericalError(f"INS state became non-finite at t = {t:.3f} s")
            if is_out[ti]:
                P = belief.covariance()
                rec_nav[io] = nav
                rec_sig[io] = np.sqrt(np.diag(P))
                rec_used[io] = used
                rec_sensor[io] = sensor
                rec_pv[io] = P[3:9, 3:9]
                rec_w[io] = prev[0:3] / imu_s.dt[end - 1] if end > 0 else 0.0
                io += 1
        wall = _time.perf_counter() - wall0
        n_ep = max(n_updates, 1)
        timing = {"epoch_time_mean_us": wall / n_ep * 1e6,
                  "update_time_mean_us": update_time / n_ep * 1e6,
                  "wall_time_s": wall, "measurement_epochs": n_updates}
        timing.update(self.extra_timing())
        return FilterResult(
            time=out_t[:io], nav=rec_nav[:io], sigma=rec_sig[:io], gnss_used=rec_used[:io],
            sensor=rec_sensor[:io], pv_cov=rec_pv[:io], w_b=rec_w[:io], nis=np.array(nis_list),
            nis_dim=np.array(nis_dim, dtype=int), recoveries=recov, layout=lay, P=belief.covariance(),
            timing=timing,
        )

    def extra_timing(self) -> dict:
        """Timing entries beyond the loop's own (e.g. the learning time of a mixture)."""
        return {}


def repair_covariance(P: np.ndarray) -> None:
    """Rebuild P (in place) from its eigen-decomposition with eigenvalues floored
    at 1e-12 of the largest."""
    w, v = np.linalg.eigh(P)
    w = np.maximum(w, 1e-12 * w.max())
    P[:, :] = (v * w) @ v.T


class GaussianBelief:
    """The one Gaussian of the EKF: ``P``, and the stochastic-clone blocks.

    The run loop hands it each propagation step (``propagated``), each
    measurement (``update``, which also feeds the correction back into the
    INS, sensor and clock estimates) and each clone replacement. Subclasses
    change only :meth:`correct` (e.g. the robust adaptive EKF).

    ``counts`` holds the recoveries of the module docstring (and whatever a
    subclass adds); the run loop reports it as ``FilterResult.recoveries``.
    """

    def __init__(self, P0: np.ndarray, n_clone: int, layout: StateLayout, absurd_sigma: float):
        n = layout.n
        self.P = np.array(P0, dtype=float)
        self.nc = n_clone
        self.P_xc = np.zeros((n, n_clone))  # cross-covariance of the error state and the clone
        self.P_cc = np.zeros((n_clone, n_clone))
        self.have_clone = False
        self.absurd_sigma = absurd_sigma
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0}

    def propagated(self, work: np.ndarray, T: float, measured: bool) -> None:
        """``P`` was propagated in place by the kernel; move the clone's cross block."""
        if self.have_clone:
            self.P_xc = work[1] @ self.P_xc  # work[1] holds this step's Phi

    def correct(self, P, z, H, r, nav, sensor, clock, layout_arr):
        """One gated Kalman correction with feedback: ``(P_post, dx, nis, status)``."""
        return ekf_correct_dx(P, z, H, r, self.absurd_sigma, nav, sensor, clock, layout_arr)

    def update(self, z, H, r, kinds, nav, sensor, clock, layout_arr, cloner):
        """Apply one measurement; returns ``(status, nis)``."""
        n, nc = self.P.shape[0], self.nc
        if self.have_clone:
            Pa = np.empty((n + nc, n + nc))
            Pa[:n, :n] = self.P
            Pa[:n, n:] = self.P_xc
            Pa[n:, :n] = self.P_xc.T
            Pa[n:, n:] = self.P_cc
            if H.shape[1] == n:
                H = np.hstack([H, np.zeros((len(z), nc))])
            Pa_new, dx, nis, status = self.correct(Pa, z, H, r, nav, sensor, clock, layout_arr)
            if status in (OK, NEEDS_REPAIR):  # applied: split the blocks back
                self.P = np.ascontiguousarray(Pa_new[:n, :n])
                cloner.correct_clone(dx[n:])
                self.P_xc = Pa_new[:n, n:].copy()
                self.P_cc = Pa_new[n:, n:].copy()
            return status, nis
        if H.shape[1] != n:
            raise NumericalError("a measurement model returned H for a clone the "
                                 "filter does not carry")  # a bug, not bad input
        P_new, dx, nis, status = self.correct(self.P, z, H, r, nav, sensor, clock, layout_arr)
        if status in (OK, NEEDS_REPAIR):
            self.P = P_new
        return status, nis

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
