"""The unscented Kalman filter (M7) and the variational-Bayes adaptive UKF (VB-AUKF, paper P5).

The engine keeps one nominal state and feeds corrections back (docs/ukf.md);
the UKF fits it as a *mean-carrying error-state estimator whose sigma points
are full states*. Its belief is ``N(x, P)`` over the error state ``dx =
x_true - x_est`` of the layout (attitude as a rotation vector about the
nominal quaternion, ``C_true = exp([phi x]) C_est``: the minimal attitude
parameterisation, the USQUE choice; velocity; NED position metres; sensor,
clock and auxiliary errors; or the layout of another motion model). Per propagation
step (three compiled calls: the sigma points, the motion model's
``propagate_members``, the moments):

1. ``2n + 1`` scaled sigma points ``D_j = x +- c L e_k`` (``L L^T = P``,
   ``c = sqrt(n + lambda)``, ``lambda = alpha^2 (n + kappa) - n``);
2. the motion model turns each into a full state ``nominal_before (+) D_j`` (its
   feedback map), propagates it over the step's inputs (the nonlinear model: no
   Jacobian; for the strapdown INS each point mechanized with its own sensor
   errors), as it does a reference point ``D = 0``,
3. and differences them back against the reference (for the INS: rotation vector
   of ``C_j C_ref^T``, velocity and NED position differences, sensor deviations
   through their Gauss-Markov decay): the propagated error states
   (:meth:`~mixnav.engine.protocols.MotionModel.propagate_members`); their
   weighted mean and covariance plus
   the transition's ``Qd`` (additive process noise) are the prediction. The
   mean stays non-zero between updates (``carry_mean``): the nonlinearity's
   bias is kept, not dropped.

At a measurement epoch the sigma points are drawn again about the current
nominal (as full states by the motion model's ``member_states``), ``h`` is
evaluated on all of them by ``epoch.model.predict_batch`` (the loose GNSS model,
or the tight pseudorange/Doppler one with each point's receiver clock; the
motion model's ``member_rates`` gives each point's body rate), and the unscented
update gives the posterior mean, returned as the
correction; the engine feeds it back and calls :meth:`recentre`.

Scaled unscented transform (Julier 2002; Wan & van der Merwe 2000) weights::

    wm_0 = lambda / (n + lambda),  wc_0 = wm_0 + 1 - alpha^2 + beta,
    wm_j = wc_j = 1 / (2 (n + lambda))

``n + lambda <= 0`` or ``wc_0 < 0`` (the covariance then is a difference that
can lose positive definiteness) are rejected (ArgumentError naming the key).
A sigma-point covariance that is not positive definite (Cholesky fails) is
repaired (eigenvalues floored) and counted (``sigma_repair``).

With a :class:`~mixnav.filters.vb_akf.ChannelNoise` the update is the VB one of
:mod:`mixnav.filters.vb_akf` (VB-AUKF): the measurement moments come from the
sigma points, the posterior residual moments by statistical linearisation
(``G = Pxy^T P^-1 Pxy``), so the iterations re-use the one batch of ``h``.
"""

from __future__ import annotations

import numpy as np

from ..engine.protocols import Correction, Epoch, Transition
from ..errors import ArgumentError, NumericalError
from ..engine.status import NEEDS_REPAIR, OK
from ._no_clone import NoCloneEstimator
from ._ukf_kernels import linearized_pyy, measurement_moments, ukf_moments, ukf_sigma, vb_correct
from pydantic import Field

from .ekf import repair_covariance
from .facade import facade
from .registry import MOTIONS, GateOptions, register_estimator
from .vb_akf import ChannelNoise, VbOptions, channel_label, warm_vb
from .registry import ABSURD_SIGMA

__all__ = ["ut_weights", "UnscentedEstimator", "UnscentedKalmanFilter", "VbAdaptiveUkf"]

_WARM: set = set()


def ut_weights(n: int, alpha: float = 0.6, beta: float = 2.0, kappa: float = 0.0):
    """Scaled unscented-transform weights ``(wm, wc, c)`` for ``n`` states (module docstring).

    Raises ArgumentError (naming ``kappa`` or ``alpha``) when ``n + lambda <= 0`` or
    the centre's covariance weight is negative.
    """
    if not alpha > 0.0:
        raise ArgumentError(f"must be positive, got {alpha}", argument="alpha")
    if not np.isfinite(beta):
        raise ArgumentError(f"must be finite, got {beta}", argument="beta")
    lam = alpha * alpha * (n + kappa) - n
    if not n + lam > 0.0:
        raise ArgumentError(f"alpha^2 (n + kappa) must be positive (n = {n}, alpha = {alpha}, kappa = {kappa})",
                            argument="kappa")
    N = 2 * n + 1
    wm = np.full(N, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = wm[0] + 1.0 - alpha * alpha + beta
    if wc[0] < 0.0:
        raise ArgumentError(f"the centre point's covariance weight {wc[0]:.3g} is negative (n = {n}, alpha = "
                            f"{alpha}, beta = {beta}, kappa = {kappa}): the covariance can lose positive "
                            "definiteness; raise alpha or beta", argument="alpha")
    return wm, wc, float(np.sqrt(n + lam))


def predict_members(epoch: Epoch, D: np.ndarray, navs: np.ndarray, clk: int, who: str, motion=None):
    """``epoch.model.predict_batch`` at the members (sigma points, particles) ``D`` (N, n) whose
    full states are ``navs`` (N, 10): each member's body rate from ``motion.member_rates``
    (the strapdown INS: its gyro-bias deviation moves it; without ``motion`` that map) and,
    with a clock block at ``clk >= 0`` (tight coupling, pseudoranges), its clock deviation its
    receiver clock; a model with ``batch_aux`` (the multi-system pseudoranges) also gets
    each member's auxiliary states (``epoch.aux`` plus the member's deviation). Returns ``(y, Y, R)`` or None (no data); ArgumentError when the model
    has no ``predict_batch`` (``who``, the estimator, names itself in the message)."""
    predict_batch = getattr(epoch.model, "predict_batch", None)
    if predict_batch is None:
        raise ArgumentError(f"{type(epoch.model).__name__} has no predict_batch (h on a batch of states): "
                            f"{who} it", argument="measurements")
    if motion is None:
        w_b = np.asarray(epoch.w_b, dtype=float) - D[:, 9:12]
    else:
        w_b = motion.member_rates(epoch.w_b, D)
    kw = {}
    if getattr(epoch.model, "batch_aux", False) and epoch.aux:
        # each member's auxiliary states (an inter-system clock offset): nominal + deviation
        kw["aux"] = {name: np.asarray(epoch.aux[name], dtype=float) + D[:, sl]
                     for name, sl in epoch.model.layout.aux}
    if clk >= 0:
        clocks = np.asarray(epoch.clock, dtype=float) + D[:, clk:clk + 2]
        return predict_batch(epoch.index, navs, w_b, clocks, **kw)
    return predict_batch(epoch.index, navs, w_b, **kw)


class UnscentedEstimator(NoCloneEstimator):
    """The UKF's belief ``N(x, P)`` about the error state, propagated by sigma points (module docstring).

    Parameters
    ----------
    alpha, beta, kappa : float
        Scaled unscented-transform parameters (defaults 0.6, 2, 0: the points
        ``0.6 sqrt(n)`` sigma out, 2.3 sigma at 15 states; the centre's covariance
        weight 0.86 >= 0; see docs/ukf.md for why not alpha = 1).
    substeps : int
        The sigma points are mechanized over at most this many merged
        sub-intervals of each propagation step (0: every IMU increment); the
        reference point is mechanized the same way, so the merging error is common
        and cancels in the difference (docs/ukf.md).
    absurd_sigma : float
        Innovations beyond this many predicted sigmas reject the epoch (counted).
    noise : ChannelNoise, optional
        VB-adaptive measurement noise per channel (VB-AUKF).
    """

    needs_step_inputs = True
    carry_mean = True

    label = "the UKF"

    def __init__(self, alpha: float = 0.6, beta: float = 2.0, kappa: float = 0.0, substeps: int = 4,
                 absurd_sigma: float = ABSURD_SIGMA, noise: ChannelNoise | None = None):
        if not absurd_sigma > 0:
            raise ArgumentError(f"must be positive, got {absurd_sigma}", argument="absurd_sigma")
        if int(substeps) != substeps or substeps < 0:
            raise ArgumentError(f"must be an integer >= 0, got {substeps}", argument="substeps")
        ut_weights(15, alpha, beta, kappa)  # the smallest layout; init checks the run's n
        self.alpha, self.beta, self.kappa = float(alpha), float(beta), float(kappa)
        self.substeps = int(substeps)
        self.absurd_sigma = float(absurd_sigma)
        self.noise = noise
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0, "sigma_repair": 0}

    # --- the estimator protocol --------------------------------------------------------------
    def init(self, motion, P0, n_clone, rng) -> None:
        self.refuse_clone(n_clone)
        lay = motion.layout
        n = lay.n
        self.n = n
        self.motion = motion
        self._clk = lay.clk
        self._sensor = np.zeros(12)   # the engine's sensor estimates, once a step has shown them
        self.wm, self.wc, self.c = ut_weights(n, self.alpha, self.beta, self.kappa)
        N = 2 * n + 1
        self.P = np.array(P0, dtype=float)
        self.x = np.zeros(n)
        self._scratch = np.zeros((n, n))
        self._L = np.empty((n, n))
        self._D = np.empty((N, n))
        self._Dn = np.empty((N, n))
        self._navs = np.empty((N, 10))
        self._xo = np.empty(n)
        self._Po = np.empty((n, n))
        self.rng = rng
        self.counts = {"rejected_not_pd": 0, "rejected_absurd": 0, "covariance_repair": 0, "sigma_repair": 0}
        if self.noise is not None:
            self.noise.reset()

    @property
    def kernel_covariance(self) -> np.ndarray:
        """A scratch the motion model's kernel may propagate (its ``Qd`` is what is used)."""
        return self._scratch

    def predict(self, step: Transition) -> None:
        """Sigma points propagated over the step by the motion model, their moments + Qd."""
        self._scratch[:, :] = 0.0   # what the engine's kernel propagated there is not used
        inp = step.inputs
        if inp is None:
            raise ArgumentError("the UKF needs the engine's step inputs (needs_step_inputs)", argument="engine")
        self._sensor = inp.sensor
        for attempt in range(2):
            if ukf_sigma(self.x, self.P, self.c, self._L, self._D):
                break
            self._repair_sigma()
        else:
            raise NumericalError("the UKF covariance stayed not positive definite after a "
                                 "repair")  # pragma: no cover (the repair makes it PD)
        self.motion.propagate_members(inp, self._D, self.substeps, step.T, self._Dn)
        ukf_moments(self._Dn, self.wm, self.wc, step.Qd, self._xo, self._Po)
        self.x, self._xo = self._xo, self.x
        self.P, self._Po = self._Po, self.P

    def _repair_sigma(self) -> None:
        repair_covariance(self.P)
        self.P = 0.5 * (self.P + self.P.T)
        self.counts["sigma_repair"] += 1

    def recentre(self, dx: np.ndarray) -> None:
        """The nominal moved by ``dx`` (fed back by the engine): ``x -= dx``."""
        self.x = self.x - dx[:self.n]

    def sigma_points(self, nav: np.ndarray):
        """``(D, navs)``: the sigma points of the current belief about ``nav`` as error states
        (2n+1, n) and as full navigation states (2n+1, 10) (views of scratch)."""
        for attempt in range(2):
            if ukf_sigma(self.x, self.P, self.c, self._L, self._D):
                self.motion.member_states(nav, self._sensor, self._D, self._navs)
                return self._D, self._navs
            self._repair_sigma()
        raise NumericalError("the UKF covariance stayed not positive definite after a "
                             "repair")  # pragma: no cover

    def update(self, epoch: Epoch) -> Correction | None:
        D, navs = self.sigma_points(epoch.nav)
        out = predict_members(epoch, D, navs, self._clk, "the unscented filters need", self.motion)
        if out is None:
            return None
        y, Y, r = out
        r = np.asarray(r, dtype=float)
        innov, Pyy, Pxy = measurement_moments(D, np.ascontiguousarray(Y), y, self.wm, self.wc)
        m = len(y)
        nz = self.noise
        if nz is None:
            x_post, P_post, nis, status, a, b, it = vb_correct(
                self.x, self.P, Pxy, Pyy, Pyy, innov, r, r, r, False, 1, 0.0, self.absurd_sigma)
        else:
            ch_fn = getattr(epoch.model, "row_channels", None)
            channels = ch_fn(epoch.index, m) if ch_fn is not None else np.arange(m, dtype=np.int64)
            a0, b0 = nz.predicted(channels, r)
            G = linearized_pyy(self._L, Pxy)
            x_post, P_post, nis, status, a, b, it = vb_correct(
                self.x, self.P, Pxy, Pyy, G, innov, r, a0, b0, True, nz.iterations, nz.tolerance,
                self.absurd_sigma)
        if status == OK or status == NEEDS_REPAIR:
            self.x, self.P = x_post, P_post
            if nz is not None:
                nz.store(epoch.time, channels, a, b, it)
        return Correction(self.x.copy(), nis, status, m)

    def repair(self) -> None:
        repair_covariance(self.P)
        self.counts["covariance_repair"] += 1

    def covariance(self) -> np.ndarray:
        return self.P

    def diagnostics(self) -> dict:
        if self.noise is None:
            return {}
        return {f"vb_sigma_{channel_label(ch)}": s for ch, s in sorted(self.noise.sigma().items())}

    def outputs(self) -> dict:
        return {} if self.noise is None else self.noise.outputs()

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) the kernels once per process."""
        if self.noise is not None:
            warm_vb()
        if "ukf" in _WARM:
            return
        n = 15
        N = 2 * n + 1
        wm, wc, c = ut_weights(n)
        P = np.eye(n) * 1e-4
        L = np.empty((n, n))
        D = np.empty((N, n))
        ukf_sigma(np.zeros(n), P, c, L, D)
        ukf_moments(D, wm, wc, P, np.empty(n), np.empty((n, n)))
        Y = np.ascontiguousarray(D[:, 6:9])
        innov, Pyy, Pxy = measurement_moments(D, Y, np.zeros(3), wm, wc)
        linearized_pyy(L, Pxy)
        r = np.ones(3)
        vb_correct(np.zeros(n), P, Pxy, Pyy, Pyy, innov, r, r, r, False, 1, 0.0, 1e4)
        _WARM.add("ukf")


class UnscentedOptions(GateOptions):
    """``[methods.options]`` of ``estimator = "ukf"`` (docs/ukf.md): the scaled unscented
    transform's ``alpha``, ``beta``, ``kappa``; the centre point's covariance weight must not
    be negative for the method's number of states (checked when built, naming the key)."""

    alpha: float = Field(default=0.6, gt=0, description="spread of the sigma points (> 0)")
    beta: float = Field(default=2.0, description="prior-distribution weight (2: Gaussian)")
    kappa: float = Field(default=0.0, description="secondary scaling")
    substeps: int = Field(default=4, ge=0, description="merged sub-intervals the sigma points are mechanized "
                          "over per step (0: every IMU increment)")


class VbUnscentedOptions(VbOptions, UnscentedOptions):
    """``[methods.options]`` of ``estimator = "vb-aukf"``: :class:`~mixnav.filters.vb_akf.VbOptions`
    and :class:`UnscentedOptions`."""


def _build_ukf(options: UnscentedOptions, absurd_sigma: float, context):
    ut = dict(alpha=options.alpha, beta=options.beta, kappa=options.kappa, substeps=options.substeps)
    if context.motion is not None:
        ut_weights(context.motion.layout.n, options.alpha, options.beta, options.kappa)
    noise = options.channel_noise() if isinstance(options, VbOptions) else None
    return UnscentedEstimator(absurd_sigma=absurd_sigma, noise=noise, **ut)


#: every motion model: the ensemble runs on the motion seam (member_states, propagate_members, ...)
register_estimator("ukf", options=UnscentedOptions, motions=MOTIONS, can_smooth=False, build=_build_ukf,
                   description="M7 unscented Kalman filter: sigma points mechanized as full states, loose or "
                   "tight GNSS through predict_batch (options: alpha, beta, kappa, substeps)")(UnscentedEstimator)
register_estimator("vb-aukf", options=VbUnscentedOptions, motions=MOTIONS, can_smooth=False,
                   build=_build_ukf,
                   description="M7 variational-Bayes adaptive UKF (paper P5): an inverse-Gamma noise variance per "
                   "measurement channel with forgetting (options: rho, prior_shape, prior_scale, iterations, "
                   "tolerance and the UKF's)")(UnscentedEstimator)

#: The UKF on the strapdown INS (M7): ``UnscentedKalmanFilter(layout, imu_model, alpha=0.6, ...)``.
UnscentedKalmanFilter = facade("ukf", "UnscentedKalmanFilter")
#: The VB-AUKF (paper P5): ``VbAdaptiveUkf(layout, imu_model, rho=0.95, ..., alpha=0.6, ...)``.
VbAdaptiveUkf = facade("vb-aukf", "VbAdaptiveUkf")
