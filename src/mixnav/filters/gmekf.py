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
of the bank's standardised innovations (:mod:`mixnav.filters.online`; the
hook is :meth:`BankBelief.epoch`).

When an event has no measurement (a GNSS outage), the accumulated white
noise is folded into every component with the mixture's mean scale
``sum w_j v_j``: without a measurement the children could never be told
apart, so merging them at once is exact.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..engine.protocols import Correction, Epoch, Transition
from ..errors import ArgumentError, ConfigError
from ..ins._error_kernels import covariance_predict, discrete_noise
from ..ins.error_model import ClockModel, StateLayout
from ..ins.imu_model import ImuErrorModel
from ..measurements.kinds import KINDS, MAX_KINDS
from ..noise.mixture import GaussianMixture
from ._bank_kernels import (bank_epoch, bank_epoch_collect, bank_moments, bank_propagate, bank_reduce, bank_split,
                            bank_update, predicted_nis)
from ._ekf_kernels import NEEDS_REPAIR, OK
from .ekf import ErrorStateEkf, repair_covariance


@dataclass(frozen=True)
class StandardMixture:
    """A 1-D mixture of a standardised noise: weights, means, variance scales."""

    weights: tuple
    means: tuple
    scales: tuple

    def __post_init__(self):
        w, mu, v = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (self.weights, self.means, self.scales))
        if not (w.shape == mu.shape == v.shape) or w.ndim != 1 or len(w) == 0:
            raise ConfigError(f"weights, means and scales need one entry per component, got "
                              f"{len(w)}, {len(mu)}, {len(v)}", key="weights")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(mu)) and np.all(np.isfinite(v))):
            raise ConfigError("weights, means and scales must be finite", key="weights")
        if np.any(w < 0) or abs(w.sum() - 1.0) > 1e-6:
            raise ConfigError(f"weights must be non-negative and sum to 1, got {w.tolist()}", key="weights")
        if np.any(v <= 0):
            raise ConfigError(f"variance scales must be positive, got {v.tolist()}", key="scales")
        object.__setattr__(self, "weights", tuple(w / w.sum()))
        object.__setattr__(self, "means", tuple(mu))
        object.__setattr__(self, "scales", tuple(v))

    @classmethod
    def gaussian(cls) -> "StandardMixture":
        return cls((1.0,), (0.0,), (1.0,))

    @classmethod
    def from_mixture(cls, gm: GaussianMixture, sigma: float = 1.0) -> "StandardMixture":
        """From a fitted 1-D :class:`GaussianMixture` of residuals in units of ``sigma``."""
        if gm.dim != 1:
            raise ConfigError(f"a noise mixture must be one-dimensional, got d = {gm.dim}")
        return cls(tuple(gm.weights), tuple(gm.means[:, 0] / sigma), tuple(gm.covariances[:, 0, 0] / sigma ** 2))

    @property
    def n_components(self) -> int:
        return len(self.weights)

    @property
    def mean_scale(self) -> float:
        return float(np.dot(self.weights, self.scales))

    def variance(self) -> float:
        w, mu, v = map(np.asarray, (self.weights, self.means, self.scales))
        m = w @ mu
        return float(w @ (v + mu ** 2) - m ** 2)


@dataclass(frozen=True)
class BankMixtures:
    """The three mixtures of a Gaussian-mixture EKF.

    ``measurement`` maps an observable kind (``"pseudorange"``, ``"tdcp"``,
    ``"range_rate"``, ``"position"``, ``"velocity"``; see
    :mod:`mixnav.measurements.kinds`) to its standardised noise mixture;
    kinds not listed are Gaussian with the model's sigma.
    """

    measurement: dict = field(default_factory=dict)
    process: StandardMixture = field(default_factory=StandardMixture.gaussian)
    prior: StandardMixture = field(default_factory=StandardMixture.gaussian)

    def __post_init__(self):
        for k in self.measurement:
            if k not in KINDS:
                raise ConfigError(f"unknown observable '{k}' (known: {', '.join(KINDS)})",
                                  key=f"mixture.measurement.{k}")
        if any(m != 0.0 for m in self.process.means):
            raise ConfigError("process-noise mixture means must be zero", key="mixture.process.means")
        if any(m != 0.0 for m in self.prior.means):
            raise ConfigError("prior mixture means must be zero", key="mixture.prior.means")

    def tables(self):
        """``(log_w, mu, var)``, each (n_kinds, L_max), rows in kind-code order."""
        L = max([m.n_components for m in self.measurement.values()] + [1])
        nk = len(KINDS)
        lw = np.full((nk, L), -np.inf)
        mu = np.zeros((nk, L))
        var = np.ones((nk, L))
        for name, code in KINDS.items():
            m = self.measurement.get(name, StandardMixture.gaussian())
            k = m.n_components
            with np.errstate(divide="ignore"):
                lw[code, :k] = np.log(m.weights)
            mu[code, :k] = m.means
            var[code, :k] = m.scales
        return lw, mu, var


def independent_rows(z, r) -> tuple[np.ndarray, np.ndarray]:
    """``z`` contiguous and ``R`` as its diagonal; a bank updates row by row, so a
    full ``R`` with off-diagonal terms is refused."""
    z = np.ascontiguousarray(z, dtype=float)
    r = np.asarray(r, dtype=float)
    if r.ndim != 1:
        if np.any(r - np.diag(np.diag(r))):
            raise ConfigError("the Gaussian-mixture EKF needs independent measurement rows (a diagonal R)")
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
    online : mixnav.filters.online.OnlineSettings, optional
        Re-learn these kinds' measurement mixtures online (M4 beyond the paper).
    """

    def __init__(self, mixtures: BankMixtures, max_components: int = 16, absurd_sigma: float = 1e4,
                 online=None):
        if int(max_components) < 1:
            raise ArgumentError(f"must be at least 1, got {max_components}", argument="max_components")
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
        qc_white = np.zeros(n)  # the white IMU noise (ARW, VRW) the process mixture scales
        qc_white[lay.att] = motion.qc[lay.att]
        qc_white[lay.vel] = motion.qc[lay.vel]
        mixtures = self.mixtures0
        nk = self._kept_states()
        na = n + nk + n_clone
        self.n, self.na, self.nc = n, na, n_clone
        #: first index of the stochastic clone; states n:ic (M6's process-noise states)
        #: are kept as estimates after an update, not fed back into the nominal
        self.ic = n + nk
        self.P = np.zeros((n, n))  # scratch for the propagation kernel (gives Phi and Qd)
        pr = mixtures.prior
        I = pr.n_components
        self.lw = np.log(np.asarray(pr.weights))
        self.X = np.zeros((I, na))
        self.Pb = np.zeros((I, na, na))
        for i, s in enumerate(pr.scales):
            self.Pb[i, :n, :n] = s * P0
        self.mixtures = mixtures
        self.tables = self._tables_for(mixtures)
        #: optional :class:`mixnav.filters.online.OnlineMixtureLearner` (M4 online re-learning)
        self.online = None if self.online_settings is None else self.online_settings.learner(mixtures)
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
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0}
        self.largest_bank = I
        self.have_clone = False
        self.rng = rng

    @property
    def kernel_covariance(self) -> np.ndarray:
        """A zeroed scratch: the kernel's step leaves this step's ``Phi`` and ``Qd`` in the work array."""
        return self.P

    def predict(self, step: Transition) -> None:
        F, phi, qd, T, measured = step.F, step.Phi, step.Qd, step.T, step.measured
        self.P[:, :] = 0.0
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
        status, nis, lw, X, Pb, dx = self.epoch(z, np.ascontiguousarray(H), r, kinds)
        if status in (OK, NEEDS_REPAIR):
            X[:, n:ic] += dx[n:ic]  # kept states are estimates, not errors of the nominal: undo the re-centring
            self.lw, self.X, self.Pb = lw, X, Pb
            if self.have_clone:
                return Correction(np.concatenate([dx[:n], dx[ic:]]), nis, status, len(z))
        return Correction(dx[:n], nis, status, len(z))

    def epoch(self, z, H, r, kinds):
        """The bank's measurement epoch in one compiled call, ``(status, nis, lw, X, P, dx)``
        of :func:`~mixnav.filters._bank_kernels.bank_epoch` (the bank itself unchanged).

        With online learning the collecting variant also returns each row's
        standardised innovation and prediction share, which go to the learner;
        a refit replaces the mixture tables used from the next epoch on. A
        subclass that writes its own ``update`` calls this to keep both.
        """
        args = (self.lw, self.X, self.Pb, z, H, r, kinds, *self.tables, self.absurd_sigma,
                self.max_components, self.n)
        if self.online is None:
            return bank_epoch(*args)
        m = len(z)
        if len(self._u) < m:
            self._u, self._q = np.empty(2 * m), np.empty(2 * m)
        out = bank_epoch_collect(*args, self._u, self._q)
        if self.online.observe(out[0] in (OK, NEEDS_REPAIR), kinds, self._u[:m], self._q[:m]):
            self.mixtures = replace(self.mixtures, measurement={**self.mixtures.measurement,
                                                                **self.online.current})
            self.tables = self._tables_for(self.mixtures)
        return out

    def _tables_for(self, mixtures):
        return _padded(mixtures.tables())

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
        _, _, Pm = bank_moments(self.lw, self.X, self.Pb)
        return np.ascontiguousarray(Pm[:self.n, :self.n])

    def diagnostics(self) -> dict:
        out = {"bank_components_max": float(self.largest_bank)}
        if self.online is not None:
            out.update(self.online.timing())
        return out

    def warm_up(self) -> None:
        """Compile (or load from the numba cache) the bank kernels once per process,
        outside the timed loop."""
        if self.online_settings is not None:
            from .online import warm_online
            warm_online()
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
        bank_epoch(lw, X, P, np.zeros(1), H, np.ones(1), np.zeros(1, dtype=np.int64), np.zeros((1, 1)),
                   np.zeros((1, 1)), np.ones((1, 1)), 1e4, 1, n)
        bank_epoch_collect(lw, X, P, np.zeros(1), H, np.ones(1), np.zeros(1, dtype=np.int64), np.zeros((1, 1)),
                           np.zeros((1, 1)), np.ones((1, 1)), 1e4, 1, n, np.empty(1), np.empty(1))
        _BANK_WARM.append(True)


#: The old name of :class:`BankEstimator`.
BankBelief = BankEstimator


class GaussianMixtureEkf(ErrorStateEkf):
    """Gaussian-mixture (Gaussian sum) closed-loop error-state EKF, method M3.

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
    online : mixnav.filters.online.OnlineSettings, optional
        Re-learn these kinds' measurement mixtures online from a sliding window
        of innovations (M4 beyond the paper; :mod:`mixnav.filters.online`),
        starting from ``mixtures``. Every run starts again from ``mixtures``.
    learner_not_converged : int
        Offline mixture fits that did not converge (reported in ``recoveries``).
    """

    def __init__(self, layout: StateLayout, imu_model: ImuErrorModel, mixtures: BankMixtures,
                 max_components: int = 16, covariance_interval: float = 1.0, absurd_sigma: float = 1e4,
                 clock: ClockModel | None = None, learning_time_s: float = 0.0, online=None,
                 learner_not_converged: int = 0):
        super().__init__(layout, imu_model, covariance_interval, absurd_sigma, clock)
        if int(max_components) < 1:
            raise ArgumentError(f"must be at least 1, got {max_components}", argument="max_components")
        self.mixtures = mixtures
        self.max_components = int(max_components)
        self.learning_time_s = float(learning_time_s)
        self.learner_not_converged = int(learner_not_converged)
        self.online = online
        self._last = None

    def make_estimator(self):
        self._last = BankEstimator(self.mixtures, self.max_components, self.absurd_sigma, self.online)
        return self._last

    def run(self, imu, init, measurements=(), output_times=None, rng=None, history: bool = False):
        res = super().run(imu, init, measurements, output_times, rng, history)
        res.timing["learning_time_s"] = self.learning_time_s
        if self.learner_not_converged:
            res.recoveries["learner_not_converged"] = self.learner_not_converged
        return res

    @property
    def online_learner(self):
        """The online learner of the last run (its ``history`` and counters), or None."""
        return None if self._last is None else self._last.online


def learn_mixture(samples: np.ndarray, method: str, n_components: int = 4, gibbs_samples: int = 1000,
                  prune: float = 0.01, seed: int = 0) -> StandardMixture:
    """Fit a standardised 1-D noise mixture to training residuals.

    ``"vb"`` uses P1's settings (alpha0 = 1, beta0 = 1, nu0 = 1, W0 = 2,
    m0 = the sample mean, K = ``n_components``, stop at a lower-bound change
    below 1e-6, prune below ``prune``); ``"gibbs"`` the same conjugate model
    sampled ``gibbs_samples`` times (P1 schemes 3-4); ``"em"`` maximum
    likelihood.
    """
    from ..noise.learn import EMGaussianMixture, GibbsGaussianMixture, VariationalGaussianMixture
    x = np.asarray(samples, dtype=float).reshape(-1, 1)
    if method == "vb":
        est = VariationalGaussianMixture(n_components=n_components, alpha0=1.0, beta0=1.0, nu0=1.0,
                                         W0=np.array([[2.0]]), tol=1e-6, prune_threshold=prune,
                                         random_state=seed)
    elif method == "gibbs":
        est = GibbsGaussianMixture(n_components=n_components, n_samples=gibbs_samples, alpha0=1.0,
                                   beta0=1.0, nu0=1.0, W0=np.array([[2.0]]), prune_threshold=prune,
                                   random_state=seed)
    elif method == "em":
        est = EMGaussianMixture(n_components=n_components, random_state=seed)
    else:
        raise ConfigError(f"unknown learner '{method}' (vb, gibbs, em)", key="mixture.learn.method")
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a non-converged fit is still a usable mixture; counted below
        est.fit(x)
    gm = est.mixture_
    if method == "em":  # EM has no pruning of its own
        gm = gm.prune(prune)
    return StandardMixture.from_mixture(gm)


def learn_mixtures(cfg, training: dict, seed: int = 0) -> tuple[BankMixtures, float]:
    """The mixtures of ``cfg.learn`` from training residuals, and the learning time [s].

    ``cfg`` is a :class:`mixnav.config.schema.MixtureConfig`; mixtures it
    gives explicitly are kept, the ones listed in ``learn`` are learned.
    """
    import time
    lc = cfg.learn
    t0 = time.perf_counter()
    meas = {k: _spec(v) for k, v in cfg.measurement.items()}
    if not lc.offline:  # only online learning: start from the given mixtures
        return mixtures_from_config(cfg), 0.0
    for kind in lc.observables:
        meas[kind] = learn_mixture(training[kind][:lc.training_samples], lc.method, lc.n_components, lc.gibbs_samples, lc.prune, seed)
    process = _spec(cfg.process) if cfg.process is not None else StandardMixture.gaussian()
    if lc.learn_process:
        p = learn_mixture(training["process"][:lc.training_samples], lc.method, lc.n_components, lc.gibbs_samples, lc.prune, seed)
        # process-noise means are zero by construction (module docstring): keep weights and scales,
        # the scales about zero (E[x^2] per component)
        process = StandardMixture(p.weights, (0.0,) * p.n_components,
                                  tuple(np.asarray(p.scales) + np.asarray(p.means) ** 2))
    prior = _spec(cfg.prior) if cfg.prior is not None else StandardMixture.gaussian()
    return BankMixtures(meas, process, prior), time.perf_counter() - t0


def mixtures_from_config(cfg) -> BankMixtures:
    """The given (not learned) mixtures of a :class:`mixnav.config.schema.MixtureConfig`."""
    return BankMixtures({k: _spec(v) for k, v in cfg.measurement.items()},
                        _spec(cfg.process) if cfg.process is not None else StandardMixture.gaussian(),
                        _spec(cfg.prior) if cfg.prior is not None else StandardMixture.gaussian())


def _spec(s) -> StandardMixture:
    return StandardMixture(tuple(s.weights), tuple(s.means or [0.0] * len(s.weights)), tuple(s.scales))
