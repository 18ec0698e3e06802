"""Interacting multiple models over the INS error state (method M9, paper P4 eqs. 6-16).

An :class:`ImmEstimator` holds ``r`` mode-conditioned estimators (children that carry
their own error-state mean, ``KalmanEstimator(carry_mean=True)`` or a subclass such as
the robust EKF) about the one nominal INS. Each mode has its own measurement set: the
models whose epochs update it. At every measurement epoch of a model in any set:

1. **Mixing** (eqs. 6-9): with the Markov transition matrix ``Pi`` for the time since
   the last cycle, ``c_j = sum_i Pi_ij mu_i``, ``mu_{i|j} = Pi_ij mu_i / c_j``, and each
   mode restarts from ``x0_j = sum_i mu_{i|j} x_i``,
   ``P0_j = sum_i mu_{i|j} (P_i + (x_i - x0_j)(x_i - x0_j)^T)``. The modes share one
   transition ``Phi``, ``Qd`` (one motion model), so mixing the predicted moments at the
   epoch equals mixing the previous posteriors and predicting them (exact, linear).
2. **Likelihoods** (eq. 13), made comparable across measurement sets: every mode scores
   *the same rows* -- the epoch's -- with its own predictive density
   ``N(z; H x_j, H P_j H^T + R)``, whether or not the epoch's model is in its set. The
   set decides only who is updated. P4 scores each sub-filter on its own measurement
   (GNSS metres against odometer metres per second), whose densities are not comparable:
   their ratio changes with the units. Here a mode that ignores the GNSS is judged by how
   well its own belief, grown without the GNSS, predicts the GNSS fix; a mode that
   ignores the odometer, by how well it predicts the odometer.
3. **Mode-matched updates** (eqs. 10-12) of the modes whose set holds the model.
4. **Probabilities** (eq. 14): ``mu_j ∝ Lambda_j c_j``; **combination** (eqs. 15-16):
   ``x = sum_j mu_j x_j`` is the correction the engine feeds back once, every mode is
   re-centred on it, and ``P = sum_j mu_j (P_j + (x_j - x)(x_j - x)^T)`` is recorded.

``Pi`` is given per ``transition_interval`` seconds (default 1 s: "the probability of
being in mode j one second after mode i") and raised to the fractional power ``dt / T``
for the time ``dt`` since the previous cycle, so the switching rate does not depend on
how many epochs (odometer at 125 Hz, GNSS at 1 Hz) a second holds. That needs real,
non-negative eigenvalues (a "sticky" matrix, ``Pi_ii >= 1/2`` for two modes);
``transition_interval=None`` applies ``Pi`` once per epoch instead (P4's form).

A mode may be a Gaussian-mixture bank (``BankEstimator(carry_mean=True)``,
:mod:`mixnav.filters.gmekf`). It mixes through its merged moments: mixing gives it the
mean and covariance ``x0_j``, ``P0_j`` and it takes them by one affine map of all its
components (``x_c -> x0 + A (x_c - m)``, ``P_c -> A P_c A^T``, ``A = L0 Lm^-1``), which
moves a mixture's first two moments exactly and keeps its shape. It is scored by its own
predictive density of the rows (components x noise mixtures), not a Gaussian of its
moments: a mode whose noise model has a multipath tail is judged with that tail.

Model probabilities are outputs: ``result.outputs["mode_probabilities"]`` (K, r) at the
cycle times ``result.outputs["mode_times"]``.
"""

from __future__ import annotations

import math

import numpy as np

from ..engine.protocols import Correction, Epoch, Transition
from ._imm_kernels import imm_combine, imm_epoch, imm_mix_score, imm_predict, imm_probabilities
from ..errors import ArgumentError, ConfigError
from ..ins.error_model import ClockModel, StateLayout
from ..ins.imu_model import ImuErrorModel
from ..markov import check_transition
from .ekf import KalmanEstimator
from .facade import Filter
from .imm_options import ImmOptions, check_imm_entry
from .registry import BuildContext, entry_options, estimator_spec, register_estimator
from ..engine.status import ABSURD, NEEDS_REPAIR, NON_FINITE, OK
from .registry import ABSURD_SIGMA

_LOG_2PI = math.log(2.0 * math.pi)
#: the recoveries an IMM counts itself (per mode for the rejections)
_COUNTS = ("rejected_not_pd", "rejected_absurd", "covariance_repair", "imm_no_likelihood")


class _FractionalPower:
    """``Pi ** s`` for real ``s >= 0`` through the eigen-decomposition, cached per ``s``."""

    def __init__(self, P: np.ndarray, argument: str):
        lam, V = np.linalg.eig(P)
        if np.max(np.abs(lam.imag)) > 1e-12 or np.min(lam.real) < -1e-12:
            raise ArgumentError("has complex or negative eigenvalues, so it is not the one-interval "
                                "matrix of a switching that goes on in time (make the diagonal larger, "
                                "e.g. >= 0.5 for two modes, or apply it per epoch with "
                                "transition_interval = None)", argument=argument)
        self.lam = np.clip(lam.real, 0.0, None)
        self.V = V.real
        self.Vi = np.linalg.inv(self.V)
        self._cache: dict = {}

    def __call__(self, s: float) -> np.ndarray:
        key = int(s * 1e9 + 0.5)       # nanosecond resolution
        out = self._cache.get(key)
        if out is None:
            out = (self.V * self.lam ** s) @ self.Vi
            out = np.clip(out, 0.0, None)
            out /= out.sum(axis=1, keepdims=True)      # round-off only
            if len(self._cache) < 4096:
                self._cache[key] = out
        return out


def mix(mu: np.ndarray, Pi: np.ndarray, xs: np.ndarray, Ps: np.ndarray):
    """IMM mixing (P4 eqs. 6-9).

    Parameters
    ----------
    mu : (r,) mode probabilities; Pi : (r, r) transition, ``Pi[i, j] = p(j | i)``;
    xs : (r, n) mode means; Ps : (r, n, n) mode covariances.

    Returns
    -------
    c : (r,) predicted mode probabilities ``sum_i Pi_ij mu_i``;
    x0 : (r, n), P0 : (r, n, n) the mixed starting moments of each mode.
    """
    c = mu @ Pi
    w = Pi * mu[:, None]                       # w[i, j] = Pi_ij mu_i
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(c > 0, w / c, 0.0)        # mu_{i|j}; a mode predicted impossible keeps zeros
    x0 = w.T @ xs
    P0 = np.einsum("ij,ikl->jkl", w, Ps)
    for j in range(len(mu)):
        if c[j] <= 0:     # mode j cannot be entered: it keeps its moments (they carry no weight)
            x0[j], P0[j] = xs[j], Ps[j]
            continue
        d = xs - x0[j]
        P0[j] += (w[:, j, None] * d).T @ d
    return c, x0, P0


def combine(mu: np.ndarray, xs: np.ndarray, Ps: np.ndarray):
    """The combined mean and covariance (P4 eqs. 15-16): ``(x (n,), P (n, n))``."""
    x = mu @ xs
    d = xs - x
    P = np.einsum("j,jkl->kl", mu, Ps) + (mu[:, None] * d).T @ d
    return x, P


def log_likelihood(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray) -> float:
    """``log N(z; H x, H P H^T + R)`` (``R`` (m,) variances or (m, m)); -inf when ``S`` is
    not positive definite."""
    y = z - H @ x
    S = H @ P @ H.T
    if R.ndim == 1:
        S[np.diag_indices_from(S)] += R
    else:
        S = S + R
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        return -np.inf
    w = np.linalg.solve(L, y)
    return float(-0.5 * (w @ w + 2.0 * np.log(np.diag(L)).sum() + len(z) * _LOG_2PI))


def mode_factories(options: ImmOptions, context: BuildContext) -> list:
    """One factory of fresh mean-carrying estimators per mode of ``options``, each asked of the
    mode estimator's registration (its ``imm_child`` hook) with the mode's entry, measurement
    models and file key in the context; a bad argument is a ConfigError under the mode's key."""
    from dataclasses import replace
    makers = []
    for k, mode in enumerate(options.modes):
        key, spec = f"{context.entry_key}.imm.modes[{k}]", None
        try:
            spec = estimator_spec(mode.estimator)
            child = replace(context, key=key, mode=mode,
                            measurements=[context.named_measurements[x] for x in mode.measurements])
            makers.append(spec.mode_factory(entry_options(mode, spec), child))
        except ArgumentError as exc:
            where = exc.argument or ""
            if where != "estimator" and spec is not None and spec.table is not None:
                where = f"{spec.table}.{where}" if where else spec.table
            raise ConfigError(exc.message, file=context.source, key=f"{key}.{where}" if where else key) from None
    return makers


def _imm_parts(options: ImmOptions, context: BuildContext):
    sets = [[context.named_measurements[x] for x in mode.measurements] for mode in options.modes]
    interval = None if options.transition_interval == "epoch" else float(options.transition_interval)
    return sets, interval, [m.name for m in options.modes], mode_factories(options, context)


def _imm_filter(options: ImmOptions, context: BuildContext):
    """The registration's build_filter (M9): the IMM of the method's modes, each updated by the
    measurements it lists, the modes' settings learned once per method."""
    sets, interval, names, makers = _imm_parts(options, context)
    try:
        filt = ImmEkf(context.layout, context.imu_model, sets, options.transition, options.initial_probabilities,
                      interval, names, makers, output=options.output, covariance_interval=context.covariance_interval,
                      clock=context.clock)
    except ArgumentError as exc:   # under the method's [imm] table
        key = f"{context.entry_key}.imm" + (f".{exc.argument}" if exc.argument else "")
        raise ConfigError(exc.message, file=context.source, key=key) from None
    return filt, list(context.measurements)


def _imm_estimator(options: ImmOptions, absurd_sigma: float, context: BuildContext):
    sets, interval, names, makers = _imm_parts(options, context)
    return ImmEstimator([make() for make in makers], sets, options.transition, options.initial_probabilities,
                        interval, names, options.output)


@register_estimator("imm", options=ImmOptions, table="imm", motions=("strapdown",), can_smooth=False,
                    build=_imm_estimator, build_filter=_imm_filter, check=check_imm_entry,
                    description="M9 interacting multiple models (paper P4): modes of any registered mode estimator "
                    "(ekf, robust-adaptive, em-bias, gaussian-mixture, ...) with their own measurement sets "
                    "([methods.imm])")
class ImmEstimator:
    """Interacting multiple models of mode-conditioned error-state estimators (module docstring).

    Parameters
    ----------
    children : list of estimators, r >= 1
        Each with ``carry_mean = True`` (``KalmanEstimator(carry_mean=True)``, the robust
        EKF with ``carry_mean=True``, ``BankEstimator(carry_mean=True)``...): they predict
        their own ``x`` and ``P`` (a bank: ``moments()``, ``set_moments()``).
    measurement_sets : list of r collections of measurement models
        The models that update each mode (the same objects given to the engine); none
        may be empty. An epoch of a model in no set is ignored.
    transition : (r, r) array
        ``transition[i][j]``: probability of mode j one ``transition_interval`` after mode
        i (rows sum to one).
    initial_probabilities : (r,) array, optional
        Default: uniform.
    transition_interval : float or None
        Seconds per application of ``transition`` (default 1 s); None: once per epoch.
    names : list of str, optional
        Mode names for the outputs.
    output : ``"combined"`` or ``"most-probable"``
        What is fed back and recorded: the combination of the modes (P4 eqs. 15-16,
        default), or the most probable mode's mean and covariance. The combination
        blends in modes that do not fit (on clean GNSS, a mode without it), which costs
        accuracy; the most probable mode is what a user who wants one model at a time
        expects. Every mode is re-centred on what is fed back either way.
    """

    carry_mean = False   # the composite re-centres its children itself

    def __init__(self, children, measurement_sets, transition, initial_probabilities=None,
                 transition_interval: float | None = 1.0, names=None, output: str = "combined"):
        if output not in ("combined", "most-probable"):
            raise ArgumentError(f"must be 'combined' or 'most-probable', got {output!r}", argument="output")
        self.output = output
        children = list(children)
        r = len(children)
        if r < 1:
            raise ArgumentError("needs at least one mode", argument="children")
        for k, c in enumerate(children):
            if not getattr(c, "carry_mean", False) or not hasattr(c, "recentre"):
                raise ArgumentError(f"mode {k} does not carry its own mean: use "
                                    "KalmanEstimator(carry_mean=True) or a subclass, or "
                                    "BankEstimator(carry_mean=True)", argument="children")
        sets = [frozenset(s) for s in measurement_sets]
        if len(sets) != r:
            raise ArgumentError(f"one set per mode: {r} modes, {len(sets)} sets", argument="measurement_sets")
        for k, s in enumerate(sets):
            if not s:
                raise ArgumentError(f"mode {k} has no measurements: it could never be told apart from "
                                    "pure inertial navigation", argument="measurement_sets")
        self.children = children
        self.sets = sets
        self.Pi = check_transition(transition, r)
        mu0 = np.full(r, 1.0 / r) if initial_probabilities is None else np.asarray(initial_probabilities, float)
        if mu0.shape != (r,) or np.any(mu0 < 0) or not np.all(np.isfinite(mu0)) or abs(mu0.sum() - 1) > 1e-9:
            raise ArgumentError(f"must be {r} non-negative probabilities summing to 1, got {mu0}",
                                argument="initial_probabilities")
        self.mu0 = mu0
        if transition_interval is not None:
            if not (np.isfinite(transition_interval) and transition_interval > 0):
                raise ArgumentError(f"must be a positive time [s] or None, got {transition_interval!r}",
                                    argument="transition_interval")
            self._power = _FractionalPower(self.Pi, "transition")
        else:
            self._power = None
        self.transition_interval = transition_interval
        self.names = list(names) if names is not None else [f"mode{k}" for k in range(r)]
        if len(self.names) != r:
            raise ArgumentError(f"one name per mode: {r} modes, {len(self.names)} names", argument="names")
        self.counts = dict.fromkeys(_COUNTS, 0)

    # --- the estimator protocol ---------------------------------------------------------------
    def init(self, motion, P0: np.ndarray, n_clone: int, rng: np.random.Generator) -> None:
        if n_clone:
            raise ArgumentError("the IMM does not carry a stochastic clone (TDCP with clone)",
                                argument="measurements")
        for c in self.children:
            c.init(motion, P0, 0, rng)
        self.n = motion.layout.n
        self._scratch = np.zeros((self.n, self.n))
        self.mu = self.mu0.copy()
        r, n = len(self.children), self.n
        self._xs, self._x0 = np.empty((r, n)), np.empty((r, n))
        self._Ps, self._P0 = np.empty((r, n, n)), np.empty((r, n, n))
        self._logl = np.empty(r)
        self._P = np.empty((n, n))
        self._mu_new = np.empty(r)
        self._user_cache: dict = {}
        self._adjusting = [j for j, c in enumerate(self.children) if hasattr(c, "adjusted_rows")]
        # modes with more than one Gaussian (a mixture bank): their moments through
        # moments()/set_moments(), their score from their own predictive density
        self._shaped = [j for j, c in enumerate(self.children) if hasattr(c, "set_moments")]
        self._scoring = [j for j, c in enumerate(self.children) if hasattr(c, "log_likelihood")]
        # every mode a plain Kalman filter: the modes' moments live in the stacked _xs, _Ps (the
        # children's x and P are views of them) and one compiled call predicts them all, one
        # runs the epoch up to the probabilities (tested equal to the general path)
        self._fast = all(type(c) is KalmanEstimator for c in self.children)
        if self._fast:
            self._views = [(self._xs[j], self._Ps[j]) for j in range(r)]
            self._sync()
            self._users_arr: dict = {}
            self._status = np.empty(r, dtype=np.int64)
            self._nis = np.empty(r)
            self._tmp = np.empty((n, n))
            self._absurd = min(c.absurd_sigma for c in self.children)
            if len({c.absurd_sigma for c in self.children}) > 1:
                self._fast = False     # one gate per call: modes with different gates go the long way
        self._t_last = None
        self._times: list = []
        self._mus: list = []
        self.counts = dict.fromkeys(_COUNTS, 0)   # a fresh run (the modes' own join in outputs())

    @property
    def kernel_covariance(self) -> np.ndarray:
        """A zeroed scratch: each mode propagates its own covariance in :meth:`predict`."""
        return self._scratch

    def predict(self, step: Transition) -> None:
        self._scratch[:, :] = 0.0
        if self._fast:
            self._sync()
            imm_predict(self._xs, self._Ps, step.Phi, step.Qd, self._tmp)
            return
        for c in self.children:
            c.predict(step)

    def _transition(self, t: float) -> np.ndarray:
        if self._power is None:
            return self.Pi
        if self._t_last is None:
            return np.eye(len(self.mu))   # the first cycle: mu0 is the probability at that time
        return self._power(max(t - self._t_last, 0.0) / self.transition_interval)

    def _users(self, model) -> tuple:
        """Which modes the model updates (a tuple of bools, cached per model)."""
        u = self._user_cache.get(id(model))
        if u is None:
            u = self._user_cache[id(model)] = tuple(model in s for s in self.sets)
        return u

    def update(self, epoch: Epoch) -> Correction | None:
        users = self._users(epoch.model)
        if not any(users):
            return None
        rows = epoch.rows()
        if rows is None:
            return None
        z, H, R = rows.z, rows.H, np.asarray(rows.R, dtype=float)
        if H.shape[1] != self.n:
            raise ArgumentError("the IMM does not carry a stochastic clone", argument="measurements")
        ch = self.children
        m = len(z)
        if self._fast:
            return self._update_fast(epoch, users, z, H, R)
        # 1. mixing and 2. every mode scoring the epoch's rows with its own predictive
        #    density, in one compiled call (mix and log_likelihood are the numpy reference)
        Pi = self._transition(epoch.time)
        xs, Ps, x0, P0, logl = self._xs, self._Ps, self._x0, self._P0, self._logl
        self._gather()
        cbar = imm_mix_score(self.mu, Pi, xs, Ps, z, H, np.diag(R) if R.ndim == 1 else R, x0, P0, logl)
        shaped = self._shaped
        for j, c in enumerate(ch):
            if shaped and j in shaped:
                c.set_moments(x0[j], P0[j])
            else:
                c.x = x0[j].copy()
                c.P = P0[j].copy()
        logl = logl.copy()
        for j in self._scoring:      # a mixture mode: its own density of the rows, not a Gaussian's
            logl[j] = ch[j].log_likelihood(rows)
        for j in self._adjusting:
            # a mode that changes the rows (the EM-IMM's bias removal) is scored on its rows;
            # one that gated them out (calls them outliers) on the raw rows
            if users[j]:
                c = ch[j]
                rj = c.adjusted_rows(epoch)
                if rj is not None and rj is not rows and len(rj.z) == m:
                    logl[j] = log_likelihood(c.x, c.P, rj.z, rj.H, np.asarray(rj.R, dtype=float))
        logl = self.weigh(logl)
        # 3. mode-matched updates (a child's rejection is counted here; the IMM's own
        #    correction is the combination, fed back unless every updating mode rejected)
        applied = [False] * len(ch)
        corrs = [None] * len(ch)
        for j, c in enumerate(ch):
            if users[j]:
                corr = c.update(epoch)
                if corr is None:       # the mode kept all the rows out (a gate): not updated
                    continue
                corrs[j] = corr
                st = corr.status
                if st == OK or st == NEEDS_REPAIR:
                    applied[j] = True
                    if st == NEEDS_REPAIR:
                        c.repair()
                        self.counts["covariance_repair"] += 1
                elif st == NON_FINITE:
                    return corr
                else:
                    self.counts["rejected_absurd" if st == ABSURD else "rejected_not_pd"] += 1
        any_applied = any(applied)
        if not any_applied and any(c is not None for c in corrs):
            self._log(epoch.time, cbar)
            worst = next(c for c in corrs if c is not None)
            # the engine counts this epoch's rejection once; the per-mode counts above are per mode
            self.counts["rejected_absurd" if worst.status == ABSURD else "rejected_not_pd"] -= 1
            return worst
        # 4. probabilities and combination
        mu = self._mu_new
        if not imm_probabilities(logl, cbar, mu):
            self.counts["imm_no_likelihood"] += 1
        self._log(epoch.time, mu)
        if not any_applied:
            # every updating mode kept the rows out (a gate): nothing to feed back; the modes
            # keep their mixed means, whose combination the next correction carries
            return None
        shaped = self._shaped
        for j, c in enumerate(ch):
            xs[j] = c.moments()[0] if shaped and j in shaped else c.x
        dx = mu @ xs if self.output == "combined" else xs[int(np.argmax(mu))].copy()
        for c in ch:
            c.recentre(dx)
        best = max((j for j in range(len(ch)) if applied[j]), key=lambda j: mu[j])  # NIS of the likeliest
        return Correction(dx, corrs[best].nis, OK, m)

    def _sync(self) -> None:
        """Fast path: a mode whose ``x`` or ``P`` was replaced from outside (a user setting a
        mode's state) is copied into the stacks and given its views back."""
        for c, (xv, Pv) in zip(self.children, self._views):
            if c.x is not xv:
                xv[:] = c.x
                c.x = xv
            if c.P is not Pv:
                Pv[:, :] = c.P
                c.P = Pv

    def _update_fast(self, epoch: Epoch, users: tuple, z, H, R) -> Correction | None:
        """:meth:`update` for plain Kalman modes: the same steps, the mixing, scoring and
        mode updates in one compiled call (:func:`~mixnav.filters._imm_kernels.imm_epoch`)."""
        self._sync()
        ua = self._users_arr.get(users)
        if ua is None:
            ua = self._users_arr[users] = np.array(users, dtype=np.bool_)
        xs, Ps, status, nis = self._xs, self._Ps, self._status, self._nis
        cbar = imm_epoch(self.mu, self._transition(epoch.time), xs, Ps, z, H, R, ua, self._absurd,
                         self._x0, self._P0, self._logl, status, nis)
        logl = self.weigh(self._logl.copy())
        applied, best, worst = False, -1, -1
        counts = self.counts
        for j, st in enumerate(status):
            if st < 0:
                continue
            if st == OK or st == NEEDS_REPAIR:
                applied = True
                if st == NEEDS_REPAIR:
                    self.children[j].repair()
                    counts["covariance_repair"] += 1
            elif st == NON_FINITE:
                return Correction(np.zeros(self.n), np.inf, NON_FINITE, len(z))
            else:
                counts["rejected_absurd" if st == ABSURD else "rejected_not_pd"] += 1
                if worst < 0:
                    worst = j
        if not applied:
            self._log(epoch.time, cbar)
            st = int(status[worst])
            counts["rejected_absurd" if st == ABSURD else "rejected_not_pd"] -= 1   # the engine counts it
            return Correction(np.zeros(self.n), np.inf, st, len(z))
        mu = self._mu_new
        if not imm_probabilities(logl, cbar, mu):
            counts["imm_no_likelihood"] += 1
        self._log(epoch.time, mu)
        dx = mu @ xs if self.output == "combined" else xs[int(np.argmax(mu))].copy()
        xs -= dx
        for j in range(len(mu)):
            if (status[j] == OK or status[j] == NEEDS_REPAIR) and (best < 0 or mu[j] > mu[best]):
                best = j
        return Correction(dx, float(nis[best]), OK, len(z))

    def _log(self, t: float, mu: np.ndarray) -> None:
        self.mu = mu.copy()
        self._t_last = t
        self._times.append(t)
        self._mus.append(self.mu)

    def weigh(self, logl: np.ndarray) -> np.ndarray:
        """The modes' log-likelihoods of this epoch (r,), ``log N(z; H x_j, H P_j H^T + R)``
        after mixing; a subclass may change them (the tests force one mode's to zero)."""
        return logl

    def _gather(self) -> None:
        """Every mode's mean and covariance into ``_xs``, ``_Ps`` (already there on the fast path)."""
        if self._fast:
            return
        xs, Ps, shaped = self._xs, self._Ps, self._shaped
        for j, c in enumerate(self.children):
            if shaped and j in shaped:
                xs[j], Ps[j] = c.moments()
            else:
                xs[j] = c.x
                Ps[j] = c.P

    def covariance(self) -> np.ndarray:
        """The combined covariance (eq. 16) of the current modes, or with ``output =
        "most-probable"`` that mode's own."""
        self._gather()
        if self.output == "combined":
            imm_combine(self.mu, self._xs, self._Ps, self._P)
        else:
            self._P[:, :] = self._Ps[int(np.argmax(self.mu))]
        return self._P

    def replace_clone(self, J: np.ndarray) -> None:
        raise ArgumentError("the IMM does not carry a stochastic clone", argument="measurements")

    def repair(self) -> None:
        for c in self.children:
            c.repair()
        self.counts["covariance_repair"] += 1

    def diagnostics(self) -> dict:
        return {}

    def outputs(self) -> dict:
        """Mode probabilities at the cycle times: ``mode_times`` (K,) [s],
        ``mode_probabilities`` (K, r), ``mode_initial`` (r,) before the first cycle,
        ``mode_names``; and the modes' own outputs (an EM-IMM's ``bias_times``, ``bias``)."""
        r = len(self.children)
        out = {}
        for name, c in zip(self.names, self.children):   # the modes' own counts (the EM's fits)
            for k, v in c.counts.items():
                if k not in _COUNTS:
                    self.counts[f"{name}:{k}"] = v
        for name, c in zip(self.names, self.children):   # the modes' own (the EM-IMM's bias)
            for k, v in (c.outputs() if hasattr(c, "outputs") else {}).items():
                out[k if k not in out else f"{name}:{k}"] = v
        out.update({"mode_times": np.array(self._times, dtype=float),
                    "mode_probabilities": np.array(self._mus, dtype=float).reshape(-1, r),
                    "mode_initial": self.mu0.copy(), "mode_names": list(self.names)})
        return out

    def warm_up(self) -> None:
        for c in self.children:
            c.warm_up()
        n = 15
        H = np.zeros((3, n))
        H[:, 6:9] = np.eye(3)
        imm_mix_score(np.array([0.5, 0.5]), np.eye(2), np.zeros((2, n)), np.tile(np.eye(n), (2, 1, 1)),
                      np.zeros(3), H, np.eye(3), np.empty((2, n)), np.empty((2, n, n)), np.empty(2))
        imm_combine(np.array([0.5, 0.5]), np.zeros((2, n)), np.tile(np.eye(n), (2, 1, 1)), np.empty((n, n)))
        imm_probabilities(np.zeros(2), np.array([0.5, 0.5]), np.empty(2))


def ImmEkf(layout: StateLayout, imu_model: ImuErrorModel, measurement_sets, transition,
           initial_probabilities=None, transition_interval: float | None = 1.0, names=None,
           mode_estimators=None, covariance_interval: float = 1.0, absurd_sigma: float = ABSURD_SIGMA,
           clock: ClockModel | None = None, output: str = "combined"):
    """The IMM as a filter a user runs (method M9): the
    :class:`~mixnav.filters.facade.Filter` of an :class:`ImmEstimator` of EKF (or robust EKF)
    modes, made fresh per run.

    Parameters
    ----------
    layout, imu_model, covariance_interval, absurd_sigma, clock
        As :class:`~mixnav.filters.ekf.ErrorStateEkf`.
    measurement_sets : list of r collections of measurement models
        The models that update each mode (pass the same objects to :meth:`run`).
    transition, initial_probabilities, transition_interval, names, output
        As :class:`ImmEstimator`.
    mode_estimators : list of r callables, optional
        Each returns a fresh mean-carrying estimator for its mode (default:
        ``KalmanEstimator(absurd_sigma, carry_mean=True)``).

    The filter carries ``measurement_sets`` and ``mode_estimators``. A mixture of modes:
    the RTS smoother (one Gaussian per event) does not apply.
    """
    measurement_sets = [frozenset(s) for s in measurement_sets]
    if mode_estimators is None:
        mode_estimators = [lambda: KalmanEstimator(float(absurd_sigma), carry_mean=True)] * len(measurement_sets)
    mode_estimators = list(mode_estimators)
    settings = dict(transition=transition, initial_probabilities=initial_probabilities,
                    transition_interval=transition_interval, names=names, output=output)

    def imm() -> ImmEstimator:
        return ImmEstimator([make() for make in mode_estimators], measurement_sets, **settings)
    return Filter(imm, layout, imu_model, None, covariance_interval, absurd_sigma, clock, name="imm",
                  can_smooth=False, attributes=dict(measurement_sets=measurement_sets,
                                                    mode_estimators=mode_estimators))
