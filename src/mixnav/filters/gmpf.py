"""The Gaussian-mixture particle filter (GMPF, paper P3; SPEC M8) on the one navigation core.

The belief about the error state ``dx = x_true - x_est`` (the layout's states,
as the UKF's and the particle filter's: docs/ukf.md) is a Gaussian mixture
``sum_g alpha_g N(mu_g, P_g)`` of at most ``components`` (K) components
(P3 eq. 15). It carries its mean (``carry_mean``); the engine feeds each
correction back and calls :meth:`GmpfEstimator.recentre`.

- **Time update** (P3 eq. 18): every component by a DD2 time update
  (:mod:`mixnav.filters.dd2`): the ``K (2n + 1)`` points of all components are
  mechanized as full states over the step's IMU block in one compiled call,
  plus the transition's ``Qd`` (one process-noise component, I = 1). The
  weights are kept.
- **Importance density** (P3 eq. 19, section 3.2): every component by a DD2
  measurement update with the newest measurement (one ``predict_batch`` call
  for all points); the component weights become ``alpha_g N(y; y_hat_g,
  Pyy_g)`` normalised (the Gaussian-sum filter's; one measurement-noise
  component, J = 1). This mixture ``q`` is the importance density.
- **Measurement update** (P3 section 3.4.2): ``N`` particles are drawn from
  ``q`` (``sampling = "matched"``, the default: systematic component counts and
  each component's normals whitened to its exact mean and covariance;
  ``"iid"``: multinomial counts and independent normals, P3 literally; see
  below why the default is not P3's); their
  predictions come from one more ``predict_batch`` call; each log-weight is
  ``log p(y | chi) + log p_G(chi | y_1:k-1) - log q(chi)`` (Gaussian
  likelihood with the model's variances; the predicted mixture and ``q``
  evaluated in log space, ``logsumexp`` over components), normalised after
  subtracting the maximum. The weighted mean (P3 eq. 20) is returned as the
  correction, the weighted covariance (eq. 21) is what the EM fit keeps.
- **Weighted EM instead of resampling** (P3 section 3.3, step 3): a K-component
  mixture is fitted to the weighted particles by the noise toolkit's learner
  (:class:`mixnav.noise.learn.em.EMGaussianMixture`, ``sample_weight`` = the
  importance weights, at most ``em_iterations`` iterations, started from each
  particle's responsibilities under ``q``: the components keep their identity from
  epoch to epoch; k-means++ from the estimator's stream while ``q`` has fewer
  than K components, i.e. at the first epoch). The fit runs on the particles standardised by
  the importance density's per-state spread (error states span 1e-6 rad/s to
  metres; the learner's ``reg_covar`` is absolute). Its M-step keeps the
  weighted mean and covariance of the particles exactly, so the new mixture
  has the moments of eqs. 20-21. It is the next epoch's prior; the next
  particles are drawn from its DD2 update.

Why matched draws: the refit keeps the weighted sample covariance of the
particles, and a sample covariance of N iid draws in n dimensions spreads its
eigenvalues (the smallest shrink by about ``(1 - sqrt(n / N))^2``, 0.6 at n =
15, N = 300). Refitted every epoch, that bias accumulates in the weakly
observable directions (attitude, sensor biases) and the filter becomes
overconfident: on loose-demo with 300 particles and 3 components, iid draws
diverged on one filter seed of three (28 m position RMS, NEES 111; at 1000
particles 2.7 m, NEES 4.3) while matched draws stayed at the EKF's level
(2.55 m, NEES 3.8; docs/particle.md). Matched draws remove the Monte Carlo
error of the Gaussian part; the importance weights still carry what the
Gaussian densities miss.

Recoveries (``counts``), never a NaN:

- ``gmpf_fewer_components``: a full covariance in n states needs at least
  ``n + 1`` effective samples, so the fit uses ``min(K, floor(ESS / (n + 1)))``
  components (at least one) when the effective sample size ``1 / sum w^2`` is
  small;
- ``gmpf_em_fallback``: the EM fit failed (a component collapsed): the one
  Gaussian with the particles' weighted mean and covariance is kept;
- ``gmpf_degenerate``: no importance weight is finite: the importance density
  ``q`` itself (the DD2 Gaussian-sum update) is the posterior;
- an epoch that no component can explain (every innovation beyond
  ``absurd_sigma`` sigmas per row, or non-finite) is rejected (``ABSURD``,
  counted by the engine as ``rejected_absurd``); the predicted mixture is kept;
- ``sigma_repair``: a component covariance that was not positive definite
  (eigenvalues floored) before its points were drawn.

Randomness: only the ``rng`` the engine hands to :meth:`GmpfEstimator.init`.
"""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from ..engine.protocols import Correction, Epoch, Transition
from ..engine.status import ABSURD, OK
from ..errors import ArgumentError
from ..noise.learn import ConvergenceWarning
from ..noise.learn.em import EMGaussianMixture, gaussian_logpdf
from ._no_clone import NoCloneEstimator
from .dd2 import (DEFAULT_STEP, Dd2Options, check_dd2_step, dd2_measure, dd2_points, dd2_time, mechanize_points,
                  predict_points, psd_cholesky)
from .facade import facade
from .registry import MOTIONS, register_estimator
from .registry import ABSURD_SIGMA

__all__ = ["GmpfEstimator", "GaussianMixtureParticleFilter", "check_gmpf_settings", "mixture_logpdf",
           "fit_weighted_mixture"]

#: covariance floor of the EM fit in standardised units (variance 1 per state): negligible
EM_REG_COVAR = 1e-6
#: EM stops earlier when the weighted mean log-likelihood changes by less than this
EM_TOL = 1e-5


SAMPLING = ("iid", "matched")


def check_gmpf_settings(particles, components, em_iterations, dd2_step, substeps=4, absurd_sigma=ABSURD_SIGMA,
                        sampling="matched") -> None:
    """ArgumentError naming the key of a setting out of range."""
    if not _is_int(particles) or particles < 2:
        raise ArgumentError(f"must be an integer >= 2, got {particles}", argument="particles")
    if not _is_int(components) or components < 1:
        raise ArgumentError(f"must be an integer >= 1, got {components}", argument="components")
    if components > particles:
        raise ArgumentError(f"must not exceed particles ({particles}), got {components}", argument="components")
    if not _is_int(em_iterations) or em_iterations < 1:
        raise ArgumentError(f"must be an integer >= 1, got {em_iterations}", argument="em_iterations")
    check_dd2_step(dd2_step, "dd2_step")
    if not _is_int(substeps) or substeps < 0:
        raise ArgumentError(f"must be an integer >= 0, got {substeps}", argument="substeps")
    if not absurd_sigma > 0:
        raise ArgumentError(f"must be positive, got {absurd_sigma}", argument="absurd_sigma")
    if sampling not in SAMPLING:
        raise ArgumentError(f"must be one of {', '.join(SAMPLING)}, got {sampling!r}", argument="sampling")


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool) or (
        isinstance(v, float) and float(v).is_integer())


def logsumexp_rows(a: np.ndarray) -> np.ndarray:
    """``log sum_k exp(a[:, k])`` (N,) of finite-or-minus-infinity log terms (N, K) (scipy's
    ``logsumexp`` costs about 1 ms per call at N = 2000 here; this is the same formula)."""
    top = a.max(axis=1)
    safe = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return safe + np.log(np.exp(a - safe[:, None]).sum(axis=1))


def mixture_logpdf(X: np.ndarray, weights: np.ndarray, means: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """``log sum_g w_g N(x_n; mu_g, L_g L_g^T)`` for the rows of ``X`` (N, n), (N,);
    ``chol`` (K, n, n) lower Cholesky factors; zero weights are skipped."""
    keep = weights > 0
    lp = gaussian_logpdf(X, means[keep], chol[keep]) + np.log(weights[keep])[None, :]
    return logsumexp_rows(lp)


def fit_weighted_mixture(X: np.ndarray, w: np.ndarray, components: int, iterations: int, rng, scale=None,
                         resp=None):
    """A ``components``-Gaussian mixture fitted by weighted EM to the samples ``X`` (N, n) with
    normalised weights ``w`` (N,): ``(weights (K,), means (K, n), covariances (K, n, n), status)``.

    The fit runs on ``(X - mean_w) / scale`` (``scale`` (n,), default the weighted standard
    deviations) and is mapped back. EM starts from the responsibilities ``resp`` (N, K) when
    given with K columns (a warm start: the mixture the samples were drawn from), else from a
    k-means++ seeding drawn from ``rng``. ``status``: ``"ok"``; ``"fewer"`` when the effective sample
    size allowed fewer components (at least ``n + 1`` effective samples each); ``"fallback"``
    when EM failed (a collapsed component) and the weighted mean and covariance are returned
    as one Gaussian.
    """
    N, n = X.shape
    m = w @ X
    Xc = X - m
    C = (Xc * w[:, None]).T @ Xc
    C = 0.5 * (C + C.T)
    if scale is None:
        scale = np.sqrt(np.maximum(np.diag(C), 0.0))
    scale = np.where(scale > 0, scale, 1.0)
    ess = 1.0 / float(w @ w)
    K = max(1, min(int(components), int(ess // (n + 1))))
    status = "fewer" if K < components else "ok"
    if K == 1:
        return np.ones(1), m[None], C[None], status
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            init = resp if resp is not None and resp.shape == (N, K) else "kmeans++"
            em = EMGaussianMixture(n_components=K, tol=EM_TOL, max_iter=int(iterations), reg_covar=EM_REG_COVAR,
                                   init=init, random_state=rng).fit(Xc / scale, sample_weight=w)
    except ValueError:
        return np.ones(1), m[None], C[None], "fallback"
    means = m + em.means_ * scale
    covs = em.covariances_ * scale[None, :, None] * scale[None, None, :]
    return em.weights_ / em.weights_.sum(), means, 0.5 * (covs + np.swapaxes(covs, 1, 2)), status


class GmpfEstimator(NoCloneEstimator):
    """The GMPF's belief: a Gaussian mixture over the error state (module docstring).

    Parameters
    ----------
    particles : int
        Particles drawn from the importance density per measurement epoch (>= 2).
    components : int
        Mixture components K (1 <= K <= particles).
    em_iterations : int
        Most EM iterations of the refit per epoch (>= 1).
    dd2_step : float
        The DD2 step ``h`` (> 1; default sqrt(3)).
    substeps : int
        Merged sub-intervals the DD2 points are mechanized over per step (as the UKF's).
    absurd_sigma : float
        An epoch no component can explain within this many sigmas per row is rejected.
    sampling : {"iid", "matched"}
        How the particles are drawn from the importance density (:meth:`_draws`): each
        component's draws matched to its mean and covariance (default), or independently (P3).
    """

    needs_step_inputs = True
    carry_mean = True

    label = "the GMPF"

    def __init__(self, particles: int = 1000, components: int = 3, em_iterations: int = 10,
                 dd2_step: float = DEFAULT_STEP, substeps: int = 4, absurd_sigma: float = ABSURD_SIGMA,
                 sampling: str = "matched"):
        check_gmpf_settings(particles, components, em_iterations, dd2_step, substeps, absurd_sigma, sampling)
        self.sampling = sampling
        self.N = int(particles)
        self.K = int(components)
        self.em_iterations = int(em_iterations)
        self.h = float(dd2_step)
        self.substeps = int(substeps)
        self.absurd_sigma = float(absurd_sigma)
        self.counts = self._fresh_counts()
        self.ess_history: list = []

    @staticmethod
    def _fresh_counts() -> dict:
        return {"gmpf_degenerate": 0, "gmpf_em_fallback": 0, "gmpf_fewer_components": 0, "sigma_repair": 0,
                "covariance_repair": 0}

    # --- the estimator protocol --------------------------------------------------------------
    def init(self, motion, P0, n_clone, rng) -> None:
        self.refuse_clone(n_clone)
        lay = motion.layout
        self.n = lay.n
        self.motion = motion
        self._clk = lay.clk
        self._sensor = np.zeros(12)   # the engine's sensor estimates, once a step has shown them
        self.rng = rng
        self.start(np.array(P0, dtype=float))

    def start(self, P0: np.ndarray) -> None:
        """The prior: one component ``N(0, P0)`` (the first refit splits it into K)."""
        n = P0.shape[0]
        self.n = n
        self.alpha = np.ones(1)
        self.mu = np.zeros((1, n))
        self.P = P0[None].copy()
        self.D = np.zeros((0, n))
        self.w = np.zeros(0)
        self._scratch = np.zeros((n, n))
        self.counts = self._fresh_counts()
        self.ess_history = []

    @property
    def kernel_covariance(self) -> np.ndarray:
        return self._scratch

    def points(self):
        """``(pts (K, 2n+1, n), L (K, n, n))``: every component's DD2 points and square root
        (a covariance that is not positive definite is repaired first, counted)."""
        L, rep = psd_cholesky(self.P)
        self.counts["sigma_repair"] += rep
        return dd2_points(self.mu, L, self.h), L

    def predict(self, step: Transition) -> None:
        """Every component by a DD2 time update (all points mechanized in one compiled call)."""
        self._scratch[:, :] = 0.0
        inp = step.inputs
        if inp is None:
            raise ArgumentError("the GMPF needs the engine's step inputs (needs_step_inputs)", argument="engine")
        self._sensor = inp.sensor
        pts, _ = self.points()
        self.mu, self.P = dd2_time(mechanize_points(inp, pts, self.substeps, self.motion, step.T), self.h, step.Qd)

    def predict_linear(self, F: np.ndarray, Q: np.ndarray) -> None:
        """The time update through the linear map ``x -> F x`` with process noise ``Q`` (tests on
        linear-Gaussian models)."""
        pts, _ = self.points()
        self.mu, self.P = dd2_time(pts @ np.asarray(F, float).T, self.h, Q)

    def recentre(self, dx: np.ndarray) -> None:
        """The nominal moved by ``dx``: every component mean and particle shifts by ``-dx``."""
        self.mu = self.mu - dx[:self.n]
        self.D = self.D - dx[:self.n]

    def update(self, epoch: Epoch) -> Correction | None:
        pts, L = self.points()
        who = "the GMPF needs"
        out = predict_points(epoch, pts, self.motion, self._sensor, self._clk, who)
        if out is None:
            return None
        y, Yp, r = out

        def predict(D):
            return predict_points(epoch, D, self.motion, self._sensor, self._clk, who)[1]
        return self.weigh(y, r, pts, L, Yp, predict)

    def update_linear(self, y: np.ndarray, H: np.ndarray, r: np.ndarray) -> Correction:
        """The measurement update with ``y = H x + v``, ``v ~ N(0, diag(r))`` (tests)."""
        pts, L = self.points()
        H = np.asarray(H, float)
        return self.weigh(np.asarray(y, float), np.asarray(r, float), pts, L, pts @ H.T, lambda D: D @ H.T)

    def weigh(self, y, r, pts, L, Yp, predict) -> Correction:
        """The measurement update (module docstring): the DD2 importance density from the
        component points ``pts`` (K, 2n+1, n) (square roots ``L``) and their predictions ``Yp``
        (K, 2n+1, m) of ``y`` (m,) with noise variances ``r`` (m,); particles drawn from it and
        predicted by ``predict`` ((N, n) -> (N, m)); weights; the weighted EM refit."""
        n, m = self.n, len(y)
        res = dd2_measure(self.mu, L, Yp, y, r, self.h)
        ok = res["ok"]
        if not ok.any() or not np.nanmin(np.where(ok, res["nis"], np.inf)) <= m * self.absurd_sigma ** 2:
            return Correction(np.zeros(n), np.inf, ABSURD, m)
        nis = self._mixture_nis(y, res, ok)
        # importance density q: the DD2 posteriors weighted by alpha_g N(y; y_hat_g, Pyy_g)
        with np.errstate(divide="ignore"):
            la = np.where(ok, np.log(self.alpha) + res["loglik"], -np.inf)
        beta = np.exp(la - la.max())   # some component is ok: the maximum is finite
        beta /= beta.sum()
        keep = beta > 0
        beta, qmu, qP = beta[keep] / beta[keep].sum(), res["x"][keep], res["P"][keep]
        qL, rep = psd_cholesky(qP)
        self.counts["sigma_repair"] += rep
        # particles: component counts, then Gaussian draws (the estimator's stream only)
        counts, Z = self._draws(beta)
        D = np.empty((self.N, n))
        start = 0
        for c, cnt in enumerate(counts):   # the draws of a component are contiguous
            D[start:start + cnt] = qmu[c] + Z[start:start + cnt] @ qL[c].T
            start += cnt
        Yd = np.asarray(predict(D), dtype=float)
        # weights (P3 3.4.2): likelihood x predicted mixture / importance mixture, in log space,
        # with both mixtures in the same standardised coordinates (the Jacobian cancels)
        qm = beta @ qmu
        qcov = np.einsum("k,kij->ij", beta, qP) + ((qmu - qm).T * beta) @ (qmu - qm)
        s = np.sqrt(np.maximum(np.diag(qcov), 1e-300))
        Ds = (D - qm) / s
        with np.errstate(all="ignore"):
            loglik = -0.5 * (((y[None, :] - Yd) ** 2) / r[None, :]).sum(axis=1)
            lq = gaussian_logpdf(Ds, (qmu - qm) / s, qL / s[None, :, None]) + np.log(beta)[None, :]
            logq = logsumexp_rows(lq)
            logw = loglik + mixture_logpdf(Ds, self.alpha, (self.mu - qm) / s, L / s[None, :, None]) - logq
        finite = np.isfinite(logw)
        if not finite.any():
            self.counts["gmpf_degenerate"] += 1
            self.alpha, self.mu, self.P = beta, qmu, qP
            self.D, self.w = D, np.full(self.N, 1.0 / self.N)
            return Correction(qm.copy(), nis, OK, m)
        top = logw[finite].max()
        w = np.where(finite, np.exp(np.where(finite, logw, top) - top), 0.0)
        w /= w.sum()
        self.ess_history.append(float(1.0 / (w @ w)))
        # EM warm start: each particle's responsibilities under q (when q has K components)
        resp = np.exp(lq - logq[:, None]) if len(beta) == self.K else None
        alpha, mu, P, status = fit_weighted_mixture(D, w, self.K, self.em_iterations, self.rng, scale=s, resp=resp)
        if status == "fewer":
            self.counts["gmpf_fewer_components"] += 1
        elif status == "fallback":
            self.counts["gmpf_em_fallback"] += 1
        self.alpha, self.mu, self.P = alpha, mu, P
        self.D, self.w = D, w
        return Correction(w @ D, nis, OK, m)

    def _draws(self, beta: np.ndarray):
        """``(counts (K,), Z (N, n))``: particles per component and their standard normals.
        ``sampling = "iid"``: multinomial counts, independent normals (P3). ``"matched"``:
        systematic counts (``floor`` or ``ceil`` of ``N beta_k``) and each component's normals
        centred and whitened to a zero sample mean and identity sample covariance (when it has
        at least n + 1 particles), so that uniform weights reproduce q's moments exactly."""
        N, n = self.N, self.n
        if self.sampling == "iid":
            return self.rng.multinomial(N, beta), self.rng.standard_normal((N, n))
        edges = np.floor(np.cumsum(beta) * N + float(self.rng.random())).astype(int)
        edges[-1] = N   # round-off: the last bin closes at N
        counts = np.diff(np.concatenate([[0], edges]))
        Z = self.rng.standard_normal((N, n))
        start = 0
        for c in counts:
            if c > n:
                Zc = Z[start:start + c]
                Zc -= Zc.mean(axis=0)
                Lc = np.linalg.cholesky(Zc.T @ Zc / c)
                Z[start:start + c] = np.linalg.solve(Lc, Zc.T).T
            start += c
        return counts, Z

    def _mixture_nis(self, y: np.ndarray, res: dict, ok: np.ndarray) -> float:
        """NIS of the epoch: innovation of the prior-weighted mean prediction, ``S`` the
        prediction mixture's covariance (the components that could be updated)."""
        a = self.alpha[ok] / self.alpha[ok].sum()
        yh, Pyy = res["y_hat"][ok], res["Pyy"][ok]
        ym = a @ yh
        S = np.einsum("k,kij->ij", a, Pyy) + ((yh - ym).T * a) @ (yh - ym)
        e = y - ym
        try:
            v = np.linalg.solve(np.linalg.cholesky(S), e)
        except np.linalg.LinAlgError:  # pragma: no cover (a sum of positive definite Pyy)
            return np.inf
        return float(v @ v)

    def mean(self) -> np.ndarray:
        return self.alpha @ self.mu

    def covariance(self) -> np.ndarray:
        m = self.alpha @ self.mu
        d = self.mu - m
        return np.einsum("k,kij->ij", self.alpha, self.P) + (d.T * self.alpha) @ d

    def warm_up(self) -> None:
        """Nothing of its own to compile: the members' kernels are the motion model's."""


class GmpfOptions(Dd2Options):
    """``[methods.options]`` of ``estimator = "gmpf"`` (docs/particle.md): the DD2 settings and these."""

    particles: int = Field(default=1000, ge=2, description="particles drawn per epoch")
    components: int = Field(default=3, ge=1, description="mixture components (1 to particles)")
    em_iterations: int = Field(default=10, ge=1, description="most iterations of the weighted-EM refit")
    sampling: Literal["iid", "matched"] = Field(default="matched", description="how the particles are drawn")

    @field_validator("components")
    @classmethod
    def _at_most_particles(cls, v, info):
        n = info.data.get("particles")
        if n is not None and v > n:
            raise ValueError(f"must not exceed particles ({n}), got {v}")
        return v


def _build_gmpf(o: GmpfOptions, absurd_sigma: float, context):
    from .particle import check_particle_memory
    check_particle_memory(o.particles, context.motion)
    return GmpfEstimator(particles=o.particles, components=o.components, em_iterations=o.em_iterations,
                         dd2_step=o.dd2_step, substeps=o.substeps, sampling=o.sampling, absurd_sigma=absurd_sigma)


#: every motion model: the ensemble runs on the motion seam (member_states, propagate_members, ...)
register_estimator("gmpf", options=GmpfOptions, motions=MOTIONS, can_smooth=False, build=_build_gmpf,
                   description="M8 Gaussian-mixture particle filter (paper P3): DD2 per mixture component builds "
                   "the importance density, weighted EM refit instead of resampling (options: particles, "
                   "components, em_iterations, dd2_step, substeps, sampling)")(GmpfEstimator)

#: The GMPF on the strapdown INS (M8, paper P3): ``GaussianMixtureParticleFilter(layout, imu_model, ...)``.
GaussianMixtureParticleFilter = facade("gmpf", "GaussianMixtureParticleFilter")
