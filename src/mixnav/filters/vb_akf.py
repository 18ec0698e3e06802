"""Variational-Bayes adaptive measurement noise (Sarkka & Nummenmaa 2009) and the VB-AKF.

Each measurement channel (a row id that means the same thing at every epoch,
``Rows.channels``: north position, down velocity, one satellite's
pseudorange...) has an unknown variance ``r_i`` with an inverse-Gamma belief
``IG(alpha_i, beta_i)``. Per epoch of the channel:

* prediction with the forgetting factor ``rho`` in (0, 1] (SN09 eq. 17):
  ``alpha <- rho alpha``, ``beta <- rho beta`` (rho = 1: a constant noise,
  ever longer memory; steady state ``alpha -> 1 / (2 (1 - rho))``, a memory of
  about ``1 / (1 - rho)`` epochs);
* update by a fixed-point iteration (SN09 algorithm 1): ``alpha = alpha^- +
  1/2``, then repeat ``iterations`` times (or until no variance changes by more
  than ``tolerance`` relative): the Kalman update with ``R = diag(beta /
  alpha)``, then ``beta = beta^- + (e_i^2 + (H P+ H^T)_ii) / 2`` with ``e``
  the posterior residual.

The tracked standard deviation of a channel is ``sqrt(beta / alpha)`` (the
variance used in the update). A channel seen for the first time starts from
``alpha = prior_shape`` and ``beta = prior_shape * prior_scale * r_model``:
the model's (receiver-reported) variance times ``prior_scale``.

:class:`VbKalmanEstimator` is the same step on the EKF (VB-AKF, beyond the
paper); :class:`mixnav.filters.ukf.UnscentedEstimator` with a
:class:`ChannelNoise` is the VB-AUKF. Both call one compiled correction
(:func:`mixnav.filters._ukf_kernels.vb_correct`); with an EKF, ``Pxy = P
H^T`` and ``Pyy = H P H^T``.
"""

from __future__ import annotations

import numpy as np

from ..engine.protocols import Correction, Epoch
from ..errors import ArgumentError
from ._ukf_kernels import vb_correct
from pydantic import Field

from .ekf import KalmanEstimator
from .facade import facade
from .registry import GateOptions, register_estimator
from ..engine.status import NEEDS_REPAIR, OK
from .registry import ABSURD_SIGMA

__all__ = ["ChannelNoise", "VbKalmanEstimator", "VbAdaptiveEkf", "VbOptions", "check_vb_settings"]


def check_vb_settings(rho, prior_shape, prior_scale, iterations, tolerance) -> None:
    """ArgumentError naming the first bad setting."""
    if not 0.0 < rho <= 1.0:
        raise ArgumentError(f"must be in (0, 1], got {rho}", argument="rho")
    if not prior_shape > 0.0:
        raise ArgumentError(f"must be positive, got {prior_shape}", argument="prior_shape")
    if not prior_scale > 0.0:
        raise ArgumentError(f"must be positive, got {prior_scale}", argument="prior_scale")
    if int(iterations) != iterations or iterations < 1:
        raise ArgumentError(f"must be an integer >= 1, got {iterations}", argument="iterations")
    if not tolerance >= 0.0:
        raise ArgumentError(f"must be >= 0, got {tolerance}", argument="tolerance")


class ChannelNoise:
    """The inverse-Gamma belief about each channel's noise variance (module docstring).

    Parameters
    ----------
    rho : float
        Forgetting factor in (0, 1].
    prior_shape : float
        ``alpha`` of a channel's first prior (> 0).
    prior_scale : float
        A channel's first variance relative to the model's ``R`` (> 0).
    iterations : int
        Fixed-point iterations per epoch (>= 1).
    tolerance : float
        Relative change of every variance below which the iteration stops early.
    """

    def __init__(self, rho: float = 0.95, prior_shape: float = 1.0, prior_scale: float = 1.0,
                 iterations: int = 3, tolerance: float = 1e-4):
        check_vb_settings(rho, prior_shape, prior_scale, iterations, tolerance)
        self.rho, self.prior_shape, self.prior_scale = float(rho), float(prior_shape), float(prior_scale)
        self.iterations, self.tolerance = int(iterations), float(tolerance)
        self.reset()

    def reset(self) -> None:
        self.index = {}                 # channel id -> position in alpha/beta
        self.alpha = np.empty(0)
        self.beta = np.empty(0)
        self.trace_t, self.trace_ch, self.trace_sigma, self.trace_iter = [], [], [], []

    def predicted(self, channels: np.ndarray, r: np.ndarray):
        """``(alpha^-, beta^-)`` (m,) of the epoch's rows: the forgetting step of each
        channel seen before, the prior for a new one."""
        idx = np.empty(len(channels), dtype=np.int64)
        for k, ch in enumerate(channels.tolist()):
            j = self.index.get(ch)
            if j is None:
                j = len(self.index)
                self.index[ch] = j
                self.alpha = np.append(self.alpha, self.prior_shape / self.rho)  # forgotten below: the prior
                self.beta = np.append(self.beta, self.prior_shape * self.prior_scale * float(r[k]) / self.rho)
            idx[k] = j
        self._idx = idx
        return self.rho * self.alpha[idx], self.rho * self.beta[idx]

    def store(self, time: float, channels: np.ndarray, alpha: np.ndarray, beta: np.ndarray, iters: int) -> None:
        """Keep the epoch's posterior parameters and trace the tracked sigma."""
        self.alpha[self._idx] = alpha
        self.beta[self._idx] = beta
        self.trace_t.append(time)
        self.trace_ch.append(channels)
        self.trace_sigma.append(np.sqrt(beta / alpha))
        self.trace_iter.append(iters)

    def sigma(self) -> dict:
        """Channel id -> current tracked sigma ``sqrt(beta / alpha)``."""
        return {ch: float(np.sqrt(self.beta[j] / self.alpha[j])) for ch, j in self.index.items()}

    def outputs(self) -> dict:
        """``vb_time`` (E,), ``vb_channel`` (E, m) ids and ``vb_sigma`` (E, m) tracked sigma per
        updated epoch (rows padded with -1 / NaN when epochs have different row counts),
        ``vb_iterations`` (E,)."""
        if not self.trace_t:
            return {}
        m = max(len(c) for c in self.trace_ch)
        E = len(self.trace_t)
        ch = np.full((E, m), -1, dtype=np.int64)
        sg = np.full((E, m), np.nan)
        for k, (c, s) in enumerate(zip(self.trace_ch, self.trace_sigma)):
            ch[k, :len(c)] = c
            sg[k, :len(s)] = s
        return {"vb_time": np.array(self.trace_t), "vb_channel": ch, "vb_sigma": sg,
                "vb_iterations": np.array(self.trace_iter)}


def channel_label(ch: int) -> str:
    """The label of a channel id (:func:`~mixnav.measurements.kinds.channel_id`):
    ``position_n`` (an axis), ``pseudorange_12`` (a PRN), ``pseudorange_E05`` (a
    satellite of a lettered system, :data:`~mixnav.gnss.pseudoranges.SYSTEM_LETTERS`);
    a channel of no registered kind is labelled by its id."""
    from ..gnss.pseudoranges import SYSTEM_LETTERS
    from ..measurements.kinds import channel_parts, kind_name
    kind, system, axis = channel_parts(ch)
    try:
        name = kind_name(kind)
    except Exception:
        return str(ch)
    if system:
        return f"{name}_{SYSTEM_LETTERS.get(system, f'S{system}:')}{axis:02d}"
    return f"{name}_{'ned'[axis]}" if axis < 3 and name in ("position", "velocity") else f"{name}_{axis}"


class VbOptions(GateOptions):
    """The variational-Bayes noise settings (``[methods.options]`` of ``estimator = "vb-akf"``,
    and of ``"vb-aukf"`` with the UKF's)."""

    rho: float = Field(default=0.95, gt=0, le=1, description="forgetting factor in (0, 1]")
    prior_shape: float = Field(default=1.0, gt=0, description="inverse-Gamma shape of a new channel")
    prior_scale: float = Field(default=1.0, gt=0, description="a new channel's variance relative to the "
                               "model's (dimensionless)")
    iterations: int = Field(default=3, ge=1, description="fixed-point iterations per epoch")
    tolerance: float = Field(default=1e-4, ge=0, description="relative variance change that stops the "
                             "iteration early")

    def channel_noise(self) -> "ChannelNoise":
        return ChannelNoise(self.rho, self.prior_shape, self.prior_scale, self.iterations, self.tolerance)


@register_estimator("vb-akf", options=VbOptions, can_smooth=False,
                    description="variational-Bayes adaptive EKF: the VB-AUKF's noise step on the EKF (options: "
                    "rho, prior_shape, prior_scale, iterations, tolerance)",
                    build=lambda o, absurd_sigma, context: VbKalmanEstimator(o.channel_noise(), absurd_sigma))
class VbKalmanEstimator(KalmanEstimator):
    """The EKF's Gaussian with a VB-adapted variance per measurement channel (VB-AKF).

    Parameters
    ----------
    noise : ChannelNoise
    absurd_sigma : float
        As :class:`~mixnav.filters.ekf.KalmanEstimator` (the gate uses the predicted variance).
    """

    def __init__(self, noise: ChannelNoise | None = None, absurd_sigma: float = ABSURD_SIGMA):
        super().__init__(absurd_sigma)
        self.noise = noise if noise is not None else ChannelNoise()

    def init(self, motion, P0, n_clone, rng):
        super().init(motion, P0, n_clone, rng)
        if n_clone:
            raise ArgumentError("the VB-AKF does not carry a stochastic clone (TDCP)", argument="estimator")
        self.noise.reset()

    def update(self, epoch: Epoch) -> Correction | None:
        rows = epoch.rows()
        if rows is None:
            return None
        z, H, r = rows.z, rows.H, np.asarray(rows.R, dtype=float)
        if r.ndim != 1:
            raise ArgumentError("the VB-AKF adapts independent rows: R must be diagonal", argument="R")
        channels = rows.channels if rows.channels is not None else np.arange(len(z), dtype=np.int64)
        a0, b0 = self.noise.predicted(channels, r)
        PHt = self.P @ H.T
        Pyy = H @ PHt
        nz = self.noise
        x_post, P_post, nis, status, a, b, it = vb_correct(
            np.zeros(self.n), self.P, PHt, Pyy, Pyy, z, r, a0, b0, True, nz.iterations, nz.tolerance,
            self.absurd_sigma)
        if status == OK or status == NEEDS_REPAIR:
            self.P = P_post
            nz.store(epoch.time, channels, a, b, it)
        return Correction(x_post, nis, status, len(z))

    def diagnostics(self) -> dict:
        return {f"vb_sigma_{channel_label(ch)}": s for ch, s in sorted(self.noise.sigma().items())}

    def outputs(self) -> dict:
        return self.noise.outputs()

    def warm_up(self) -> None:
        super().warm_up()
        warm_vb()


def warm_vb() -> None:
    """Compile (or load) the VB correction once per process."""
    if _WARM:
        return
    m, n = 3, 9
    P = np.eye(n)
    Pxy = np.zeros((n, m))
    Pxy[6:9] = np.eye(3)
    one = np.ones(m)
    for vb in (True, False):
        vb_correct(np.zeros(n), P, Pxy, np.eye(m), np.eye(m), np.zeros(m), one, one, one, vb, 2, 1e-4, 1e4)
    _WARM.append(True)


_WARM: list = []


#: The VB-AKF: ``VbAdaptiveEkf(layout, imu_model, rho=0.95, ..., tolerance=1e-4, ...)``.
VbAdaptiveEkf = facade("vb-akf", "VbAdaptiveEkf")
