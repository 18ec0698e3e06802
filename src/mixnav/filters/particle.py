"""The SIR (bootstrap) particle filter on the one navigation core (issue 19, first step).

Like the UKF (:mod:`mixnav.filters.ukf`, docs/ukf.md) the particle filter is a
*mean-carrying error-state estimator whose members are full states*: its
belief is ``N`` weighted particles ``D[j]`` over the error state ``dx = x_true
- x_est`` of the layout (attitude as a rotation vector about the nominal
quaternion, velocity, NED position metres, sensor/clock/auxiliary errors).

Per propagation step (the motion model's ``particle_kernels().step``,
:func:`mixnav.ins._particle_kernels.pf_step`, one compiled call for the whole array,
fused per particle): each particle becomes the full state
``nominal_before (+) D[j]``, is mechanized with its own sensor errors over the
step's IMU block and differenced from the mechanized nominal (the engine's
feedback map, the strapdown step, the UKF's difference map); process noise
``w_j ~ N(0, Qd)`` (the transition's ``Qd``, through a symmetric square root
``SQ``) is drawn per particle from the estimator's own random stream (the
``rng`` the engine hands to :meth:`ParticleEstimator.init`), before the call.
Every per-step array is allocated once in :meth:`ParticleEstimator.init`
(O(N n)); with ``parallel=True`` the per-particle kernels run on numba's threads
and give bitwise the same particles (docs/particle.md, "Speed").

At a measurement epoch the particles are made full states about the current
nominal, ``epoch.model.predict_batch`` gives ``(y, Y, R)``, and each log-weight
gains the Gaussian log-likelihood ``-1/2 sum (y - Y_j)^2 / R`` (normalised in
log space: subtract the maximum, exponentiate, divide by the sum). Where the epoch's model
offers a fused member update (``epoch.model.member_update``, a
:class:`~mixnav.measurements.base.MemberUpdate`: the loose GNSS model does) its one kernel
does all of it from the particle array, with the weighted mean and covariance: the generic
path's numbers to round-off (tested; ``fused=False`` keeps the generic path). The estimator
asks for the capability and never names a measurement model. The
effective sample size ``1 / sum w^2`` decides a systematic resampling (ESS <
``resample_threshold`` N); with ``roughening = h > 0`` (on by default, 0.9: plain SIR
diverges on loose-demo, docs/particle.md) the Liu-West kernel jitter then
re-diversifies the particles (:meth:`ParticleEstimator._resample`; the Cholesky factor
of the weighted covariance, the normals drawn inside the jitter kernel: a ziggurat on
per-chunk SplitMix64 streams seeded from the estimator's generator, ``_normals.py``).
The weighted mean deviation (computed before the
resampling) is returned as the correction; the engine feeds it back and calls
:meth:`recentre`, which shifts every particle. The recorded mean and covariance are
the weighted sample moments before any resampling (the resampling and the jitter
keep them in expectation and only add Monte Carlo noise).

On a motion model other than the strapdown INS (dead reckoning, constant velocity) the
particles go through the model's ensemble seam (:class:`~mixnav.engine.protocols.MotionModel`:
``propagate_members``, then the same noise step with ``F = I``; ``member_states`` and
``member_rates`` at an epoch) and every update takes the generic path; the fused
strapdown step and a model's fused member update are the INS's fast path.

Degeneracy: when no particle can explain the measurement (every log-likelihood
non-finite, or the best particle's squared normalised innovation beyond
``absurd_sigma^2`` per row) the epoch is rejected (``ABSURD``, nothing fed
back), the weights are reset to uniform and the particles' spread about their
mean is doubled; ``counts["pf_degenerate"]`` counts it. Never a NaN.
"""

from __future__ import annotations

import os
import threading

import numpy as np

from ..engine.protocols import Correction, Epoch, Transition
from ..engine.status import ABSURD, OK
from ..errors import ArgumentError
from ..linalg import cholesky_lower
from ..measurements.base import warm_member_updates
from ._no_clone import NoCloneEstimator
from ._pf_kernels import CHUNKS, PARALLEL, SERIAL, pf_log_weights, pf_systematic
from pydantic import Field

from .facade import facade
from .registry import MOTIONS, GateOptions, register_estimator
from .ukf import predict_members
from .registry import ABSURD_SIGMA

__all__ = ["ParticleEstimator", "ParticleFilter", "systematic_resample", "normalise_log_weights",
           "check_particle_settings", "check_particle_memory", "linear_gaussian_particles", "particle_memory"]

_WARM: set = set()

#: the factor on the particles' spread about their mean after a degenerate epoch
DEGENERATE_INFLATION = 2.0


def check_particle_settings(particles, resample_threshold, roughening, substeps=4, absurd_sigma=ABSURD_SIGMA) -> None:
    """ArgumentError naming the key of a setting out of range."""
    if int(particles) != particles or particles < 2:
        raise ArgumentError(f"must be an integer >= 2, got {particles}", argument="particles")
    if not 0.0 < resample_threshold <= 1.0:
        raise ArgumentError(f"must be in (0, 1], got {resample_threshold}", argument="resample_threshold")
    if not 0.0 <= roughening < 1.0:
        raise ArgumentError(f"must be in [0, 1), got {roughening}", argument="roughening")
    if int(substeps) != substeps or substeps < 0:
        raise ArgumentError(f"must be an integer >= 0, got {substeps}", argument="substeps")
    if not absurd_sigma > 0:
        raise ArgumentError(f"must be positive, got {absurd_sigma}", argument="absurd_sigma")


#: arrays of particles x states a particle filter keeps at once (the particles, their next draw, the
#: noise draws, the fused update's state-major scratch), and the further numbers per particle (the
#: strapdown kernels' navigation, previous and sensor rows): :func:`particle_memory`
PARTICLE_STATE_COPIES = 4
PARTICLE_EXTRA = 28


def particle_memory(particles: int, states: int, copies: int = PARTICLE_STATE_COPIES) -> int:
    """Bytes of a particle cloud: ``particles x (copies x states + PARTICLE_EXTRA) x 8``."""
    return int(particles) * 8 * (int(copies) * int(states) + PARTICLE_EXTRA)


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (psutil when installed, else the free
    physical pages), or None when the system does not say."""
    try:
        import psutil
        return int(psutil.virtual_memory().available)
    except Exception:   # noqa: BLE001  not installed, or no answer on this system
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_particle_memory(particles: int, motion, copies: int = PARTICLE_STATE_COPIES) -> None:
    """ArgumentError naming ``particles`` when the cloud on ``motion``'s layout would not fit in the
    memory available (an "out of memory" deep in a run named no setting). No check without a
    motion model (its state count is not known yet) or when the system does not say."""
    layout = getattr(motion, "layout", None)
    if layout is None:
        return
    n = int(layout.n)
    need, avail = particle_memory(particles, n, copies), available_memory()
    if avail is not None and need > avail:
        raise ArgumentError(f"{int(particles)} particles of {n} states need about {need / 1e9:.3g} GB "
                            f"({int(particles)} x ({copies} x {n} + {PARTICLE_EXTRA}) x 8 bytes), more than the "
                            f"{avail / 1e9:.3g} GB of memory available", argument="particles")


def normalise_log_weights(logw: np.ndarray):
    """``(w, ess)``: the normalised weights of the log-weights ``logw`` and the effective
    sample size ``1 / sum w^2``; ``(None, 0.0)`` when no log-weight is finite."""
    finite = np.isfinite(logw)
    if not finite.any():
        return None, 0.0
    top = logw[finite].max()
    w = np.where(finite, np.exp(np.where(finite, logw, top) - top), 0.0)
    w /= w.sum()
    return w, float(1.0 / np.dot(w, w))


def systematic_resample(w: np.ndarray, u0: float) -> np.ndarray:
    """Indices of the systematic resampling of the weights ``w`` (N,) with the offset
    ``u0`` in [0, 1): particle ``i`` is drawn ``floor`` or ``ceil`` of ``N w_i`` times,
    ``N w_i`` on average over ``u0`` (unbiased)."""
    idx = np.empty(len(w), dtype=np.int64)
    pf_systematic(np.ascontiguousarray(w, dtype=float), float(u0), idx)   # the last bin closes at 1
    return idx


class ParticleEstimator(NoCloneEstimator):
    """The SIR particle filter's belief: N weighted error-state particles (module docstring).

    Parameters
    ----------
    particles : int
        Number of particles (>= 2).
    resample_threshold : float
        Resample when the effective sample size falls below this fraction of N, in (0, 1].
    roughening : float
        Roughening constant K (>= 0; 0: none) applied after each resampling.
    substeps : int
        Merged sub-intervals the particles are mechanized over per step (as the UKF's).
    absurd_sigma : float
        An epoch whose best particle's innovation exceeds this many sigmas per row is
        degenerate (counted, rejected).
    parallel : bool
        Run the per-particle kernels on numba's threads (``prange``; docs/particle.md,
        "Speed"). The particles are bitwise the same either way and on any thread
        count. Off by default: on a busy 2-core machine a parallel region waits for a
        descheduled thread; only used from the main thread (numba's threading layers
        do not all allow concurrent use).
    fused : bool
        Update with the model's fused kernel where it offers one (``member_update``; the
        loose model's ``pf_loose_update``: no full states, no ``predict_batch``; the generic
        path's numbers to round-off, tested). False: every epoch through ``predict_batch``
        (the reference, for tests and timing).
    """

    needs_step_inputs = True
    carry_mean = True

    label = "the particle filter"

    def __init__(self, particles: int = 1000, resample_threshold: float = 0.5, roughening: float = 0.9,
                 substeps: int = 4, absurd_sigma: float = ABSURD_SIGMA, parallel: bool = False, fused: bool = True):
        check_particle_settings(particles, resample_threshold, roughening, substeps, absurd_sigma)
        self.parallel = bool(parallel)
        self.fused = bool(fused)
        self._k = SERIAL
        self._sk = None   # the motion model's strapdown particle kernels (the strapdown INS only)
        self.N = int(particles)
        self.resample_threshold = float(resample_threshold)
        self.roughening = float(roughening)
        self.substeps = int(substeps)
        self.absurd_sigma = float(absurd_sigma)
        self.counts = {"pf_degenerate": 0, "pf_resampled": 0, "covariance_repair": 0, "pf_jitter_root": 0}
        self.ess_history: list = []

    # --- the estimator protocol --------------------------------------------------------------
    def init(self, motion, P0, n_clone, rng) -> None:
        self.refuse_clone(n_clone)
        lay = motion.layout
        n = lay.n
        self.n = n
        self.motion = motion
        # the strapdown INS: the fused compiled step and member updates; any other motion
        # model: its ensemble seam (propagate_members, member_states), the noise added after
        self.layout_array = lay.as_array() if lay.is_ins else None
        self._clk = lay.clk
        self.tau = np.asarray(motion.tau, dtype=float) if lay.is_ins else None
        self._sensor = np.zeros(12)   # the engine's sensor estimates, once a step has shown them
        self._eye = None if lay.is_ins else np.eye(n)
        self.rng = rng
        threads = self.parallel and threading.current_thread() is threading.main_thread()
        self._k = PARALLEL if threads else SERIAL
        self._threads = threads
        self._sk = motion.particle_kernels(threads) if lay.is_ins else None
        N = self.N
        self.D = np.ascontiguousarray(self.rng.standard_normal((N, n)) @ _sqrt_psd(np.asarray(P0, float)).T)
        self.logw = np.zeros(N)
        self.w = np.full(N, 1.0 / N)
        # every per-step array is allocated here once (O(N n)); steps swap buffers
        self._Dn = np.empty((N, n))
        self._Z = np.empty((N, n))
        self._no_seeds = np.zeros(CHUNKS, dtype=np.uint64)
        self._logw_new = np.empty(N)
        self._idx = np.empty(N, dtype=np.int64)
        self._w_new = np.empty(N)
        self._navs = np.empty((N + 1, 10))
        self._prevs = np.empty((N + 1, 6))
        self._sensors = np.empty((N + 1, 12))
        self._scr = np.empty((N + 1, self._sk.scratch)) if self._sk is not None else None
        self._g = np.empty((8, 7))        # merged sub-intervals: gth (0:3), gdv (3:6), gdt (6); grown on demand
        self._fdec = np.empty(4)
        self._part = np.empty((CHUNKS, n + n * n))
        self._pa = np.empty((CHUNKS, 2 + n))
        self._Yl = {}                                # a fused update's predictions, moments, sums, by m
        self._work = np.empty((n + 1, N))        # the fused update's state-major scratch
        self._L = np.zeros((n, n))
        self._scratch = np.zeros((n, n))
        self._Qd_last = None
        self._SQT = None
        self._x = np.empty(n)
        self._P = np.empty((n, n))
        self._stale = True
        self.counts = {"pf_degenerate": 0, "pf_resampled": 0, "covariance_repair": 0, "pf_jitter_root": 0}
        self.ess_history = []

    @property
    def kernel_covariance(self) -> np.ndarray:
        return self._scratch

    def predict(self, step: Transition) -> None:
        """All particles mechanized over the step's block with process noise (one compiled call)."""
        self._scratch[:, :] = 0.0
        inp = step.inputs
        if inp is None:
            raise ArgumentError("the particle filter needs the engine's step inputs (needs_step_inputs)",
                                argument="engine")
        self.propagate_linear_noise(None, step.Qd, inp, step.T)

    def propagate_linear_noise(self, F, Qd, inp=None, T=0.0) -> None:
        """``D <- f(D) + w``, ``w ~ N(0, Qd)`` from the estimator's stream: ``f`` the
        mechanization (``inp`` the step inputs) or, with ``F`` given, the linear map
        ``D F^T`` (tests on linear-Gaussian models)."""
        SQT = self._noise_root(Qd)
        if F is not None or self.layout_array is None:
            if F is None:   # another motion model: its members' propagation, then the noise step with F = I
                self._sensor = inp.sensor
                self.motion.propagate_members(inp, self.D, self.substeps, T, self._Dn)
                self.D, self._Dn = self._Dn, self.D
                FT = self._eye
            else:
                FT = np.ascontiguousarray(np.asarray(F, dtype=float).T)
            # the normals drawn in the kernel, one stream per chunk seeded from ours
            seeds = self.rng.integers(0, 2 ** 64, size=CHUNKS, dtype=np.uint64)
            self._k.linear_step_drawn(self.D, FT, SQT, seeds, self._Z, self._Dn)
        else:
            Z = self.rng.standard_normal(out=self._Z)
            K = len(inp.dt)
            S = K if self.substeps <= 0 or self.substeps >= K else self.substeps
            if S > len(self._g):
                self._g = np.empty((2 * S, 7))
            g = self._g
            self._sk.step(inp.nav0, inp.prev0, inp.sensor, self.D, SQT, Z, inp.dtheta, inp.dvel, inp.dt, self.substeps,
                          self.layout_array, self.tau, T, self._navs, self._prevs, self._sensors, self._scr,
                          g[:, 0:3], g[:, 3:6], g[:, 6], self._fdec, self._Dn)
        self.D, self._Dn = self._Dn, self.D
        self._stale = True

    def _noise_root(self, Qd) -> np.ndarray:
        """``SQ^T`` of ``Qd`` (symmetric square root), reused while ``Qd`` repeats exactly
        (a constant step and noise model: no eigendecomposition per step)."""
        Qd = np.asarray(Qd, dtype=float)
        if self._Qd_last is None or self._Qd_last.shape != Qd.shape or not np.array_equal(self._Qd_last, Qd):
            self._Qd_last = Qd.copy()
            self._SQT = np.ascontiguousarray(_sqrt_psd(Qd).T)
        return self._SQT

    def recentre(self, dx: np.ndarray) -> None:
        """The nominal moved by ``dx``: every particle's deviation shifts by ``-dx``; so
        does their mean (the covariance does not change: no recomputation)."""
        self.D -= dx[:self.n]
        if not self._stale:
            self._x -= dx[:self.n]

    def update(self, epoch: Epoch) -> Correction | None:
        navs = self._navs[:self.N]
        if self.layout_array is None:
            self.motion.member_states(epoch.nav, self._sensor, self.D, navs)
            out = predict_members(epoch, self.D, navs, self._clk, "the particle filter needs", self.motion)
        else:
            fused = self._member_update(epoch) if self.fused else None
            if fused is not None:
                return self._update_fused(epoch, fused)
            self._sk.member_navs(epoch.nav, self.D, self.layout_array, navs, self._sensors, self._scr)
            out = predict_members(epoch, self.D, navs, self._clk, "the particle filter needs")
        if out is None:
            return None
        y, Y, r = out
        return self.weigh(np.asarray(y, float), np.ascontiguousarray(Y, dtype=float), np.asarray(r, float))

    def _member_update(self, epoch: Epoch):
        """The epoch's model's fused member update (:class:`~mixnav.measurements.base.MemberUpdate`)
        for this filter's particles, or None (no such capability: the generic path)."""
        ask = getattr(epoch.model, "member_update", None)
        return None if ask is None else ask(epoch.index, self.motion.layout, self._threads)

    def _update_fused(self, epoch: Epoch, fused) -> Correction:
        """The update in the model's one fused kernel (``fused``, a ``MemberUpdate``):
        predictions, log-weights, NIS, weights, ESS, mean and covariance from the particle array."""
        m = fused.rows
        bufs = self._Yl.get(m)
        if bufs is None:    # allocated once per row count
            bufs = self._Yl[m] = (np.empty((m, self.N)), np.empty(m), np.empty((m, m)),
                                  np.empty((CHUNKS, 2 + m + m * m)))
        YT, ym, Pyy, yp = bufs
        logw, w = self._logw_new, self._w_new
        best, ess, nis = fused.kernel(self.D, epoch.nav, np.asarray(epoch.w_b, dtype=float), self.logw, self.w,
                                      m * self.absurd_sigma ** 2, YT, logw, w, ym, Pyy, self._x, self._P, yp,
                                      self._pa, self._part, self._work, *fused.constants)
        return self._weighed(best, ess, nis, m, logw, w, moments=False)

    def weigh(self, y: np.ndarray, Y: np.ndarray, r: np.ndarray) -> Correction:
        """The update from the particles' predictions ``Y`` (N, m) of ``y`` (m,) with noise
        variances ``r`` (m,): weights, degeneracy, mean, resampling (module docstring)."""
        m = len(y)
        # one pass: log-weights, normalisation, and the prior-weighted moments of Y for the
        # NIS (innovation of the weighted mean prediction, S = Cov_w(Y) + R)
        ym, Pyy = np.empty(m), np.empty((m, m))
        logw, w = self._logw_new, self._w_new
        best, ess, nis = pf_log_weights(self.logw, self.w, y, Y, r, logw, w, ym, Pyy)
        return self._weighed(best, ess, nis, m, logw, w, moments=True)

    def _weighed(self, best, ess, nis, m, logw, w, moments) -> Correction:
        """The rest of an update once the new log-weights ``logw`` and weights ``w`` are
        in the spare buffers: degeneracy, the buffers swapped, the moments (unless the
        fused kernel gave them), the correction, resampling."""
        if ess == 0.0 or not best <= m * self.absurd_sigma ** 2:
            self._degenerate()
            return Correction(np.zeros(self.n), np.inf, ABSURD, m)
        self._logw_new, self._w_new = self.logw, self.w
        self.logw, self.w = logw, w
        self.ess_history.append(ess)
        if moments:
            self._k.moments(self.D, w, self._x, self._P, self._part)
        dx = self._x.copy()
        self._stale = False
        if ess < self.resample_threshold * self.N:
            self._resample()
        return Correction(dx, nis, OK, m)

    def _resample(self) -> None:
        """Systematic resampling; with ``roughening = h > 0`` the kernel jitter of
        Liu & West (2001): ``D <- a D + (1 - a) x + h L z``, ``a = sqrt(1 - h^2)``, ``L L^T``
        the weighted covariance before the resampling, ``x`` the weighted mean: the
        particles are re-diversified in every direction while the mean and covariance
        are kept in expectation."""
        idx = self._idx
        pf_systematic(self.w, float(self.rng.random()), idx)
        h = self.roughening
        if h > 0.0:
            L = self._L
            if not cholesky_lower(self._P, L):
                # not numerically positive definite (a collapsed direction): a lower-
                # triangular root of its PSD part, R^T of the QR of the symmetric root
                self.counts["pf_jitter_root"] += 1
                L[:, :] = np.linalg.qr(_sqrt_psd(self._P).T, mode="r").T
            L *= h
            # the normals are drawn in the kernel, one stream per chunk seeded from ours
            seeds = self.rng.integers(0, 2 ** 64, size=CHUNKS, dtype=np.uint64)
        else:
            L, seeds = self._scratch, self._no_seeds
        ZT = self._Z.reshape((self.n, self.N))      # z_j: column j
        self._k.jitter_drawn(self.D, idx, float(np.sqrt(1.0 - h * h)), h, self._x, L, seeds, ZT, self._Dn)
        self.D, self._Dn = self._Dn, self.D
        self.logw[:] = 0.0
        self.w[:] = 1.0 / self.N
        self.counts["pf_resampled"] += 1
        # the estimate stays the weighted moments before the resampling (x, P): the
        # resampling and the jitter keep them in expectation and only add Monte Carlo
        # noise to the cloud's own (recomputing them would also cost a pass over it)
        self._stale = False

    def _degenerate(self) -> None:
        """Reset to uniform weights and inflate the spread about the mean (counted)."""
        self.counts["pf_degenerate"] += 1
        bad = ~np.isfinite(self.D).all(axis=1)
        if bad.all():   # pragma: no cover (the propagation keeps particles finite)
            self.D[:] = 0.0
        elif bad.any():  # pragma: no cover
            self.D[bad] = self.D[~bad][0]
        mean = self.D.mean(axis=0)
        self.D = mean + DEGENERATE_INFLATION * (self.D - mean)
        self.logw = np.zeros(self.N)
        self.w = np.full(self.N, 1.0 / self.N)
        self._stale = True

    def mean(self) -> np.ndarray:
        self._moments()
        return self._x

    def covariance(self) -> np.ndarray:
        self._moments()
        return self._P

    def _moments(self) -> None:
        if self._stale:
            self._k.moments(self.D, self.w, self._x, self._P, self._part)
            self._stale = False

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) the kernels once per process (the serial
        or the parallel set, as ``parallel`` asks)."""
        key = "pf-parallel" if self.parallel else "pf"
        if key in _WARM:
            return
        k = PARALLEL if self.parallel else SERIAL
        from ..ins.error_model import LAYOUTS
        from ..ins.strapdown import StrapdownMotion
        sk = StrapdownMotion.particle_kernels(self.parallel)
        lay = LAYOUTS[15]
        n, N = lay.n, 3
        nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.5, 0.5, 0.0])
        D = np.zeros((N, n))
        one = np.zeros((2, 3))
        g = np.empty((2, 7))
        scr = np.empty((N + 1, sk.scratch))
        navs, sensors = np.empty((N + 1, 10)), np.empty((N + 1, 12))
        sk.step(nav, np.zeros(6), np.zeros(12), D, np.eye(n), D.copy(), one, one, np.full(2, 0.01), 1,
                lay.as_array(), np.full(4, np.inf), 0.02, navs, np.empty((N + 1, 6)), sensors, scr,
                g[:, 0:3], g[:, 3:6], g[:, 6], np.empty(4), np.empty((N, n)))
        sk.member_navs(nav, D, lay.as_array(), navs, sensors, scr)
        w = np.full(N, 1.0 / N)
        pf_log_weights(np.zeros(N), w, np.zeros(3), np.zeros((N, 3)), np.ones(3), np.empty(N), np.empty(N),
                       np.empty(3), np.empty((3, 3)))
        pf_systematic(w, 0.5, np.empty(N, dtype=np.int64))
        k.moments(D, w, np.empty(n), np.empty((n, n)), np.empty((CHUNKS, n + n * n)))
        k.moments(np.zeros((N, 3)), w, np.empty(3), np.empty((3, 3)), np.empty((CHUNKS, n + n * n)))
        k.jitter_drawn(D, np.zeros(N, dtype=np.int64), 0.5, 0.5, np.zeros(n), np.eye(n), np.zeros(CHUNKS, np.uint64),
                       D.T.copy(), np.empty((N, n)))
        k.linear_step_drawn(D, np.eye(n), np.eye(n), np.zeros(CHUNKS, np.uint64), np.empty((N, n)), np.empty((N, n)))
        cholesky_lower(np.eye(n), np.empty((n, n)))
        warm_member_updates(lay, self.parallel)    # the fused updates the models offer (loose GNSS)
        _WARM.add(key)


def linear_gaussian_particles(P0, particles: int = 1000, rng=None, resample_threshold: float = 0.5,
                              roughening: float = 0.0, parallel: bool = False) -> ParticleEstimator:
    """The SIR particle filter on a linear-Gaussian model, without the engine.

    ``x_k = F x_{k-1} + w``, ``w ~ N(0, Q)``; ``y_k = H x_k + v``, ``v ~ N(0, diag(r))``.
    The estimator's particles ``D`` (N, n) are then the states themselves (the nominal
    is zero and never moves), drawn from ``N(0, P0)`` (P0 (n, n)) with ``rng`` (a numpy
    Generator or a seed). Per epoch::

        est.propagate_linear_noise(F, Q)          # D <- D F^T + w, w from est's stream
        corr = est.weigh(y, est.D @ H.T, r)       # weights, ESS, resampling, jitter
        x_hat = corr.dx                           # the weighted mean (before resampling)

    The same compiled weighting, resampling and propagation as on the strapdown INS
    (:class:`ParticleEstimator`), used by tests/test_particle.py and by the comparison
    with Stone Soup (benchmarks/bench_pf_stonesoup.py). ``roughening`` defaults to 0
    here (plain SIR)."""
    P0 = np.asarray(P0, dtype=float)
    if P0.ndim != 2 or P0.shape[0] != P0.shape[1]:
        raise ArgumentError(f"must be a square matrix, got shape {P0.shape}", argument="P0")
    n = P0.shape[0]
    layout = _LinearLayout(n)
    est = ParticleEstimator(particles=particles, resample_threshold=resample_threshold, roughening=roughening,
                            parallel=parallel)
    est.init(_LinearMotion(layout), P0, 0, np.random.default_rng(rng))
    return est


class _LinearLayout:
    """The minimal layout of a linear-Gaussian model: ``n`` states, no INS blocks."""

    clk = -1
    is_ins = False   # propagated by the linear map the caller gives, never by a motion model

    def __init__(self, n):
        self.n = n

    def as_array(self):
        return np.full(8, -1, dtype=np.int64)


class _LinearMotion:
    def __init__(self, layout):
        self.layout = layout
        self.tau = np.full(4, np.inf)


def _sqrt_psd(Q: np.ndarray) -> np.ndarray:
    """A symmetric square root ``S`` with ``S S^T = Q`` (negative eigenvalues floored at 0:
    ``Qd`` can be singular)."""
    lam, V = np.linalg.eigh(0.5 * (Q + Q.T))
    return (V * np.sqrt(np.maximum(lam, 0.0))) @ V.T


class ParticleOptions(GateOptions):
    """``[methods.options]`` of ``estimator = "pf"`` (docs/particle.md)."""

    particles: int = Field(default=1000, ge=2, description="number of particles")
    resample_threshold: float = Field(default=0.5, gt=0, le=1, description="effective-sample-size fraction "
                                      "below which the particles are resampled")
    roughening: float = Field(default=0.9, ge=0, lt=1, description="Liu-West jitter after a resampling "
                              "(0: none)")
    substeps: int = Field(default=4, ge=0, description="merged sub-intervals the particles are mechanized "
                          "over per step (0: every IMU increment)")
    parallel: bool = Field(default=False, description="per-particle kernels on numba's threads (the same "
                           "particles)")


def _build_pf(o: ParticleOptions, absurd_sigma: float, context):
    check_particle_memory(o.particles, context.motion)
    return ParticleEstimator(particles=o.particles, resample_threshold=o.resample_threshold,
                             roughening=o.roughening, substeps=o.substeps, parallel=o.parallel,
                             absurd_sigma=absurd_sigma)


#: every motion model: the ensemble runs on the motion seam (member_states, propagate_members, ...)
register_estimator("pf", options=ParticleOptions, motions=MOTIONS, can_smooth=False, build=_build_pf,
                   description="SIR particle filter (issue 19): particles as full states mechanized over each "
                   "IMU block, Gaussian log-weights, systematic resampling (options: particles, "
                   "resample_threshold, roughening, substeps, parallel)")(ParticleEstimator)

#: The SIR particle filter on the strapdown INS: ``ParticleFilter(layout, imu_model, particles=1000, ...)``.
ParticleFilter = facade("pf", "ParticleFilter")
