"""The coloured-noise Gaussian-mixture EKF, method M6 (paper P2).

P2 whitens, inside every component of the Gaussian-mixture EKF (M3,
:mod:`mixnav.filters.gmekf`), the coloured part of a non-Gaussian noise:

Coloured process noise, by state augmentation (P2 eqs. 6, 8-12). The
process noise of an epoch is ``W_k = Psi_w W_{k-1} + xi_k`` with ``xi_k`` the
process-noise mixture. Here ``W`` is the white IMU noise (ARW, VRW)
accumulated over the epoch, which lives on the attitude, velocity and
position errors (the first 9 error states; M3's ``Q_white``), and ``Psi_w``
is diagonal. Each component carries ``w`` (9,), the noise added at the last
epoch, beside its error state. At each epoch (where M3 splits into
process-noise children ``j`` or, without a measurement, folds the noise in)::

    w <- Psi_w w + xi,   x <- x + (Psi_w w + xi),   xi ~ N(0, c_j Q_white)

i.e. ``[x; w] <- A [x; w] + [xi; xi]`` with ``A = [[I, Psi_w], [0, Psi_w]]``.
That is P2 eq. (9) with the noise of an epoch entering the state at that
epoch (P2 lets it enter one epoch later, which only relabels ``W``). With
``Psi_w = 0`` it is M3's split exactly. ``w`` starts from its stationary
covariance ``Q / (1 - psi_i psi_j)``. Between epochs ``w`` is constant (the
engine treats it like a clone). The recursion steps once per covariance
event (with the standard 1 s grid and 1 Hz GNSS, once per epoch); a step of
length ``T`` uses ``psi^(T / process_interval)`` (:func:`ar_coefficient`).

Coloured measurement noise, by differencing (P2 eqs. 7, 13-20): the
measurement model is wrapped in
:class:`mixnav.measurements.differenced.DifferencedMeasurement`, which forms
``z_k - Psi z_{k-1}`` per channel and asks the engine for a stochastic clone
of the previous error state; the differenced rows carry the white mixture
``zeta`` of P2 eq. (7), rows without a previous value the stationary noise.

The update itself is M3's: every component, every row, the row's mixture
merged back in closed form, weights in log space, reduction each epoch (P2
eqs. 21-29). The augmented state of a component is ``[x (n), w (9),
clone (c)]``; the bank kernels treat everything past ``n`` as constant
during propagation. After an update the error state and the clone are fed
back and re-centred as in M3; ``w`` keeps its estimate (it predicts the
next epoch's noise).

With every coefficient zero M6 equals M3 (tested to 1e-10).
"""

from __future__ import annotations


import numpy as np
from numba import njit

from ..errors import ArgumentError, ConfigError
from ..measurements.kinds import MAX_KINDS, kind_code
from .facade import Filter
from .gmekf import BankEstimator, learn_bank_mixtures, mixtures_from_options
from .registry import ABSURD_SIGMA, register_variant

#: Error states the coloured process noise lives on (attitude, velocity, position).
N_W = 9


@njit(cache=True)
def colored_split(lw, X, P, Q, log_wj, cj, psi, n):
    """Children ``(c, j)`` of every component for each process-noise component ``j``
    with the AR(1) process-noise state ``w`` at ``n:n+9`` (module docstring)::

        X' = A X,   P' = A P A^T + c_j [[Q, Q], [Q, Q]],   A = [[I, Psi], [0, Psi]]

    ``Q`` (9, 9) the white noise of the step, ``psi`` (9,) the coefficients.
    """
    N, na = X.shape
    J = cj.shape[0]
    lw2 = np.empty(N * J)
    X2 = np.empty((N * J, na))
    P2 = np.empty((N * J, na, na))
    B = np.empty((na, na))
    AP = np.empty((na, na))
    xa = np.empty(na)
    for c in range(N):
        # A x and A P A^T, once per parent
        for i in range(na):
            xa[i] = X[c, i]
        for i in range(N_W):
            pw = psi[i] * X[c, n + i]
            xa[i] += pw
            xa[n + i] = pw
        for j in range(na):
            for i in range(na):
                B[i, j] = P[c, i, j]
        for i in range(N_W):          # rows: B = A P
            for j in range(na):
                pw = psi[i] * P[c, n + i, j]
                B[i, j] += pw
                B[n + i, j] = pw
        for i in range(na):           # columns: A P A^T = B A^T
            for j in range(na):
                AP[i, j] = B[i, j]
            for j in range(N_W):
                pw = psi[j] * B[i, n + j]
                AP[i, j] += pw
                AP[i, n + j] = pw
        for jj in range(J):
            o = c * J + jj
            lw2[o] = lw[c] + log_wj[jj]
            for i in range(na):
                X2[o, i] = xa[i]
            for i in range(na):
                for j in range(na):
                    P2[o, i, j] = AP[i, j]
            s = cj[jj]
            for i in range(N_W):
                for j in range(N_W):
                    q = s * Q[i, j]
                    P2[o, i, j] += q
                    P2[o, i, n + j] += q
                    P2[o, n + i, j] += q
                    P2[o, n + i, n + j] += q
    return lw2, X2, P2


def ar_coefficient(psi: np.ndarray, steps: float) -> np.ndarray:
    """The AR(1) coefficient over ``steps`` intervals: ``psi ** steps``, an integer power
    when ``steps`` is within 1e-6 of an integer (a negative ``psi`` alternates), else
    ``sign(psi) |psi| ** steps`` (a fractional step of a negative coefficient has no
    exact AR(1) meaning; this keeps its sign and the decay of its magnitude)."""
    k = round(steps)
    if abs(steps - k) < 1e-6:
        return psi ** k
    return np.sign(psi) * np.abs(psi) ** steps


_COLORED_WARM = []


class ColoredBankEstimator(BankEstimator):
    """The bank of :func:`ColoredMixtureEkf`: M3's bank with the AR(1)
    process-noise state ``w`` and the differencing clone (module docstring).

    Parameters
    ----------
    mixtures, max_components, absurd_sigma
        As :class:`~mixnav.filters.gmekf.BankEstimator`.
    psi_process : ndarray (9,)
        AR(1) coefficients of the process noise per ``process_interval``.
    process_interval : float
        [s]
    psi_measurement : ndarray (MAX_KINDS,)
        AR(1) coefficient of each kind code's measurement noise.
    augment : bool
        Carry the 9 process-noise states.
    **guards
        ``gate``, ``outlier_mean``, ``divergence_window``, ``divergence_nis`` (as the bank's).
    """

    def __init__(self, mixtures, max_components, absurd_sigma, psi_process, process_interval, psi_measurement,
                 augment=True, **guards):
        super().__init__(mixtures, max_components, absurd_sigma, **guards)
        self.nw = N_W if augment else 0     # 0: no process colour, M3's propagation and split
        self.psi_w = np.asarray(psi_process, dtype=float)
        self.process_interval = float(process_interval)
        self.psi_m = np.asarray(psi_measurement, dtype=float)

    def _kept_states(self) -> int:
        return self.nw

    def init(self, motion, P0, n_clone, rng):
        super().init(motion, P0, n_clone, rng)   # w at n:n+9 (kept as estimates), the clone after it
        self.T_acc = 0.0
        self.started = False
        if self.nw:  # the white part is always kept apart, for the AR(1) step of w
            self.white = bool(np.any(self.qc_white > 0))
            self.separate = True
        self.process_steps = 0             # AR(1) steps of w taken (not a recovery)

    def _tables_for(self, mixtures):
        """Kinds k (differenced, zeta) and their stationary twins k + MAX_KINDS
        (undifferenced, stationary noise: means grown by sqrt((1 + psi) / (1 - psi)))."""
        lw, mu, var = super()._tables_for(mixtures)
        grow = np.sqrt((1.0 + self.psi_m) / (1.0 - self.psi_m))[:, None]
        return np.vstack([lw, lw]), np.vstack([mu, mu * grow]), np.vstack([var, var])

    # --- hooks of the bank ----------------------------------------------------------------
    def predict(self, step):
        self.T_acc += step.T
        super().predict(step)

    def _fold(self):
        """No measurement: the children could never be told apart, one child of mean scale (exact)."""
        if not self.nw:
            return super()._fold()
        self._step(np.zeros(1), np.array([self.mean_scale]))

    def _split(self):
        if not self.nw:
            return super()._split()
        if self.split:
            self._step(self.proc_logw, self.proc_scale)
        else:
            self._step(np.zeros(1), np.array([self.one_scale]))

    def _step(self, log_wj, cj):
        """One AR(1) step of ``w`` with the accumulated white noise, split into children."""
        n = self.n
        Q = np.ascontiguousarray(self.Qw[:N_W, :N_W])
        psi = ar_coefficient(self.psi_w, self.T_acc / self.process_interval)
        if not self.started:  # w from its stationary covariance Q / (1 - psi_i psi_j)
            S = Q * self.mean_scale / (1.0 - np.outer(psi, psi))
            self.Pb[:, n:n + N_W, n:n + N_W] = S
            self.started = True
        self.lw, self.X, self.Pb = colored_split(self.lw, self.X, self.Pb, Q, log_wj, cj, psi, n)
        self.Qw[:, :] = 0.0
        self.Qw_pending = False
        self.T_acc = 0.0
        self.process_steps += 1
        self.largest_bank = max(self.largest_bank, len(self.lw))

    def warm_up(self) -> None:
        super().warm_up()
        if not _COLORED_WARM:
            na = N_W + 1 + N_W
            colored_split(np.zeros(1), np.zeros((1, na)), np.tile(np.eye(na), (1, 1, 1)), np.eye(N_W),
                          np.zeros(1), np.ones(1), np.zeros(N_W), N_W + 1)
            _COLORED_WARM.append(True)


#: The old name of :class:`ColoredBankEstimator`.
ColoredBankBelief = ColoredBankEstimator


def ColoredMixtureEkf(layout, imu_model, mixtures, psi_process=0.0, psi_measurement=None,
                      process_interval: float = 1.0, max_components: int = 16, covariance_interval: float = 1.0,
                      absurd_sigma: float = ABSURD_SIGMA, clock=None, learning_time_s: float = 0.0,
                      augment: bool | None = None, learner_not_converged: int = 0, gate: float = 2.0,
                      outlier_mean: float = 4.0, divergence_window: int = 10, divergence_nis: float = 9.0):
    """Coloured-noise Gaussian-mixture EKF, method M6 (paper P2).

    Parameters
    ----------
    layout, imu_model, mixtures, max_components, covariance_interval, absurd_sigma, clock, learning_time_s,
    gate, outlier_mean, divergence_window, divergence_nis
        As :func:`~mixnav.filters.gmekf.GaussianMixtureEkf`. The measurement
        mixtures are those of the white driving noise ``zeta`` (P2 eq. 7), the
        process mixture that of ``xi`` (P2 eq. 6).
    psi_process : float or array_like (9,)
        AR(1) coefficient of the epoch's process noise on the attitude,
        velocity and position errors per ``process_interval`` (P2's ``H``).
    psi_measurement : dict
        Observable kind -> AR(1) coefficient of its noise per epoch (P2's
        ``Psi``); the measurement models must be wrapped in
        :class:`~mixnav.measurements.differenced.DifferencedMeasurement` with
        the same coefficients (the experiment layer's method builder does).
    process_interval : float
        [s] The interval ``psi_process`` refers to (default 1 s).
    augment : bool, optional
        Carry the 9 process-noise states. Default: when a ``psi_process`` is
        non-zero (with all zero they cannot change the estimate, so leaving
        them out is exact and M6 then costs what M3 does); True forces them
        (the tests use it to check the zero-coefficient invariant).

    The :class:`~mixnav.filters.facade.Filter` of a :class:`ColoredBankEstimator` made fresh
    per run; it carries ``mixtures``, ``psi_process`` (9,), ``psi_measurement`` (by kind code),
    ``process_interval`` and ``augment``. Its AR(1) process-noise states are not in the
    history: the smoother does not apply.
    """
    guards = dict(gate=gate, outlier_mean=outlier_mean, divergence_window=divergence_window,
                  divergence_nis=divergence_nis)
    BankEstimator(mixtures, max_components, absurd_sigma, **guards)  # the bank's arguments named first
    psi_w = np.broadcast_to(np.asarray(psi_process, dtype=float), (N_W,)).copy()
    if not (np.all(np.isfinite(psi_w)) and np.all(np.abs(psi_w) < 1.0)):
        raise ArgumentError(f"AR(1) coefficient must satisfy |psi| < 1 (stationary), got {psi_process}",
                            argument="psi_process")
    if not process_interval > 0:
        raise ArgumentError(f"must be positive, got {process_interval}", argument="process_interval")
    psi_kinds = np.zeros(MAX_KINDS)
    for name, v in (psi_measurement or {}).items():
        psi_kinds[kind_code(name, argument=f"psi_measurement.{name}")] = v
    process_interval = float(process_interval)
    augment = bool(np.any(psi_w != 0.0)) if augment is None else bool(augment)
    max_components = int(max_components)

    def bank():
        return ColoredBankEstimator(mixtures, max_components, float(absurd_sigma), psi_w, process_interval,
                                    psi_kinds, augment, **guards)
    return Filter(bank, layout, imu_model, None, covariance_interval, absurd_sigma, clock, name="gaussian-mixture",
                  can_smooth=False, learning_time_s=learning_time_s, learner_not_converged=learner_not_converged,
                  attributes=dict(mixtures=mixtures, max_components=max_components, psi_process=psi_w,
                                  psi_measurement=psi_kinds, process_interval=process_interval, augment=augment))


def fit_coefficient(series: np.ndarray) -> float:
    """AR(1) coefficient of a training series (epochs, channels): the median of the
    per-channel least-squares fits (:func:`mixnav.noise.ar.fit_ar1`), clipped to
    ``|psi| <= 0.999`` so the filter's model stays stationary."""
    from ..noise.ar import fit_ar1
    fit = fit_ar1(np.asarray(series, dtype=float))
    return float(np.clip(np.median(fit.psi), -0.999, 0.999))


def colored_filter(options, context):
    """M6 from a method's ``[mixture]`` table with ``[mixture.colored]``: the coloured-noise
    mixture EKF and the method's measurement models differenced (the bank's build_filter,
    :mod:`mixnav.filters.gmekf`, hands it over).

    Coefficients given as ``"fit"`` are fitted to the training series; learned
    mixtures are learned from the training series *whitened* with the
    coefficients (``e_k - psi e_{k-1}``, the driving noise of P2 eqs. 6-7).
    """
    import time
    from ..measurements.differenced import DifferencedMeasurement
    from ..noise.ar import whiten_ar1
    mc, cc, source, method = options, options.colored, context.source, context.method
    prefix = context.entry_key
    key = f"{prefix}.mixture.colored"
    if mc.learn is not None and mc.learn.online is not None:
        raise ConfigError("online re-learning of the mixtures is not available with the coloured-noise "
                          "mixture EKF (M6)", file=source, key=f"{prefix}.mixture.learn.online")
    if getattr(method, "type", None) == "tdcp-ekf":
        raise ConfigError("the coloured-noise mixture EKF differences pseudoranges and range rates; TDCP "
                          "already differences the carrier: use type = \"tight-ekf\"", file=source,
                          key=f"{prefix}.type")
    series = (context.training or {}).get("series", {})

    def coefficient(v, kind, k):
        if v != "fit":
            return float(v)
        if kind not in series:
            raise ConfigError("'fit' needs a training stretch (simulated scenarios only)", file=source,
                              key=f"{key}.{k}")
        return fit_coefficient(series[kind])

    t_fit = time.perf_counter()
    psi_m = {k: coefficient(v, k, f"measurement.{k}") for k, v in cc.measurement.items()}
    psi_p = coefficient(cc.process, "process", "process")
    channels = {}
    for k, v in cc.channels.items():
        name, _, cid = k.partition(":")
        if name not in ("pseudorange", "range_rate", "position", "velocity") or not cid.isdigit():
            raise ConfigError(f"a channel is '<observable>:<id>' (e.g. 'pseudorange:12', the PRN), got '{k}'",
                              file=source, key=f"{key}.channels.{k}")
        channels[(name, int(cid))] = v
    learning_time = time.perf_counter() - t_fit  # the AR(1) fits count as learning
    if mc.learn is not None:
        if not series:
            raise ConfigError(f"method '{getattr(method, 'name', 'gaussian-mixture')}' learns its mixtures from "
                              "a training stretch, which only simulated scenarios provide", file=source,
                              key=f"{prefix}.mixture.learn")
        t0 = time.perf_counter()
        white = {k: np.ravel(whiten_ar1(series[k], psi_m.get(k, 0.0))[1:]) for k in mc.learn.observables
                 if k in series}
        if mc.learn.learn_process and "process" in series:
            white["process"] = np.ravel(whiten_ar1(series["process"], psi_p)[1:])
        missing = [k for k in mc.learn.observables if k not in white]
        if missing:
            raise ConfigError(f"the coloured-noise filter learns pseudorange and range-rate mixtures, not {missing}",
                              file=source, key=f"{prefix}.mixture.learn.observables")
        learned = learn_bank_mixtures(mc, white, seed=context.seed)
        mixtures, failed = learned.mixtures, learned.not_converged
        learning_time += time.perf_counter() - t0
    else:
        mixtures, failed = mixtures_from_options(mc), 0
    meas = list(context.measurements)
    if any(v != 0.0 for v in psi_m.values()) or channels:  # all white: nothing to difference (exact)
        meas = [DifferencedMeasurement(m, context.layout, psi_m, channels) for m in meas]
    filt = ColoredMixtureEkf(context.layout, context.imu_model, mixtures, psi_process=psi_p, psi_measurement=psi_m,
                             process_interval=cc.process_interval, max_components=mc.max_components,
                             learning_time_s=learning_time, learner_not_converged=failed, gate=mc.gate,
                             outlier_mean=mc.outlier_mean, divergence_window=mc.divergence_window,
                             divergence_nis=mc.divergence_nis, covariance_interval=context.covariance_interval,
                             clock=context.clock)
    return filt, meas


register_variant("gaussian-mixture", key="colored", build_filter=colored_filter)
