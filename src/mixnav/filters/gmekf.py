"""The Gaussian-mixture EKF (Gaussian sum filter), method M3 (P1 eqs. 5-9, P2 eqs. 21-29).

State prior, process noise and measurement noise are each Gaussian mixtures.
The filter carries a bank of error-state components about one shared nominal
INS solution (one mechanization, as in the EKF; the components differ in
their error-state mean and covariance), and each epoch:

1. propagates every component with the common ``Phi`` and ``Qd``; the white
   IMU noise (ARW, VRW) part of ``Qd`` is accumulated on its own, and at a
   measurement epoch each component splits into ``J`` children, one per
   process-noise component ``j`` (``P + c_j Q_white``, weight ``w_j``);
2. updates every child by every measurement row with the row's noise mixture
   (``L`` components), the ``L`` grandchildren merged straight back into
   their parent in closed form (:mod:`mixnav.filters._bank_kernels`), the
   weights multiplied by the innovation likelihoods in log space (P1 eqs.
   8-9);
3. reduces the bank to ``max_components`` by moment-preserving merges
   (Salmond's criterion), feeds the merged error estimate back into the INS,
   sensor and clock estimates and re-centres every component on it.

The bank is therefore ``I x J`` components before reduction (``I`` those
kept from the previous epoch, or the prior mixture at the start) and each
measurement row sees ``x L`` of them; with one-component mixtures it is the
EKF (tested to 1e-10 per update).

Noise mixtures are *standardised*: a measurement mixture
``sum pi_l N(mu_l, v_l)`` means noise ``sigma (mu_l + sqrt(v_l) N(0, 1))``
with ``sigma`` the measurement model's own sigma of that row, so one
mixture serves satellites of different sigmas; the process mixture scales
the IMU white-noise densities (``v_j ARW^2``, ``v_j VRW^2``; its means
must be zero, a non-zero mean being a bias the bias states carry); the prior
mixture scales the initial covariance.

M4 can also re-learn the measurement mixtures online from a sliding window
of the bank's standardised innovations (:mod:`mixnav.noise.learn.online`; the
hook is :meth:`BankBelief.epoch`).

When an event has no measurement (a GNSS outage), the accumulated white
noise is folded into every component with the mixture's mean scale
``sum w_j v_j``: without a measurement the children could never be told
apart, so merging them at once is exact.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.linalg import solve_triangular

from ..engine.protocols import Correction, Epoch, Transition
from ..errors import ArgumentError, ConfigError
from ..ins._error_kernels import covariance_predict, discrete_noise
from ..ins.error_model import ClockModel, StateLayout
from ..ins.imu_model import ImuErrorModel
from ..measurements.kinds import KINDS, MAX_KINDS, kind_code
from ..noise.learn.offline import learn_mixture  # noqa: F401  (re-exported)
from ..noise.mixture import BankMixtures, GaussianMixture, StandardMixture  # noqa: F401  (re-exported)
from ._bank_kernels import (bank_epoch_guarded, bank_log_likelihood, bank_moments,
                            bank_propagate, bank_reduce, bank_split, bank_update, predicted_nis)
from ._ekf_kernels import NEEDS_REPAIR, OK
from .ekf import repair_covariance
from .gmekf_options import MixtureOptions, MixtureSpec
from .facade import Filter
from .registry import BuildContext, register_estimator
from .registry import ABSURD_SIGMA


def independent_rows(z, r) -> tuple[np.ndarray, np.ndarray]:
    """``z`` contiguous and ``R`` as its diagonal; a bank updates row by row, so a
    full ``R`` with off-diagonal terms is refused."""
    z = np.ascontiguousarray(z, dtype=float)
    r = np.asarray(r, dtype=float)
    if r.ndim != 1:
        if np.any(r - np.diag(np.diag(r))):
            raise ArgumentError("the Gaussian-mixture EKF needs independent measurement rows (a diagonal R)", argument="R")
        r = np.diag(r).copy()
    return z, r


def _padded(tables):
    """The mixture tables with one row per possible kind code (``MAX_KINDS``), so a
    kind registered after the mixtures were built still indexes a row (Gaussian)."""
    lw, mu, var = tables
    k, L = lw.shape
    out = (np.full((MAX_KINDS, L), -np.inf), np.zeros((MAX_KINDS, L)), np.ones((MAX_KINDS, L)))
    out[0][:, 0] = 0.0  # unlisted kinds: N(0, 1) in standard units
    out[0][:k], out[1][:k], out[2][:k] = lw, mu, var
    return out


_BANK_WARM = []


# --- the bank built from a file's [mixture] table ----------------------------------------------------

def mixtures_from_options(options: MixtureOptions) -> BankMixtures:
    """The given (not learned) mixtures of a ``[mixture]`` table (Gaussian where not given)."""
    def standard(s: MixtureSpec) -> StandardMixture:
        return StandardMixture(tuple(s.weights), tuple(s.means or [0.0] * len(s.weights)), tuple(s.scales))
    return BankMixtures({k: standard(v) for k, v in options.measurement.items()},
                        standard(options.process) if options.process is not None else StandardMixture.gaussian(),
                        standard(options.prior) if options.prior is not None else StandardMixture.gaussian())


def learn_bank_mixtures(options: MixtureOptions, training: dict, seed: int):
    """The mixtures of ``options.learn`` from training residuals (given ones kept):
    :func:`mixnav.noise.learn.offline.learn_mixtures`."""
    from ..noise.learn.offline import learn_mixtures
    lc = options.learn
    return learn_mixtures(training, lc.observables, lc.method, mixtures_from_options(options),
                          n_components=lc.n_components, gibbs_samples=lc.gibbs_samples, prune=lc.prune,
                          training_samples=lc.training_samples, learn_process=lc.learn_process, seed=seed)


def bank_parts(options: MixtureOptions, training, seed: int, name: str, source, key: str):
    """A ``[mixture]`` table's bank: ``(mixtures, online settings or None, learning time [s],
    fits not converged)``, the mixtures given or learned offline from ``training``; ``name``
    and the table's file ``key`` for the error when there is no training stretch."""
    from ..noise.learn.online import OnlineSettings
    online = None
    if options.learn is not None and options.learn.online is not None:
        oc = options.learn.online
        online = OnlineSettings(tuple(options.learn.observables), window=oc.window, every=oc.every, gate=oc.gate,
                                n_components=options.learn.n_components, prune=options.learn.prune)
    if options.learn is not None and options.learn.offline:
        if training is None:
            raise ConfigError(f"'{name}' learns its mixtures from a training stretch, which only simulated "
                              "scenarios provide", file=source, key=f"{key}.learn")
        learned = learn_bank_mixtures(options, training, seed)
        return learned.mixtures, online, learned.learning_time_s, learned.not_converged
    return mixtures_from_options(options), online, 0.0, 0


def _guards(options: MixtureOptions) -> dict:
    return dict(gate=options.gate, outlier_mean=options.outlier_mean, divergence_window=options.divergence_window,
                divergence_nis=options.divergence_nis)


def _method_name(context: BuildContext) -> str:
    return getattr(context.method, "name", None) or "gaussian-mixture"


def _bank_estimator(options: MixtureOptions, absurd_sigma: float, context: BuildContext):
    """The registration's build: the bank on any motion model (not the coloured variant, which
    differences the measurements of an INS layout)."""
    key = context.entry_key
    if options.colored is not None:
        raise ConfigError("the coloured-noise bank (M6) differences measurements of an INS layout; not "
                          f"available on the {context.motion_name} model", file=context.source,
                          key=f"{key}.mixture.colored")
    mixtures, online, _, _ = bank_parts(options, context.training, context.seed, _method_name(context),
                                        context.source, f"{key}.mixture")
    return BankEstimator(mixtures=mixtures, max_components=options.max_components, online=online,
                         absurd_sigma=absurd_sigma, **_guards(options))


def _bank_filter(options: MixtureOptions, context: BuildContext):
    """The registration's build_filter: M3-M5 on the strapdown INS (mixtures learned once per
    method; M6, with a ``[mixture.colored]`` table, is the variant mixnav.filters.colored registers)."""
    mixtures, online, learning_time, failed = bank_parts(options, context.training, context.seed,
                                                         _method_name(context), context.source,
                                                         f"{context.entry_key}.mixture")
    filt = GaussianMixtureEkf(context.layout, context.imu_model, mixtures, max_components=options.max_components,
                              learning_time_s=learning_time, online=online, learner_not_converged=failed,
                              covariance_interval=context.covariance_interval, clock=context.clock,
                              **_guards(options))
    return filt, list(context.measurements)


def _bank_mode(options: MixtureOptions, absurd_sigma: float, context: BuildContext):
    """The registration's imm_child: fresh mean-carrying banks of one mixture set, learned once."""
    name = f"mode '{context.mode.name}' of '{_method_name(context)}'"
    mixtures, online, _, _ = bank_parts(options, context.training, context.seed, name, context.source,
                                        f"{context.entry_key}.mixture")
    return lambda: BankEstimator(mixtures, options.max_components, absurd_sigma, online=online, carry_mean=True,
                                 **_guards(options))


def _check_bank_entry(options: MixtureOptions, measurements, mode: bool) -> None:
    if mode and options.colored is not None:
        raise ValueError("a mode cannot be the coloured-noise bank (M6: it differences the measurements "
                         "and carries AR(1) states the other modes do not have)")


#: argument names of the bank's builders -> the method's file keys
BANK_KEYS = {"max_components": "mixture.max_components", "psi": "mixture.colored.measurement",
             "psi_channels": "mixture.colored.channels", "psi_process": "mixture.colored.process",
             "psi_measurement": "mixture.colored.measurement",
             "process_interval": "mixture.colored.process_interval", "kinds": "mixture.learn.observables",
             "mixtures": "mixture", "observables": "mixture.learn.observables", "process": "mixture.process",
             "prior": "mixture.prior", "window": "mixture.learn.online.window",
             "every": "mixture.learn.online.every", "gate": "mixture.learn.online.gate"}


@register_estimator("gaussian-mixture", options=MixtureOptions, table="mixture", build=_bank_estimator,
                    build_filter=_bank_filter, imm_child=_bank_mode, check=_check_bank_entry, keys=BANK_KEYS,
                    description="M3 Gaussian-mixture EKF (bank of components); M4/M5 when [mixture.learn] uses "
                    "vb/gibbs; M4 re-learned online with mixture.learn.online; M6 (coloured noise, paper P2, "
                    "strapdown only) with [mixture.colored]")
class BankEstimator:
    """The bank of Gaussian components about the one nominal INS state (method M3;
    the engine's estimator protocol, :mod:`mixnav.engine.protocols`).

    Parameters
    ----------
    mixtures : BankMixtures
        Prior, process-noise and measurement-noise mixtures.
    max_components : int
        The bank is reduced to at most this many components after each update.
    absurd_sigma : float
        Innovations beyond this many predicted sigmas reject the epoch (counted).
    online : mixnav.noise.learn.online.OnlineSettings, optional
        Re-learn these kinds' measurement mixtures online (M4 beyond the paper).
    carry_mean : bool
        Keep the bank's components about the nominal *before* the engine's feedback
        (their merged mean is the correction) and re-centre them in :meth:`recentre`:
        the form an IMM mode needs (:mod:`mixnav.filters.imm`), with :meth:`moments`,
        :meth:`set_moments` (the mixed moments imposed by an affine map of the whole
        bank, its shape kept) and :meth:`log_likelihood` (the bank's own mixture
        density of an epoch, not a Gaussian of its moments). Alone with the engine it
        gives the closed-loop bank's numbers.
    gate : float
        Convergence gate: a row whose state share of its predicted variance exceeds
        ``gate`` times its noise variance is updated with its mixture's moment-matched
        Gaussian, not the mixture (``inf``: never; :mod:`mixnav.filters._bank_kernels`).
    outlier_mean : float
        Noise components whose standardised mean exceeds this are outlier components:
        a row they explain is not used (rather than corrected by their mean; ``inf``: off).
    divergence_window, divergence_nis : int, float
        The divergence safeguard: when the merged prediction's NIS per row (each row's
        variance the state's share plus the model's own ``r``, the sigma the user gave)
        exceeds ``divergence_nis`` at ``divergence_window`` epochs in a row, the bank's
        state no longer agrees with what the measurements support: it is lost (gross
        errors met a state that was off and the mixture explained the rows away). Every
        component's error-state covariance then gets the run's initial covariance added
        back, so the next epochs re-acquire the state, counted ``bank_reset``.
        ``divergence_window = 0`` turns it off. Epochs of gross errors or multipath are
        what the mixture is there for; the window keeps them from firing it unless they
        persist (with biased epochs at random with probability p, a false reset needs p^W:
        3e-7 per epoch for P4's p = 0.3 and W = 10).
    """

    def __init__(self, mixtures: BankMixtures, max_components: int = 16, absurd_sigma: float = ABSURD_SIGMA,
                 online=None, carry_mean: bool = False, gate: float = 2.0, outlier_mean: float = 4.0,
                 divergence_window: int = 10, divergence_nis: float = 9.0):
        if int(max_components) < 1:
            raise ArgumentError(f"must be at least 1, got {max_components}", argument="max_components")
        if not (gate > 0):
            raise ArgumentError(f"must be positive, got {gate}", argument="gate")
        self.gate = float(gate)
        if not (outlier_mean > 0):
            raise ArgumentError(f"must be positive, got {outlier_mean}", argument="outlier_mean")
        self.outlier_mean = float(outlier_mean)
        if int(divergence_window) < 0:
            raise ArgumentError(f"must be >= 0 (0: off), got {divergence_window}", argument="divergence_window")
        if not (np.isfinite(divergence_nis) and divergence_nis > 0):
            raise ArgumentError(f"must be positive, got {divergence_nis}", argument="divergence_nis")
        self.divergence_window = int(divergence_window)
        self.divergence_nis = float(divergence_nis)
        self.carry_mean = bool(carry_mean)
        self.mixtures0 = mixtures
        self.max_components = int(max_components)
        self.absurd_sigma = float(absurd_sigma)
        self.online_settings = online
        self.online = None
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0}
        self.largest_bank = 0

    def _kept_states(self) -> int:
        """States between the error states and the clone, kept as estimates (M6's ``w``)."""
        return 0

    # --- the estimator protocol --------------------------------------------------------------
    def init(self, motion, P0, n_clone, rng):
        lay = motion.layout
        n = lay.n
        if getattr(motion, "qb", np.zeros(1)).any():
            raise ArgumentError("the mixture banks scale a diagonal white IMU noise; per-axis ARW/VRW "
                                "(different x, y, z values) are not supported here: give one value each",
                                argument="imu_model")
        qc_white = np.zeros(n)  # the white IMU noise (ARW, VRW) the process mixture scales
        if lay.is_ins:          # other motion models have no IMU white noise to scale
            qc_white[lay.att] = motion.qc[lay.att]
            qc_white[lay.vel] = motion.qc[lay.vel]
        mixtures = self.mixtures0
        nk = self._kept_states()
        if self.carry_mean and (nk or n_clone):
            raise ArgumentError("a mean-carrying bank (an IMM mode) carries no stochastic clone and no "
                                "coloured-noise states", argument="carry_mean")
        na = n + nk + n_clone
        self.n, self.na, self.nc = n, na, n_clone
        #: first index of the stochastic clone; states n:ic (M6's process-noise states)
        #: are kept as estimates after an update, not fed back into the nominal
        self.ic = n + nk
        self._scratch = np.zeros((n, n))  # for the propagation kernel (gives Phi and Qd)
        pr = mixtures.prior
        I = pr.n_components
        self.lw = np.log(np.asarray(pr.weights))
        self.X = np.zeros((I, na))
        self.Pb = np.zeros((I, na, na))
        for i, s in enumerate(pr.scales):
            self.Pb[i, :n, :n] = s * P0
        self.mixtures = mixtures
        self.tables = self._tables_for(mixtures)
        #: optional :class:`mixnav.noise.learn.online.OnlineMixtureLearner` (M4 online re-learning)
        self.online = None
        if self.online_settings is not None:
            codes = {k: kind_code(k, argument="online.kinds") for k in self.online_settings.kinds}
            self.online = self.online_settings.learner(mixtures, codes)
        self._u = np.empty(0)
        self._q = np.empty(0)
        proc = mixtures.process
        self.split = proc.n_components > 1
        self.proc_logw = np.log(np.asarray(proc.weights))
        self.proc_scale = np.asarray(proc.scales)
        self.one_scale = proc.scales[0] if not self.split else 1.0
        self.mean_scale = proc.mean_scale
        self.qc_white = qc_white
        self.white = np.any(qc_white > 0) and (self.split or self.one_scale != 1.0)
        #: keep the white part apart until the next split (else scale it into Qd at once)
        self.separate = self.split
        self.Qw = np.zeros((n, n))
        self.Qw_pending = False
        self._qdw = np.empty((n, n))
        self._tmp = np.empty((n, n))
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0, "bank_reset": 0}
        self.largest_bank = I
        self.P0 = np.array(P0, dtype=float)
        self._high = 0            # consecutive epochs the bank did not explain (divergence safeguard)
        self.have_clone = False
        self.rng = rng

    @property
    def kernel_covariance(self) -> np.ndarray:
        """A zeroed scratch: the kernel's step leaves this step's ``Phi`` and ``Qd`` in the work array."""
        return self._scratch

    def predict(self, step: Transition) -> None:
        F, phi, qd, T, measured = step.F, step.Phi, step.Qd, step.T, step.measured
        self._scratch[:, :] = 0.0
        if not self.white:
            bank_propagate(self.X, self.Pb, phi, qd, self.n)
            return
        discrete_noise(F, self.qc_white, T, self._qdw)
        if not self.separate:  # one process component with its own scale
            bank_propagate(self.X, self.Pb, phi, qd + (self.one_scale - 1.0) * self._qdw, self.n)
            return
        bank_propagate(self.X, self.Pb, phi, qd - self._qdw, self.n)
        covariance_predict(self.Qw, phi, self._qdw, self._tmp)  # the white part since the last split
        self.Qw_pending = True
        if not measured:  # nothing can tell the children apart: merge them now (exact)
            self._fold()

    def _fold(self):
        n = self.n
        self.Pb[:, :n, :n] += self.mean_scale * self.Qw
        self.Qw[:, :] = 0.0
        self.Qw_pending = False

    def _split(self):
        """Children of every component for each process-noise component (the white
        noise accumulated since the last split)."""
        self.lw, self.X, self.Pb = bank_split(self.lw, self.X, self.Pb, self.Qw, self.proc_logw,
                                              self.proc_scale)
        self.Qw[:, :] = 0.0
        self.Qw_pending = False
        self.largest_bank = max(self.largest_bank, len(self.lw))

    def update(self, epoch: Epoch) -> Correction | None:
        rows = epoch.rows()
        if rows is None:
            return None
        n, na, ic = self.n, self.na, self.ic
        z, r = independent_rows(rows.z, rows.R)
        H = rows.H
        if H.shape[1] != na:  # the model's columns: error states, then its clone (at ic)
            Ha = np.zeros((len(z), na))
            Ha[:, :n] = H[:, :n]
            Ha[:, ic:ic + H.shape[1] - n] = H[:, n:]
            H = Ha
        if self.Qw_pending:
            self._split()
        kinds = np.asarray(rows.kinds, dtype=np.int64)
        if self.divergence_window and self._diverged(z, H, r, kinds):
            self._reset()
        status, nis, lw, X, Pb, dx = self.epoch(z, H, r, kinds)
        if status in (OK, NEEDS_REPAIR):
            X[:, n:ic] += dx[n:ic]  # kept states are estimates, not errors of the nominal: undo the re-centring
            if self.carry_mean:     # about the nominal before feedback: the IMM re-centres on its own dx
                X += dx
            self.lw, self.X, self.Pb = lw, X, Pb
            if self.have_clone:
                return Correction(np.concatenate([dx[:n], dx[ic:]]), nis, status, len(z))
        return Correction(dx[:n], nis, status, len(z))

    def _diverged(self, z, H, r, kinds) -> bool:
        """The divergence test (class docstring) on this epoch's rows, before its update."""
        _, xm, Pm = bank_moments(self.lw, self.X, self.Pb)
        nis, _ = predicted_nis(xm, Pm, z, H, r)
        self._high = self._high + 1 if nis > self.divergence_nis * len(z) else 0
        return self._high >= self.divergence_window

    def _reset(self) -> None:
        """The state is lost: the run's initial covariance added back to every component's
        error states (their means and weights kept), so the next rows re-acquire it."""
        n = self.n
        self.Pb[:, :n, :n] += self.P0
        self._high = 0
        self.counts["bank_reset"] += 1

    # --- the mean-carrying form (an IMM mode) ---------------------------------------------------
    def recentre(self, dx: np.ndarray) -> None:
        """The nominal moved by ``dx`` (fed back by the engine or the IMM): every component's
        mean ``-= dx``."""
        self.X[:, :self.n] -= dx[:self.n]

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """The bank's merged error-state mean (n,) and covariance (n, n) (with the white
        process noise held apart until the next split, :meth:`covariance`)."""
        _, xm, _ = bank_moments(self.lw, self.X, self.Pb)
        return xm[:self.n].copy(), self.covariance()

    def set_moments(self, x0: np.ndarray, P0: np.ndarray) -> None:
        """Give the bank the merged mean ``x0`` and covariance ``P0`` (an IMM's mixing),
        keeping its shape: with ``m``, ``Pm`` the current moments, ``L0``, ``Lm`` Cholesky
        factors and ``A = L0 Lm^-1``, every component goes to ``x0 + A (x_c - m)``,
        ``A P_c A^T`` (and the white noise held for the next split to ``A Q_w A^T``). An
        affine map of a mixture moves its moments exactly so (``A Pm A^T = P0``) and keeps
        every covariance positive definite. When either factorisation fails the bank
        collapses to the one Gaussian ``(x0, P0)``, counted ``mode_collapsed``."""
        n = self.n
        xm, Pm = self.moments()
        if np.array_equal(xm, x0) and np.array_equal(Pm, P0):
            return
        try:
            Lm = np.linalg.cholesky(Pm)
            L0 = np.linalg.cholesky(P0)
        except np.linalg.LinAlgError:
            self.lw = np.zeros(1)
            self.X = np.array(x0, dtype=float).reshape(1, n)
            self.Pb = np.array(P0, dtype=float).reshape(1, n, n)
            self.Qw[:, :] = 0.0
            self.Qw_pending = False
            self.counts["mode_collapsed"] = self.counts.get("mode_collapsed", 0) + 1
            return
        A = L0 @ solve_triangular(Lm, np.eye(n), lower=True)
        self.X = np.ascontiguousarray(x0 + (self.X - xm) @ A.T)
        self.Pb = np.ascontiguousarray(A @ self.Pb @ A.T)
        if self.Qw_pending:
            self.Qw = A @ self.Qw @ A.T

    def log_likelihood(self, rows) -> float:
        """``log p(z)`` of an epoch's rows under the bank's own predictive mixture: every
        component (split by the pending process-noise mixture) and every row's noise
        mixture, rows in sequence (``p(z) = prod_i p(z_i | z_<i)``, the normaliser of the
        bank's update). Nothing in the bank changes; -inf when a variance is not positive."""
        z, r = independent_rows(rows.z, rows.R)
        lw, X, Pb = self.lw, self.X, self.Pb
        if self.Qw_pending:
            lw, X, Pb = bank_split(lw, X, Pb, self.Qw, self.proc_logw, self.proc_scale)
        kinds = np.asarray(rows.kinds, dtype=np.int64)
        return bank_log_likelihood(lw, X, Pb, z, rows.H, r, kinds, *self.tables)   # rows in C order: Epoch.rows

    def epoch(self, z, H, r, kinds):
        """The bank's measurement epoch in one compiled call, ``(status, nis, lw, X, P, dx)``
        of :func:`~mixnav.filters._bank_kernels.bank_epoch_guarded` (the bank itself unchanged).

        With online learning the collecting variant also returns each row's
        standardised innovation and prediction share, which go to the learner;
        a refit replaces the mixture tables used from the next epoch on. A
        subclass that writes its own ``update`` calls this to keep both.
        """
        args = (self.lw, self.X, self.Pb, z, H, r, kinds, *self.tables, self.absurd_sigma,
                self.max_components, self.n)
        m = len(z)
        collect = self.online is not None
        if collect and len(self._u) < m:
            self._u, self._q = np.empty(2 * m), np.empty(2 * m)
        out = bank_epoch_guarded(*args, self.gate, self.outlier_mean, collect, self._u, self._q)
        if not collect:
            return out
        if self.online.observe(out[0] in (OK, NEEDS_REPAIR), kinds, self._u[:m], self._q[:m]):
            self.mixtures = replace(self.mixtures, measurement={**self.mixtures.measurement,
                                                                **self.online.current})
            self.tables = self._tables_for(self.mixtures)
        return out

    def _tables_for(self, mixtures):
        for k in mixtures.measurement:  # an unknown kind is an error, not an unused row
            kind_code(k, argument=f"mixtures.measurement.{k}")
        return _padded(mixtures.tables(KINDS))

    def replace_clone(self, J):
        n, ic = self.n, self.ic
        A = self.Pb[:, :ic, :n] @ J.T                 # Cov(states before the clone, x) J^T
        self.X[:, ic:] = self.X[:, :n] @ J.T
        self.Pb[:, :ic, ic:] = A
        self.Pb[:, ic:, :ic] = np.swapaxes(A, 1, 2)
        self.Pb[:, ic:, ic:] = J @ A[:, :n]
        self.have_clone = True

    def repair(self):
        n = self.n
        for c in np.nonzero(np.any(np.diagonal(self.Pb, axis1=1, axis2=2)[:, :n] <= 0.0, axis=1))[0]:
            Pc = np.ascontiguousarray(self.Pb[c])
            repair_covariance(Pc)
            self.Pb[c] = Pc
        self.counts["covariance_repair"] += 1

    def covariance(self):
        """The bank's merged covariance of the error states (n, n), including the white
        process noise held apart until the next split (``mean_scale * Qw``: the moments of
        its mixture), so that after a measured step it is the predicted covariance
        ``Phi P Phi^T + Qd`` (what the engine's history records as ``P_pred``)."""
        _, _, Pm = bank_moments(self.lw, self.X, self.Pb)
        P = np.ascontiguousarray(Pm[:self.n, :self.n])
        if self.Qw_pending and not getattr(self, "nw", 0):  # M6 drives its noise through w instead
            P += self.mean_scale * self.Qw
        return P

    def diagnostics(self) -> dict:
        out = {"bank_components_max": float(self.largest_bank)}
        if self.online is not None:
            out.update(self.online.timing())
        return out

    def warm_up(self) -> None:
        """Compile (or load from the numba cache) the bank kernels once per process,
        outside the timed loop."""
        if self.online_settings is not None:
            from ..noise.learn.online import OnlineMixtureLearner
            OnlineMixtureLearner.warm_up()
        if _BANK_WARM:
            return
        n, na = 3, 4
        lw, X, P = np.zeros(2), np.zeros((2, na)), np.tile(np.eye(na), (2, 1, 1))
        phi, Q = np.eye(n), np.eye(n)
        bank_propagate(X, P, phi, Q, n)
        lw, X, P = bank_split(lw, X, P, Q, np.log([0.5, 0.5]), np.ones(2))
        w, xm, Pm = bank_moments(lw, X, P)
        H = np.ones((1, na))
        predicted_nis(xm, Pm, np.zeros(1), H, np.ones(1))
        bank_update(lw, X, P, np.zeros(1), H, np.ones(1), np.zeros(1, dtype=np.int64), np.zeros((1, 1)),
                    np.zeros((1, 1)), np.ones((1, 1)))
        bank_reduce(lw, X, P, 1, n)
        bank_log_likelihood(lw, X, P, np.zeros(1), H, np.ones(1), np.zeros(1, dtype=np.int64), np.zeros((1, 1)),
                            np.zeros((1, 1)), np.ones((1, 1)))
        for collect in (False, True):
            bank_epoch_guarded(lw, X, P, np.zeros(1), H, np.ones(1), np.zeros(1, dtype=np.int64), np.zeros((1, 1)),
                               np.zeros((1, 1)), np.ones((1, 1)), 1e4, 1, n, 2.0, 4.0, collect, np.empty(1),
                               np.empty(1))
        _BANK_WARM.append(True)


#: The old name of :class:`BankEstimator`.
BankBelief = BankEstimator


def GaussianMixtureEkf(layout: StateLayout, imu_model: ImuErrorModel, mixtures: BankMixtures,
                       max_components: int = 16, covariance_interval: float = 1.0, absurd_sigma: float = ABSURD_SIGMA,
                       clock: ClockModel | None = None, learning_time_s: float = 0.0, online=None,
                       learner_not_converged: int = 0, gate: float = 2.0, outlier_mean: float = 4.0,
                       divergence_window: int = 10, divergence_nis: float = 9.0):
    """Gaussian-mixture (Gaussian sum) closed-loop error-state EKF, method M3: the
    :class:`~mixnav.filters.facade.Filter` of a :class:`BankEstimator` made fresh per run.

    Parameters
    ----------
    layout, imu_model, covariance_interval, absurd_sigma, clock
        As :class:`~mixnav.filters.ekf.ErrorStateEkf`.
    mixtures : BankMixtures
        Prior, process-noise and measurement-noise mixtures.
    max_components : int
        The bank is reduced to at most this many components after each
        update (default 16).
    learning_time_s : float
        Time spent learning the mixtures (reported beside the filter's own
        timing; M4/M5 learn them offline).
    online : mixnav.noise.learn.online.OnlineSettings, optional
        Re-learn these kinds' measurement mixtures online from a sliding window
        of innovations (M4 beyond the paper; :mod:`mixnav.noise.learn.online`),
        starting from ``mixtures``. Every run starts again from ``mixtures``.
    learner_not_converged : int
        Offline mixture fits that did not converge (reported in ``recoveries``).
    gate, outlier_mean, divergence_window, divergence_nis
        The update's guards and the divergence safeguard, as :class:`BankEstimator`
        (``gate = outlier_mean = inf``, ``divergence_window = 0``: P1's plain update).

    The filter carries ``mixtures``, ``max_components``, ``online`` and, after a run,
    ``online_learner`` (that run's learner, or None). The RTS smoother applies on the
    bank's merged Gaussian (an approximation, docs/smoother.md).
    """
    guards = dict(gate=gate, outlier_mean=outlier_mean, divergence_window=divergence_window,
                  divergence_nis=divergence_nis)
    max_components = int(max_components)

    def bank():
        return BankEstimator(mixtures, max_components, float(absurd_sigma), online, **guards)
    return Filter(bank, layout, imu_model, None, covariance_interval, absurd_sigma, clock, name="gaussian-mixture",
                  can_smooth=True, learning_time_s=learning_time_s, learner_not_converged=learner_not_converged,
                  attributes=dict(mixtures=mixtures, max_components=max_components, online=online))


