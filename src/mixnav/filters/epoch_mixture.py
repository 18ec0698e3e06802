"""Whole-epoch mixture update: each range is line of sight or delayed, decided from all rows
of the epoch at once, with the delay distribution learned online (issue 21).

Urban pseudoranges are either line of sight (LOS: the measurement model's noise) or
non-line-of-sight (NLOS: the reflected path is longer, so the error is a *positive*
delay of tens of metres). Per row ``j`` of an epoch (innovation ``z_j``, row ``H_j``,
variance ``r_j``) the noise is the two-component mixture::

    e_j ~ w N(0, s r_j) + (1 - w) N(mu, sd^2)        (delay mean mu > 0 expected)

and the prior ``dx ~ N(0, P)``. The posterior of ``dx`` is a mixture over the
``2^m`` assignments of the rows; instead of splitting a bank row by row (M3-M5,
:mod:`mixnav.filters.gmekf`), the update finds the posterior mode by
expectation-maximisation over the whole epoch, the responsibilities of every row
computed against one common state (the receiver clock is shared, so the rows decide
together which of them are delayed):

- E-step: ``g_j = w N(e_j; 0, s r_j + h_j) / (w N(e_j; 0, s r_j + h_j) + (1 - w) N(e_j; mu,
  sd^2 + h_j))`` with ``e_j = z_j - H_j x`` and ``h_j = H_j P_post H_j^T``;
- M-step: the Kalman update from the prior with each row's expected information
  ``1 / r'_j = g_j / (s r_j) + (1 - g_j) / sd^2`` and target ``z'_j = r'_j (g_j z_j / (s r_j)
  + (1 - g_j) (z_j - mu) / sd^2)`` (Joseph form, :func:`mixnav.filters.kalman.kalman_correct`),

with ``r'_j`` of the mixture rows multiplied by the correlation factor below, until the
state moves less than ``tolerance`` (at most ``iterations``; an epoch that
hits the limit is counted, ``em_not_converged``). The posterior covariance is the last
M-step's. Rows of kinds not in ``kinds`` are Gaussian (``g = 1``).

Learning (``learn = True``): after each epoch ``w``, ``mu``, ``sd`` (and, with
``learn_scale``, the LOS variance factor ``s``) are re-estimated from the epoch's
responsibilities and posterior residuals, with exponential forgetting per row
(``forget``) and the starting values worth ``prior_rows`` rows; nothing is trained on a
truth. ``w`` stays in [0.05, 0.95], ``sd >= min_delay_sd``, ``s`` in [0.1, 10].
With ``w = 1`` fixed (``learn = False``) the update is the Kalman filter's, exactly.

Time-correlated errors (``correlation_time`` tau > 0): multipath and diffraction keep a
satellite's error for seconds, so rows of consecutive epochs are not independent and a
filter that takes them as such becomes overconfident and stiff (on smartLoc Berlin its
1-sigma fell to 0.5 m with errors of 5-10 m). For errors that follow an AR(1) of
correlation ``rho = exp(-dt / tau)`` between epochs ``dt`` apart, the mean of many
epochs has the variance of independent ones times ``(1 + rho) / (1 - rho)``
(about ``2 tau / dt``): the M-step's row variances are multiplied by that factor
(the E-step's classification keeps the model's variances). The track alignment measures
tau from its window's residuals (:func:`mixnav.alignment.track.los_correlation_time`).

Signal strength (``cn0_edges``): reflected signals arrive weaker, so the prior LOS
weight is kept per carrier-to-noise-density band (edges in dB-Hz; rows whose model
gives no C/N0, or a model without ``row_info``, use the band-free weight), each band's
``w`` learned from its own rows' responsibilities as above. On smartLoc Berlin,
measured against its reference: 13 % of the rows under 30 dB-Hz are within 10 m of
the truth, 54 % of those over 45 dB-Hz.
"""

from __future__ import annotations

import math

import numpy as np

from ..engine.protocols import Correction, Epoch
from ..engine.status import NEEDS_REPAIR, OK
from ..errors import ArgumentError
from ..measurements.kinds import kind_code
from pydantic import Field

from .ekf import KalmanEstimator
from .facade import facade
from .registry import GateOptions, register_estimator
from ._epoch_mixture_kernels import epoch_em, predictive_log_density
from .registry import ABSURD_SIGMA

__all__ = ["EpochMixtureEstimator", "EpochMixtureEkf"]



class EpochMixtureOptions(GateOptions):
    """``[methods.options]`` of ``estimator = "epoch-mixture"`` (as :class:`EpochMixtureEstimator`,
    which checks each value and names it)."""

    los_weight: float = Field(default=0.5, description="starting line-of-sight weight in (0, 1]")
    delay_mean: float = Field(default=10.0, description="starting mean of the delayed component [m]")
    delay_sd: float = Field(default=30.0, description="starting sd of the delayed component [m]")
    los_scale: float = Field(default=1.0, description="starting factor on the model's variance")
    learn: bool = True
    learn_scale: bool = False
    forget: float = Field(default=0.999, description="forgetting factor per row in (0, 1]")
    prior_rows: float = Field(default=200.0, description="weight of the starting values [rows]")
    min_delay_sd: float = Field(default=5.0, description="floor on the delay sd [m]")
    iterations: int = Field(default=20, description="EM iterations per epoch")
    tolerance: float = Field(default=1e-3, description="largest change of the state estimate that stops EM")
    kinds: list[str] = Field(default=["pseudorange"], description="observable kinds following the mixture")
    cn0_edges: list[float] = Field(default=[], description="C/N0 band edges [dB-Hz]")
    los_weight_bands: list[float] | None = Field(default=None, description="starting LOS weight per band")
    correlation_time: float = Field(default=0.0, description="correlation time of the LOS errors [s]")


def _build_epoch_mixture(options: EpochMixtureOptions, absurd_sigma: float, context):
    """The options the file sets, over the mixture a track alignment handed over
    (``context.extra["mixture_start"]``). A filter that sets no ``cn0_edges`` of its own takes
    the alignment's bands with the weights learned on them (a file that names bands once, in
    ``[alignment]``, gets them in the filter too); one that sets its own takes the weights only
    on the same bands (``cn0_edges = []``: no bands)."""
    given = options.model_dump(exclude_unset=True, exclude={"absurd_sigma"})
    start = dict(context.extra.get("mixture_start") or {})
    edges = start.pop("cn0_edges", None)
    if "cn0_edges" not in given and edges:
        start["cn0_edges"] = edges
    elif list(given.get("cn0_edges", [])) != edges:
        start.pop("los_weight_bands", None)      # learned on other bands
    return EpochMixtureEstimator(**{**start, **given}, absurd_sigma=absurd_sigma)


@register_estimator("epoch-mixture", options=EpochMixtureOptions, build=_build_epoch_mixture,
                    description="whole-epoch LOS/NLOS mixture update (issue 21): responsibilities of every "
                    "pseudorange of an epoch against one state, the delay distribution learned online")
class EpochMixtureEstimator(KalmanEstimator):
    """One Gaussian error state with the whole-epoch LOS/NLOS update (module docstring).

    Parameters
    ----------
    los_weight : float
        Starting ``w`` in (0, 1].
    delay_mean, delay_sd : float
        Starting ``mu`` [m] and ``sd`` [m] of the delayed component (``sd > 0``).
    los_scale : float
        Starting factor ``s`` on the model's variance (> 0).
    learn, learn_scale : bool
        Re-estimate ``w``, ``mu``, ``sd`` (and ``s``) online.
    forget : float
        Forgetting factor per row in (0, 1].
    prior_rows : float
        Weight of the starting values, in rows (>= 0).
    min_delay_sd : float
        Floor on ``sd`` [m] (> 0).
    iterations : int
        EM iterations per epoch (>= 1).
    tolerance : float
        Convergence: the largest change of the state estimate (> 0).
    kinds : sequence of str
        Observable kinds whose rows follow the mixture.
    cn0_edges : sequence of float
        C/N0 band edges [dB-Hz] for the per-band LOS weight (empty: one weight).
    correlation_time : float
        ``tau`` [s] of the line-of-sight errors (>= 0; 0: independent epochs).
    los_weight_bands : sequence of float, optional
        Starting LOS weight of each band, ``len(cn0_edges) + 2`` values in (0, 1] (the
        bands, then the band-free weight); default ``los_weight`` for all. A track
        alignment reports the ones it learned (:func:`mixnav.alignment.track.align_track`).
    absurd_sigma : float
        As :class:`~mixnav.filters.ekf.KalmanEstimator`.
    """

    def __init__(self, los_weight: float = 0.5, delay_mean: float = 10.0, delay_sd: float = 30.0,
                 los_scale: float = 1.0, learn: bool = True, learn_scale: bool = False, forget: float = 0.999,
                 prior_rows: float = 200.0, min_delay_sd: float = 5.0, iterations: int = 20,
                 tolerance: float = 1e-3, kinds=("pseudorange",), cn0_edges=(), los_weight_bands=None,
                 correlation_time: float = 0.0, absurd_sigma: float = ABSURD_SIGMA):
        super().__init__(absurd_sigma)
        if not (math.isfinite(correlation_time) and correlation_time >= 0):
            raise ArgumentError(f"must be >= 0 [s], got {correlation_time}", argument="correlation_time")
        self.correlation_time = float(correlation_time)
        edges = np.asarray(cn0_edges, dtype=float).reshape(-1)
        if edges.size and (not np.isfinite(edges).all() or (np.diff(edges) <= 0).any()):
            raise ArgumentError(f"must increase strictly, got {list(cn0_edges)}", argument="cn0_edges")
        self.cn0_edges = edges
        self.w_band0 = None
        if los_weight_bands is not None:
            wb = np.asarray(los_weight_bands, dtype=float).reshape(-1)
            if wb.shape != (len(edges) + 2,) or not ((wb > 0) & (wb <= 1)).all():
                raise ArgumentError(f"needs {len(edges) + 2} values in (0, 1] (one per C/N0 band and the band-free "
                                    f"one), got {list(los_weight_bands)}", argument="los_weight_bands")
            self.w_band0 = wb
        if not 0.0 < los_weight <= 1.0:
            raise ArgumentError(f"must be in (0, 1], got {los_weight}", argument="los_weight")
        for name, v in (("delay_sd", delay_sd), ("los_scale", los_scale), ("min_delay_sd", min_delay_sd),
                        ("tolerance", tolerance)):
            if not (math.isfinite(v) and v > 0):
                raise ArgumentError(f"must be positive, got {v}", argument=name)
        if not math.isfinite(delay_mean):
            raise ArgumentError(f"must be finite, got {delay_mean}", argument="delay_mean")
        if not 0.0 < forget <= 1.0:
            raise ArgumentError(f"must be in (0, 1], got {forget}", argument="forget")
        if not (math.isfinite(prior_rows) and prior_rows >= 0):
            raise ArgumentError(f"must be >= 0, got {prior_rows}", argument="prior_rows")
        if int(iterations) != iterations or iterations < 1:
            raise ArgumentError(f"must be an integer >= 1, got {iterations}", argument="iterations")
        self.start = dict(w=float(los_weight), mu=float(delay_mean), sd=float(delay_sd), s=float(los_scale))
        self.learn, self.learn_scale = bool(learn), bool(learn_scale)
        self.forget, self.prior_rows = float(forget), float(prior_rows)
        self.min_delay_sd = float(min_delay_sd)
        self.iterations, self.tolerance = int(iterations), float(tolerance)
        self.kind_codes = np.array([kind_code(k, argument="kinds") for k in kinds], dtype=np.int64)

    def init(self, motion, P0, n_clone, rng):
        super().init(motion, P0, n_clone, rng)
        if n_clone:
            raise ArgumentError("the epoch-mixture update carries no stochastic clone", argument="measurements")
        st = self.start
        self.w, self.mu, self.sd, self.s = st["w"], st["mu"], st["sd"], st["s"]
        n0 = self.prior_rows
        # sufficient statistics (forgotten per row): rows, LOS responsibility, delayed first and
        # second moments, LOS squared standardised residuals
        self._N, self._G = n0, n0 * self.w
        nb = len(self.cn0_edges) + 2          # bands, then the band-free weight (last)
        self.w_band = np.full(nb, self.w) if self.w_band0 is None else self.w_band0.copy()
        self._Nb = np.full(nb, n0)
        self._Gb = n0 * self.w_band
        self._S1 = n0 * (1 - self.w) * self.mu
        self._S2 = n0 * (1 - self.w) * (self.sd ** 2 + self.mu ** 2)
        self._Q = n0 * self.w * self.s
        self.counts["em_not_converged"] = 0
        self._trace = []
        self._t_last = None
        #: running sum of the rows' predictive log densities (:meth:`_predictive_log_density`)
        self.log_likelihood = 0.0
        #: (time, that epoch's sum, rows) of every update: a tuner scores a span of them
        self._ll_trace = []

    def _predictive_log_density(self, z, r, h, mix, w) -> float:
        """Sum over the rows of the log predictive density of each innovation, alone (the
        rows' correlation through the shared state is ignored): a score of the noise model
        and settings that needs no reference (``diagnostics()["innovation_log_likelihood"]``)."""
        return predictive_log_density(z, r, h, mix, w, self.s, self.mu, self.sd)

    def _bands(self, epoch, m: int) -> np.ndarray:
        """The C/N0 band of each row (the band-free index where unknown)."""
        nb = len(self.cn0_edges) + 2
        band = np.full(m, nb - 1, dtype=np.int64)
        info = getattr(epoch.model, "row_info", None) if len(self.cn0_edges) else None
        if info is not None:
            cn0 = np.asarray(info(epoch.index)["cn0"], dtype=float)
            if cn0.shape == (m,):
                ok = np.isfinite(cn0)
                band[ok] = np.searchsorted(self.cn0_edges, cn0[ok], side="right")
        return band

    def update(self, epoch: Epoch) -> Correction | None:
        rows = epoch.rows()
        if rows is None:
            return None
        z, H, r = rows.z, rows.H, np.asarray(rows.R, dtype=float)
        if r.ndim != 1:
            raise ArgumentError("the epoch-mixture update needs independent rows (R as variances)",
                                argument="R")
        mix = (rows.kinds[:, None] == self.kind_codes[None, :]).any(axis=1)
        P0 = self.P
        h = np.einsum("ij,jk,ik->i", H, P0, H)
        band = self._bands(epoch, len(z))
        w_row = self.w_band[band]
        ll = self._predictive_log_density(z, r, h, mix, w_row)
        self.log_likelihood += ll
        self._ll_trace.append((epoch.time, ll, len(z)))
        inflate = np.where(mix, self._correlation_factor(epoch.time), 1.0)
        P_new, x, nis, status, e, g, converged = epoch_em(
            np.ascontiguousarray(P0), z, H, r, mix, w_row, self.s, self.mu, self.sd, inflate, self.iterations,
            self.tolerance, self.absurd_sigma)
        if status != OK and status != NEEDS_REPAIR:
            return Correction(np.zeros(self.n), math.inf, status, len(z))
        if not converged:
            self.counts["em_not_converged"] += 1
        self.P = P_new
        if self.learn:
            self._learn(e[mix], r[mix], g[mix], band[mix])
        self._trace.append((epoch.time, float(g[mix].mean()) if mix.any() else 1.0, self.w, self.mu, self.sd,
                            self.s))
        return Correction(x, nis, status, len(z))

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) the EM kernel outside the timed loop."""
        super().warm_up()
        H = np.eye(2)
        mix, w = np.ones(2, np.bool_), np.full(2, 0.5)
        epoch_em(np.eye(2), np.zeros(2), H, np.ones(2), mix, w, 1.0, 10.0, 30.0, np.ones(2), 2, 1e-3, 1e4)
        predictive_log_density(np.zeros(2), np.ones(2), np.ones(2), mix, w, 1.0, 10.0, 30.0)

    def _correlation_factor(self, t: float) -> float:
        """``(1 + rho) / (1 - rho)``, ``rho = exp(-dt / tau)``, ``dt`` since the last epoch."""
        dt = None if self._t_last is None else t - self._t_last
        self._t_last = t
        if self.correlation_time <= 0 or dt is None or dt <= 0:
            return 1.0
        rho = math.exp(-dt / self.correlation_time)
        return (1.0 + rho) / max(1.0 - rho, 1e-12)

    def _learn(self, e, r, g, band):
        m = len(e)
        if m == 0:
            return
        lam = self.forget ** m
        nb = len(self.w_band)
        self._Nb = lam * self._Nb + np.bincount(band, minlength=nb)
        self._Gb = lam * self._Gb + np.bincount(band, weights=g, minlength=nb)
        self._N = lam * self._N + m
        self._G = lam * self._G + g.sum()
        self._S1 = lam * self._S1 + ((1 - g) * e).sum()
        self._S2 = lam * self._S2 + ((1 - g) * e * e).sum()
        self._Q = lam * self._Q + (g * e * e / r).sum()
        self.w = float(np.clip(self._G / self._N, 0.05, 0.95))
        self.w_band = np.clip(self._Gb / self._Nb, 0.05, 0.95)
        self.w_band[-1] = self.w
        nn = max(self._N - self._G, 1e-9)
        self.mu = float(self._S1 / nn)
        self.sd = float(max(math.sqrt(max(self._S2 / nn - self.mu ** 2, 0.0)), self.min_delay_sd))
        if self.learn_scale:
            self.s = float(np.clip(self._Q / max(self._G, 1e-9), 0.1, 10.0))

    def outputs(self) -> dict:
        """Per epoch: the mean LOS responsibility and the mixture then in use; and per update
        (``innovation_log_density_time``) the sum of its rows' predictive log densities
        (``innovation_log_density``, their sum is ``diagnostics()["innovation_log_likelihood"]``)
        and its rows (``innovation_rows``)."""
        out = {}
        if self._ll_trace:
            t, ll, m = map(np.array, zip(*self._ll_trace))
            out.update(innovation_log_density_time=t.astype(float), innovation_log_density=ll.astype(float),
                       innovation_rows=m.astype(np.int64))
        if not self._trace:
            return out
        t, g, w, mu, sd, s = map(np.array, zip(*self._trace))
        return {**out, "epoch_mixture_time": t, "los_share": g, "los_weight": w, "delay_mean_m": mu,
                "delay_sd_m": sd, "los_scale": s}

    def diagnostics(self) -> dict:
        return {"los_weight_final": self.w, "delay_mean_m_final": self.mu, "delay_sd_m_final": self.sd,
                "innovation_log_likelihood": self.log_likelihood}


#: The whole-epoch mixture filter on the strapdown INS: ``EpochMixtureEkf(layout, imu_model, los_weight=...)``
#: (C/N0 bands need a model with ``row_info``; the tight model has none: the band-free weight).
EpochMixtureEkf = facade("epoch-mixture", "EpochMixtureEkf")
