"""EM estimate of a GNSS multipath bias from a sliding window of innovations (P4 eqs. 17-27).

P4 models the GNSS position error under multipath as a two-component Gaussian mixture,
one component biased (``z = H x + a + w``, eq. 17), fits it by EM and removes the biased
component's mean from the measurement, using its covariance as R. The paper fits the
joint vector ``[X; Z]`` (eqs. 18-24); the error state is not observed, so its part of
that fit carries no information the innovation does not, and here the fit is of what is
observed: the GNSS mode's position innovations ``y = z - H x`` of the last ``window``
epochs (the noise toolkit's :class:`~mixnav.noise.learn.em.EMGaussianMixture`, seeded
from the estimator's own random stream).

Settings (:class:`EmBiasSettings`, documented in docs/imm.md):

* ``window`` [s]: the sliding window's length (P4 does not say; 60 s spans a multipath
  episode's start without remembering the previous one for long). It is a duration, not
  a count: across an outage a count-based window kept minutes-old innovations;
* ``min_samples``: no fit before the window holds this many;
* only innovations whose state part is small enter the window: the predicted position
  sigma ``sqrt(trace H P H^T)`` at most ``max_state_sigma`` (default a third of
  ``min_separation``: the state must be sure to well within the biases to be told
  apart). After an outage the first innovations are metres wide because the state
  drifted, not because of multipath; windowed, they looked like a second component (a
  3-7 m "bias" declared 100 s after an outage in simulation);
* ``gate``: position rows whose NIS under the current noise model (configured, or the
  window's) exceeds the chi-square quantile of that probability are kept out of the
  update but not out of the window. At the onset of multipath the filter, told RTK's
  centimetres, would otherwise follow every 10 m jump, and its innovations would then be
  differences of fix errors (clusters at 0 and +-10 m), not the errors EM must fit. While
  the window holds one cloud wider than the configured noise, its covariance is R (noise
  that grew without a bias);
* ``min_separation`` [m]: a bias is declared only when the two component means are at
  least this far apart, the smaller component has at least ``min_weight`` of the
  window, and the separation is at least ``min_separation_sigmas`` times the biased
  component's largest standard deviation: otherwise the window is one cloud (or a cloud
  and its tail) and nothing is removed. The last rule came from the end of a multipath
  episode: a window holding centimetre RTK innovations and a metres-wide multipath
  cloud (clean and biased fixes together) fits as "tight cloud + broad cloud" 3 m
  apart, and clean RTK epochs a few centimetres out were then "biased" (3-7 m bias
  errors in 5 of 50 runs of P4-vehicle before it);
* an epoch whose innovation the biased component explains (responsibility > 1/2) has
  the bias ``a`` (the biased mean minus the clean mean) subtracted from its position
  rows and the biased component's covariance as their R (P4: "its covariance becomes
  R"; this counts the state's own uncertainty in it once more, which errs on the safe
  side); the other epochs of a window with a bias get the clean component's covariance
  as R when it is wider (in trace) than the configured one (the clean part of a multipath episode
  is noisier than open sky: P4-vehicle's is 1 m against RTK's centimetres).

The bias applied at each GNSS epoch is an output (``result.outputs["bias_*"]``).
"""

from __future__ import annotations

import warnings
from collections import deque
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from ..errors import ArgumentError
from ..measurements.base import Rows
from ..measurements.kinds import POSITION
from pydantic import BaseModel, Field

from .ekf import KalmanEstimator
from .option_fields import STRICT, Duration, PosLength
from .registry import register_estimator
from .registry import ABSURD_SIGMA


@lru_cache(maxsize=64)
def _chi2_quantile(p: float, dof: int) -> float:
    """``chi2.ppf(p, dof)``, cached: the gate asks at every GNSS epoch (~60 us a call)."""
    from scipy.stats import chi2
    return float(chi2.ppf(p, dof))


@dataclass(frozen=True)
class EmBiasSettings:
    """See the module docstring. ``window`` [s], ``min_samples`` [epochs], ``min_separation``
    [m], ``min_weight`` (fraction), ``max_state_sigma`` [m] (None: ``min_separation / 3``),
    ``min_separation_sigmas``, ``gate`` (chi-square probability), ``refit_every`` [epochs],
    ``max_iter`` of each EM fit."""

    window: float = 60.0
    min_samples: int = 20
    min_separation: float = 3.0
    min_weight: float = 0.05
    min_separation_sigmas: float = 2.0
    max_state_sigma: float | None = None
    gate: float = 0.9999
    refit_every: int = 5
    max_iter: int = 100

    @property
    def state_sigma_limit(self) -> float:
        """Innovations enter the window while the state's position sigma is at most this [m]."""
        return self.min_separation / 3.0 if self.max_state_sigma is None else float(self.max_state_sigma)

    def gate_nis(self, dof: int) -> float:
        """The NIS above which the position rows are kept out of the update."""
        return _chi2_quantile(self.gate, int(dof))

    def __post_init__(self):
        if not (np.isfinite(self.window) and self.window > 0):
            raise ArgumentError(f"must be a positive duration [s], got {self.window!r}", argument="window")
        if not (isinstance(self.min_samples, (int, np.integer)) and self.min_samples >= 2):
            raise ArgumentError(f"must be an integer >= 2 (two components), got {self.min_samples!r}",
                                argument="min_samples")
        if not (np.isfinite(self.min_separation) and self.min_separation > 0):
            raise ArgumentError(f"must be a positive distance [m], got {self.min_separation!r}",
                                argument="min_separation")
        if self.max_state_sigma is not None and not (np.isfinite(self.max_state_sigma) and self.max_state_sigma > 0):
            raise ArgumentError(f"must be a positive distance [m] or None, got {self.max_state_sigma!r}",
                                argument="max_state_sigma")
        if not (isinstance(self.refit_every, (int, np.integer)) and self.refit_every >= 1):
            raise ArgumentError(f"must be an integer >= 1, got {self.refit_every!r}", argument="refit_every")
        if not (0.5 < self.gate < 1):
            raise ArgumentError(f"must be a probability in (0.5, 1), got {self.gate!r}", argument="gate")
        if not (np.isfinite(self.min_separation_sigmas) and self.min_separation_sigmas >= 0):
            raise ArgumentError(f"must be >= 0, got {self.min_separation_sigmas!r}", argument="min_separation_sigmas")
        if not (0 <= self.min_weight < 0.5):
            raise ArgumentError(f"must be a fraction in [0, 0.5), got {self.min_weight!r}", argument="min_weight")


class BiasFit(NamedTuple):
    """A declared bias: ``bias`` (d,) the biased mean minus the clean mean [m], the clean
    mean (d,), the two components' covariances (d, d), the fitted ``model``
    (:class:`~mixnav.noise.learn.em.EMGaussianMixture`), which of its components is the
    biased one, and whether EM converged."""

    bias: np.ndarray
    clean_mean: np.ndarray
    biased_cov: np.ndarray
    clean_cov: np.ndarray
    model: object
    biased: int
    converged: bool


def fit_bias(Y: np.ndarray, settings: EmBiasSettings, rng: np.random.Generator, start=None):
    """Two-component EM fit of innovations ``Y`` (N, d) [m].

    Returns a :class:`BiasFit`, or None when no bias is declared
    (means closer than ``min_separation`` or than ``min_separation_sigmas`` of the biased
    component's spread, or the smaller component below ``min_weight``).
    The clean component is the one whose mean is nearer zero (the innovation of a fix that
    agrees with the prediction): by weight, a window where the biased fixes happened to be
    the majority swapped the two and removed a -10 m "bias" from clean fixes (one run of 50). ``start``: a
    previous fit (an ``EMGaussianMixture``) whose responsibilities on ``Y`` start this one
    (a window moved by a few epochs is nearly the same fit); default k-means++.
    """
    from ..noise.learn import ConvergenceWarning
    from ..noise.learn.em import EMGaussianMixture
    init = "kmeans++" if start is None else start.predict_proba(Y)
    em = EMGaussianMixture(2, tol=1e-6, max_iter=settings.max_iter, reg_covar=1e-6, init=init, random_state=rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        try:
            em.fit(Y)
        except ValueError:      # zero variance or a collapsed component: one cloud
            return None
    # the clean component is the one centred nearer the filter's prediction (zero innovation):
    # the heavier one was wrong in windows where biased fixes happened to be the majority
    clean = int(np.argmin(np.linalg.norm(em.means_, axis=1)))
    biased = 1 - clean
    bias = em.means_[biased] - em.means_[clean]
    sep = float(np.linalg.norm(bias))
    spread = float(np.sqrt(np.linalg.eigvalsh(em.covariances_[biased])[-1]))
    if sep < settings.min_separation or em.weights_[biased] < settings.min_weight \
            or sep < settings.min_separation_sigmas * spread:
        return None
    return BiasFit(bias, em.means_[clean], em.covariances_[biased], em.covariances_[clean], em, biased,
                   bool(em.converged_))


class EmBiasOptions(BaseModel):
    """The EM multipath-bias removal of an EM-IMM mode (``[methods.imm.modes.em]``): the sliding
    ``window`` [s], ``min_samples`` in it before a fit (at least the two components),
    ``min_separation`` [m] (also at least ``min_separation_sigmas`` of the biased component's
    spread) and ``min_weight`` of the biased component before a bias is declared,
    ``max_state_sigma`` [m] (innovations enter the window only while the state's position
    sigma is at most this; default a third of ``min_separation``) and ``gate`` (chi-square
    probability above which position rows the current noise model cannot explain are kept out
    of the update), ``refit_every`` (epochs between EM fits, each warm-started from the last).
    :meth:`settings` gives the :class:`EmBiasSettings` the estimator takes."""

    model_config = STRICT

    window: Duration = 60.0  # type: ignore[valid-type]
    min_samples: int = Field(default=20, ge=2, description="at least one sample per component")
    min_separation: PosLength = 3.0  # type: ignore[valid-type]
    min_weight: float = Field(default=0.05, ge=0.0, lt=0.5)
    min_separation_sigmas: float = Field(default=2.0, ge=0.0)
    max_state_sigma: PosLength | None = None  # type: ignore[valid-type]
    gate: float = Field(default=0.9999, gt=0.5, lt=1.0)
    refit_every: int = Field(default=5, ge=1)

    def settings(self) -> EmBiasSettings:
        return EmBiasSettings(window=float(self.window), min_samples=self.min_samples,
                              min_separation=float(self.min_separation), min_weight=self.min_weight,
                              min_separation_sigmas=self.min_separation_sigmas,
                              max_state_sigma=None if self.max_state_sigma is None else float(self.max_state_sigma),
                              gate=self.gate, refit_every=self.refit_every)


def _gnss_models(context) -> set:
    """The models whose position rows the bias removal checks: the method's GNSS model."""
    gnss = context.named_measurements.get("gnss")
    if gnss is None:
        raise ArgumentError("the EM bias removal needs the method's GNSS model (BuildContext.named_measurements"
                            "['gnss'])", argument="measurements")
    return {gnss}


def _em_mode(options: EmBiasOptions, absurd_sigma: float, context):
    """The registration's imm_child: fresh mean-carrying EM-bias EKFs on the method's GNSS rows."""
    settings, models = options.settings(), _gnss_models(context)
    return lambda: EmBiasKalman(models, settings, absurd_sigma, carry_mean=True)


def _check_em_entry(options: EmBiasOptions, measurements, mode: bool) -> None:
    if "gnss" not in measurements:
        raise ValueError("an em-bias mode removes a bias from the GNSS: list \"gnss\" in its measurements")


@register_estimator("em-bias", options=EmBiasOptions, table="em", motions=("strapdown",), imm_child=_em_mode,
                    standalone=False, check=_check_em_entry,
                    build=lambda o, absurd_sigma, context: EmBiasKalman(_gnss_models(context), o.settings(),
                                                                        absurd_sigma),
                    description="the EM-IMM's GNSS mode: the EKF with the EM multipath-bias removal on its "
                    "GNSS rows (a mode of an IMM only)")
class EmBiasKalman(KalmanEstimator):
    """A Kalman estimator that removes an EM-estimated multipath bias from the position rows of
    the models in ``models`` (module docstring); the GNSS mode of the EM-IMM.

    Parameters
    ----------
    models : collection of measurement models
        Whose position rows are checked (the GNSS model).
    settings : EmBiasSettings
    absurd_sigma, carry_mean
        As :class:`~mixnav.filters.ekf.KalmanEstimator`.
    """

    def __init__(self, models, settings: EmBiasSettings = EmBiasSettings(), absurd_sigma: float = ABSURD_SIGMA,
                 carry_mean: bool = False):
        super().__init__(absurd_sigma, carry_mean)
        self.models = frozenset(models)
        if not isinstance(settings, EmBiasSettings):
            raise ArgumentError(f"expected EmBiasSettings, got {type(settings).__name__}", argument="settings")
        self.settings = settings

    def init(self, motion, P0, n_clone, rng):
        super().init(motion, P0, n_clone, rng)
        self._window: deque = deque()     # (time [s], innovation (3,))
        self._cache = (None, None)
        self._fit, self._since_fit = None, 0
        self._log_t, self._log_bias, self._log_applied = [], [], []
        self.counts.update(em_fits=0, em_not_converged=0, em_bias_epochs=0, em_gated_epochs=0)

    def adjusted_rows(self, epoch) -> Rows | None:
        """The epoch's rows with the bias removed when the biased component explains them (the
        same object for repeated calls within one epoch, so the window grows once)."""
        if self._cache[0] is epoch:
            return self._cache[1]
        rows = epoch.rows()
        out = rows
        if rows is not None and epoch.model in self.models:
            out = self._remove_bias(epoch.time, rows)
        self._cache = (epoch, out)
        return out

    def update(self, epoch):
        return self.update_rows(self.adjusted_rows(epoch))

    def _remove_bias(self, t: float, rows: Rows) -> Rows | None:
        pos = np.nonzero(rows.kinds == POSITION)[0]
        if len(pos) == 0:
            return rows
        st = self.settings
        x = self.x if self.carry_mean else np.zeros(self.n)
        Hp = rows.H[pos]
        y = rows.z[pos] - Hp @ x
        HPH = Hp @ self.P @ Hp.T
        w = self._window
        while w and w[0][0] < t - st.window:
            w.popleft()
        settled = float(np.sqrt(np.trace(HPH))) <= st.state_sigma_limit
        if settled:
            w.append((t, y))
        applied = np.zeros(len(pos))
        result = None
        R = np.diag(rows.R) if np.ndim(rows.R) == 1 else np.array(rows.R, dtype=float)
        z = rows.z
        if settled and len(w) >= st.min_samples:
            self._since_fit += 1
            if self._fit is None or self._since_fit >= st.refit_every:
                # a window moved by a few epochs is nearly the same fit: refit every few, warm
                self.counts["em_fits"] += 1
                Y = np.array([v for _, v in w])
                prev = self._fit[0].model if self._fit is not None and self._fit[0] is not None else None
                self._fit = (fit_bias(Y, st, self.rng, start=prev), np.cov(Y.T))
                self._since_fit = 0
            result, cov = self._fit
            if result is None:   # one cloud: its spread is the noise, if wider than configured
                if np.trace(cov) > np.trace(R[np.ix_(pos, pos)]):
                    R[np.ix_(pos, pos)] = cov
        elif not settled:
            self._fit = None
        if result is not None:
            if not result.converged and self._since_fit == 0:
                self.counts["em_not_converged"] += 1
            if result.model.predict_proba(y[None, :])[0, result.biased] > 0.5:
                applied = result.bias
                z = rows.z.copy()
                z[pos] -= result.bias
                y = y - result.bias
                R[np.ix_(pos, pos)] = result.biased_cov
                self.counts["em_bias_epochs"] += 1
            elif np.trace(result.clean_cov) > np.trace(R[np.ix_(pos, pos)]):
                # a clean epoch of a multipath episode: the clean component's spread, if wider
                R[np.ix_(pos, pos)] = result.clean_cov
        self._log_t.append(t)
        self._log_bias.append(np.asarray(applied, dtype=float))
        self._log_applied.append(result is not None)
        # the gate: position rows the current noise model cannot explain are kept out of the
        # update (they stay in the window, which is how the model learns them)
        S = HPH + R[np.ix_(pos, pos)]
        try:
            nis = float(y @ np.linalg.solve(S, y))
        except np.linalg.LinAlgError:
            nis = np.inf
        if nis > st.gate_nis(len(pos)):
            self.counts["em_gated_epochs"] += 1
            other = np.setdiff1d(np.arange(len(rows.z)), pos)
            if len(other) == 0:
                return None
            return Rows(rows.z[other], rows.H[other], R[np.ix_(other, other)], rows.kinds[other],
                        None if rows.channels is None else rows.channels[other])
        return Rows(z, rows.H, R, rows.kinds, rows.channels)

    def outputs(self) -> dict:
        """The bias removed at each checked epoch: ``bias_times`` (K,) [s], ``bias`` (K, 3) [m]
        (zeros where none was), ``bias_declared`` (K,) whether the window held a bias."""
        return {"bias_times": np.array(self._log_t, dtype=float),
                "bias": np.array(self._log_bias, dtype=float).reshape(-1, 3),
                "bias_declared": np.array(self._log_applied, dtype=bool)}
