"""The run loop every error-state estimator shares: events, mechanization,
measurement epochs, feedback, stochastic clones, recording.

1. Event times = measurement epochs, output epochs and a covariance step at
   least every ``covariance_interval``; the IMU increments that straddle an
   event are split at it once, up front (:mod:`mixnav.engine.timing`).
2. Per event the motion model mechanizes the increments up to it and gives
   the step's ``Phi`` and ``Qd`` (one compiled call); the estimator sees the
   :class:`~mixnav.engine.protocols.Transition` (with the step's
   :class:`~mixnav.engine.protocols.StepInputs` only for an estimator that sets
   ``needs_step_inputs``: the UKF family mechanizes its sigma points from them).
3. At a measurement epoch the estimator gets an
   :class:`~mixnav.engine.protocols.Epoch` (lazy rows) and returns a
   :class:`~mixnav.engine.protocols.Correction`; **only the engine feeds it
   back** (``motion.inject``: INS, sensor, clock and auxiliary estimates), and
   hands the clone part to the model's memory.
4. At an output epoch the recorder stores the state and its 1-sigma; with
   ``history=True`` the engine also keeps what a smoother needs
   (:class:`~mixnav.engine.result.History`).

Numerical recoveries (each counted in ``FilterResult.recoveries``):

``rejected_not_pd``   innovation covariance not positive definite: epoch skipped
``rejected_absurd``   innovation beyond ``absurd_sigma`` standard deviations
                      (default 1e4, i.e. a units or timing blunder, not noise):
                      epoch skipped
``covariance_repair`` a variance of P went non-positive: P rebuilt from its
                      symmetric eigen-decomposition with eigenvalues floored
                      at 1e-12 of its largest

and whatever the estimator adds to its ``counts``. A non-finite value in P or
the state raises :class:`~mixnav.errors.NumericalError` naming the epoch:
results never silently carry NaN.

Stochastic cloning and memory. A measurement model with ``remembers`` gets,
at each of its epochs, the memory it returned (``model.remember``) after the
updates of its previous epoch; the engine holds it, so models keep no state
(a model with ``remembers_aux = True`` also gets the auxiliary estimates, ``aux=``).
A model with ``clone_size = c > 0`` also asks for a stochastic clone
``x_c = J x`` of the error state at that epoch (``J = model.clone_rows(nav)``,
(c, n)): the estimator carries the augmented covariance::

    [[P,      P_xc],      P_xc <- Phi P_xc over each propagation step
     [P_xc^T, P_cc]]      (the clone is a constant: its own block does not move)

a model's ``H`` has ``n`` or ``n + c`` columns, the clone part of each
correction goes to ``model.correct_memory``, and after the model's epoch the
estimator replaces the clone (``replace_clone(J)``). At most one cloning model
per filter.

Step API: ``engine.start(imu, init)`` then ``engine.step()`` until it returns
False, then ``engine.result()``; ``engine.run`` does all three.
"""

from __future__ import annotations

import time as _time

import numpy as np

from ..data import ImuData, InitialState
from ..errors import ArgumentError, NumericalError
from ..measurements.kinds import kind_code
from .protocols import Epoch, StepInputs, Transition
from .result import FilterResult, History
from .status import ABSURD, NEEDS_REPAIR, NON_FINITE, OK, S_NOT_POSITIVE_DEFINITE
from ._record_kernel import record_epoch
from .timing import split_at_times


def _event_index(times: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Index in the merged event times of each query time (within 1e-6 s)."""
    k = np.clip(np.searchsorted(times, query - 1e-6), 0, len(times) - 1)
    if query.size and np.abs(times[k] - query).max() > 1e-6:
        raise AssertionError("an event time was lost while merging")  # a bug, not bad input
    return k


def check_covariance_interval(value: float) -> float:
    """The longest propagation step [s], which must be in (0, 1] (an :class:`ArgumentError` otherwise)."""
    if not 0.0 < value <= 1.0:
        raise ArgumentError(f"must be in (0, 1] s, got {value}", argument="covariance_interval")
    return float(value)


_WARM = []


def _warm_record() -> None:
    """Compile (or load from numba's cache) the record kernel once per process."""
    if not _WARM:
        z = np.zeros
        record_epoch(0, np.eye(9), z(10), z(12), z(2), z(6), 0.01, z((1, 10)), z((1, 9)), z((1, 12)), z((1, 2)),
                     z((1, 6, 6)), z((1, 3)))
        _WARM.append(True)


class Engine:
    """Drives one estimator about one nominal state through IMU data and measurements.

    Parameters
    ----------
    motion : MotionModel
        E.g. :class:`mixnav.ins.strapdown.StrapdownMotion`.
    estimator : Estimator
        E.g. :class:`mixnav.filters.ekf.KalmanEstimator`.
    measurements : sequence of MeasurementModel
    covariance_interval : float
        Longest propagation step [s], in (0, 1].
    rng : numpy.random.Generator or int, optional
        The estimator's own random stream (a seed makes one); default seed 0.
    history : bool
        Keep what a smoother needs (:class:`~mixnav.engine.result.History`).
    """

    def __init__(self, motion, estimator, measurements=(), covariance_interval: float = 1.0, rng=None,
                 history: bool = False):
        self.covariance_interval = check_covariance_interval(covariance_interval)
        self.motion = motion
        self.estimator = estimator
        self.measurements = list(measurements)
        for mi, m in enumerate(self.measurements):
            if not (hasattr(m, "rows") and hasattr(m, "times")):
                raise ArgumentError(f"measurement {mi} ({type(m).__name__}) is not a measurement model: it "
                                    "needs times and rows() (mixnav.measurements.base.MeasurementModel)",
                                    argument=f"measurements[{mi}]")
            for name in getattr(m, "kinds", ()):  # an unknown kind is an error, never a default
                kind_code(name, argument=f"measurements[{mi}].kinds")
        cloners = [m for m in self.measurements if getattr(m, "clone_size", 0) > 0]
        if len(cloners) > 1:
            raise ArgumentError("at most one measurement model per filter may use a stochastic clone",
                                argument="measurements")
        self.cloner = cloners[0] if cloners else None
        self._ci = self.measurements.index(self.cloner) if cloners else -1
        self.n_clone = self.cloner.clone_size if self.cloner is not None else 0
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(0 if rng is None else rng)
        self.keep_history = bool(history)

    # --- set-up -----------------------------------------------------------------------------
    def start(self, imu: ImuData, init: InitialState, output_times: np.ndarray | None = None) -> None:
        """Prepare a run: events, split IMU increments, initial state and belief."""
        if not isinstance(imu, ImuData):
            raise ArgumentError(f"expected ImuData, got {type(imu).__name__}", argument="imu")
        if not isinstance(init, InitialState):
            raise ArgumentError(f"expected InitialState, got {type(init).__name__}", argument="init")
        motion, est, lay = self.motion, self.estimator, self.motion.layout
        check = getattr(motion, "check_inputs", None)
        if check is not None:   # the increments must be the ones this motion model is driven by
            check(imu)
        motion.warm_up()
        est.warm_up()
        _warm_record()
        self.aux = {name: np.zeros(sl.stop - sl.start) for name, sl in lay.aux}
        for model in self.measurements:  # compile their kernels outside the timed loop too
            model.warm_up(init.nav, self.aux)
        t0, t1 = init.time, float(imu.time[-1])
        self._t0 = t0
        if t0 < imu.start_time - 1e-9:
            raise ArgumentError(f"initial time {t0} is before the first IMU sample {imu.start_time}",
                                argument="init.time")
        ci = self.covariance_interval
        grid = np.arange(t0 + ci, t1 + 1e-9, ci)
        meas_events = []  # (time, model index, sample index)
        for mi, model in enumerate(self.measurements):
            mt = np.asarray(model.times)
            sel = np.nonzero((mt > t0) & (mt <= t1))[0]
            meas_events += [(float(mt[i]), mi, int(i)) for i in sel]
        meas_events.sort()
        out_t = grid if output_times is None else np.asarray(output_times, dtype=float)
        out_t = out_t[(out_t > t0) & (out_t <= t1)]
        if output_times is None and meas_events:
            out_t = np.union1d(out_t, [e[0] for e in meas_events])
        # merge output times closer than the event tolerance, as the event times are
        # merged below: one record per event, so the record and out_t stay aligned
        out_t = out_t[np.concatenate([[True], np.diff(out_t) > 1e-6])] if len(out_t) else out_t
        times = np.union1d(np.union1d(grid, out_t), [e[0] for e in meas_events])
        times = times[np.concatenate([[True], np.diff(times) > 1e-6])] if len(times) else times
        # Start at the first IMU sample at or after t0.
        k0 = int(np.searchsorted(imu.time, t0 - 1e-6))
        if k0 > 0 and abs(imu.time[k0 - 1] - t0) > 1e-6 and abs(imu.time[k0] - t0) > 1e-6:
            imu, _ = split_at_times(imu, np.array([t0]))
            k0 = int(np.searchsorted(imu.time, t0 - 1e-6))
        elif abs(imu.time[k0] - t0) <= 1e-6:
            k0 += 1
        self._imu, self._ends = split_at_times(imu, times)
        self._times = times
        self._out_t = out_t
        self._is_out = np.zeros(len(times), dtype=bool)
        self._is_out[_event_index(times, out_t)] = True
        # Map measurements to event indices with the same tolerance that merged the
        # event times (never by float equality).
        self._events: dict[int, list] = {}
        if meas_events:
            idx = _event_index(times, np.array([e[0] for e in meas_events]))
            for k, e in zip(idx, meas_events):
                self._events.setdefault(int(k), []).append((e[1], e[2]))

        self.nav = np.array(init.nav, dtype=float)
        self.prev = np.zeros(6)
        self.sensor = np.zeros(12) if init.sensor0 is None else np.array(init.sensor0, dtype=float)
        self.clock = np.zeros(2) if init.clock0 is None else np.array(init.clock0, dtype=float)
        for name, v in (init.aux0 or {}).items():
            if name not in self.aux:
                raise ArgumentError(f"the layout has no auxiliary block '{name}' (it has: "
                                    f"{', '.join(self.aux) or 'none'})", argument="init.aux0")
            v = np.asarray(v, dtype=float).reshape(-1)
            if v.shape != self.aux[name].shape or not np.isfinite(v).all():
                raise ArgumentError(f"block '{name}' needs {self.aux[name].size} finite values, got {v.tolist()}",
                                    argument="init.aux0")
            self.aux[name][:] = v
        self.memory = [None] * len(self.measurements)
        est.init(motion, motion.initial_covariance(init), self.n_clone, self.rng)
        self.counts = est.counts
        for k in ("rejected_not_pd", "rejected_absurd", "covariance_repair"):
            self.counts.setdefault(k, 0)
        self._work = np.empty((4, lay.n, lay.n))
        self._n_events = len(times)
        self._ends_list = self._ends.tolist()
        self._propagate = motion.propagate
        self._inject = motion.inject
        self._recentre = est.recentre if getattr(est, "carry_mean", False) else None
        # the pre-step nominal for an estimator that mechanizes its own states (UKF)
        self._pre = (np.empty(10), np.empty(6), np.empty(2)) if getattr(est, "needs_step_inputs", False) else None
        self._has_clock = lay.clk >= 0
        self._i_vel = lay.vel.start if lay.vel is not None else -1
        self._i_pos = lay.pos.start
        self._n = lay.n
        self._start_k = k0
        self._ti = 0
        self._io = 0
        self._used_since_out = False  # an update since the last output epoch (gnss_used)
        n_out = len(out_t)
        self._rec = {"nav": np.empty((n_out, 10)), "sigma": np.empty((n_out, lay.n)),
                     "used": np.zeros(n_out, dtype=bool), "sensor": np.empty((n_out, 12)),
                     "clock": np.empty((n_out, 2)), "pv": np.empty((n_out, 6, 6)), "w_b": np.empty((n_out, 3)),
                     "aux": {name: np.empty((n_out, len(v))) for name, v in self.aux.items()}}
        self._nis, self._nis_dim, self._nis_kind = [], [], []
        self._nis_time, self._nis_logdet = [], []
        self._history = self._allocate_history(len(times), lay.n) if self.keep_history else None
        self._update_time = 0.0
        self._n_updates = 0
        self._wall = 0.0

    # --- one event --------------------------------------------------------------------------
    def step(self) -> bool:
        """Process the next event (propagation, its measurement epochs, recording).

        Returns False when there is no event left (nothing was done)."""
        ti = self._ti
        if ti >= self._n_events:
            return False
        perf = _time.perf_counter
        wall0 = perf()
        t = self._times[ti]
        imu, est, nav, sensor, clock, prev = self._imu, self.estimator, self.nav, self.sensor, self.clock, self.prev
        end = self._ends_list[ti] + 1
        s = self._start_k
        work = self._work
        pre = self._pre
        if pre is not None:
            pre[0][:] = nav
            pre[1][:] = prev
            pre[2][:] = clock
        T = self._propagate(nav, prev, sensor, imu.dtheta[s:end], imu.dvel[s:end], imu.dt[s:end],
                            est.kernel_covariance, work)
        events = self._events.get(ti, ())
        if T > 0.0:
            if pre is None:
                est.predict(Transition(work[0], work[1], work[2], T, bool(events)))
            else:
                est.predict(Transition(work[0], work[1], work[2], T, bool(events),
                                       StepInputs(pre[0], pre[1], pre[2], sensor, imu.dtheta[s:end],
                                                  imu.dvel[s:end], imu.dt[s:end], nav)))
        if self._has_clock:
            clock[0] += clock[1] * T
        self._start_k = end
        hist = self._history
        if hist is not None:  # written in place: no per-event allocation
            hist.P_pred[ti] = est.covariance()
            dx_sum = hist.dx[ti]
            dx_sum[:] = 0.0
        used = False
        for (mi, i) in events:
            tu = perf()
            w_b = prev[0:3] / imu.dt[end - 1]
            model = self.measurements[mi]
            corr = est.update(Epoch(t, i, model, nav, w_b, clock, self.memory[mi], self.aux))
            if corr is not None:
                status = corr.status
                if status == OK or status == NEEDS_REPAIR:
                    self._feedback(corr.dx)
                    if status == NEEDS_REPAIR:
                        est.repair()
                    self._nis.append(corr.nis)
                    self._nis_dim.append(corr.m)
                    self._nis_kind.append(model)
                    self._nis_time.append(t)
                    self._nis_logdet.append(corr.logdet)
                    used = True
                    if hist is not None:
                        dx_sum += corr.dx[:self._n]
                elif status == ABSURD:
                    self.counts["rejected_absurd"] += 1
                elif status == S_NOT_POSITIVE_DEFINITE:
                    self.counts["rejected_not_pd"] += 1
                elif status == NON_FINITE:
                    raise NumericalError(f"the update at t = {t:.3f} s gave a non-finite "
                                         "covariance or correction")
            if model.remembers:
                if model is self.cloner:  # replace the clone by the current state
                    est.replace_clone(model.clone_rows(nav))
                if getattr(model, "remembers_aux", False):   # e.g. inter-system offsets at the clone
                    self.memory[mi] = model.remember(i, nav, w_b, clock, aux=self.aux)
                else:
                    self.memory[mi] = model.remember(i, nav, w_b, clock)
            self._update_time += perf() - tu
            self._n_updates += 1
        if self._is_out[ti]:
            # gnss_used: an update since the previous output epoch (output epochs need not
            # coincide with measurement epochs, e.g. at a reference's times)
            finite = self._record(end, used or self._used_since_out)
            self._used_since_out = False
        else:
            self._used_since_out = self._used_since_out or used
            finite = bool(np.isfinite(nav).all())
        if not finite:
            raise NumericalError(f"INS state became non-finite at t = {t:.3f} s")
        if hist is not None:
            hist.time[ti] = t
            if T > 0.0:
                hist.Phi[ti] = work[1]
            else:
                hist.Phi[ti] = 0.0
                hist.Phi[ti].flat[::self._n + 1] = 1.0
            hist.P_filt[ti] = est.covariance()
            hist.nav[ti] = nav
            hist.updated[ti] = used
        self._ti = ti + 1
        self._wall += perf() - wall0
        return True

    @staticmethod
    def _allocate_history(n_events: int, n: int) -> History:
        """One preallocated array per field, ``n_events`` rows: ``3 n^2 + n + 11`` doubles and
        one byte per event, nothing else (no per-event Python objects). ``np.empty`` only
        reserves address space; the pages are committed as the run writes them, so a run
        stopped early (step API) costs what it has done."""
        return History(time=np.empty(n_events), Phi=np.empty((n_events, n, n)),
                       P_pred=np.empty((n_events, n, n)), P_filt=np.empty((n_events, n, n)),
                       dx=np.empty((n_events, n)), nav=np.empty((n_events, 10)),
                       updated=np.zeros(n_events, dtype=bool))

    def _feedback(self, dx: np.ndarray) -> None:
        """The one place a correction reaches the nominal state (and the clone's memory);
        an estimator that carries a mean is re-centred on the moved nominal."""
        self._inject(self.nav, self.sensor, self.clock, self.aux, dx)
        if self._recentre is not None:
            self._recentre(dx)
        if len(dx) > self._n:
            ci = self._ci
            self.memory[ci] = self.cloner.correct_memory(self.memory[ci], dx[self._n:])

    def _record(self, end: int, used: bool) -> bool:
        """Store the output epoch; returns whether the nominal state is finite."""
        r, io = self._rec, self._io
        finite = record_epoch(io, self.estimator.covariance(), self.nav, self.sensor, self.clock, self.prev,
                              self._imu.dt[end - 1] if end > 0 else 0.0, r["nav"], r["sigma"], r["sensor"],
                              r["clock"], r["pv"], r["w_b"], self._i_vel, self._i_pos)
        r["used"][io] = used
        for name, v in self.aux.items():
            r["aux"][name][io] = v
        self._io = io + 1
        return finite

    @property
    def time(self) -> float:
        """Time of the last event processed [s] (the initial time before the first step)."""
        return float(self._times[self._ti - 1]) if self._ti > 0 else float(self._t0)

    # --- the result -------------------------------------------------------------------------
    def result(self) -> FilterResult:
        """The solution of the events processed so far."""
        io, r, lay = self._io, self._rec, self.motion.layout
        n_ep = max(self._n_updates, 1)
        timing = {"epoch_time_mean_us": self._wall / n_ep * 1e6,
                  "update_time_mean_us": self._update_time / n_ep * 1e6,
                  "wall_time_s": self._wall, "measurement_epochs": self._n_updates}
        timing.update(self.estimator.diagnostics())
        sensor = r["sensor"][:io]
        estimates = lay.sensor_estimates(sensor)
        if lay.clk >= 0:
            estimates["clock"] = r["clock"][:io]
        for name, v in r["aux"].items():
            estimates[name] = v[:io]
        kinds = {}
        nis_kind = np.array([kinds.setdefault(id(m), "+".join(m.kinds)) for m in self._nis_kind], dtype=object)
        history = None
        if self._history is not None:  # views of the events done (rows already written never change)
            h, e = self._history, self._ti
            history = History(time=h.time[:e], Phi=h.Phi[:e], P_pred=h.P_pred[:e], P_filt=h.P_filt[:e],
                              dx=h.dx[:e], nav=h.nav[:e], updated=h.updated[:e])
        outputs = getattr(self.estimator, "outputs", lambda: {})()
        return FilterResult(
            time=self._out_t[:io], nav=r["nav"][:io], sigma=r["sigma"][:io], gnss_used=r["used"][:io],
            sensor=sensor, pv_cov=r["pv"][:io], w_b=r["w_b"][:io], nis=np.array(self._nis),
            nis_dim=np.array(self._nis_dim, dtype=int), recoveries=self.counts, layout=lay,
            P=self.estimator.covariance(), timing=timing, estimates=estimates, nis_kind=nis_kind,
            outputs=outputs, history=history, motion=self.motion, nis_time=np.array(self._nis_time, float),
            nis_logdet=np.array(self._nis_logdet, float))

    def run(self, imu: ImuData, init: InitialState, output_times: np.ndarray | None = None) -> FilterResult:
        """Run over all the IMU data: :meth:`start`, :meth:`step` to the end, :meth:`result`."""
        self.start(imu, init, output_times)
        step = self.step
        while step():
            pass
        return self.result()
