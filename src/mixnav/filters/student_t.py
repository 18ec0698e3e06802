"""Student-t filter with variational-Bayes noise scales (Roth, Ozkan & Gustafsson 2013;
Huang, Zhang, Li, Wu & Chambers 2017, "A novel robust Student's t-based Kalman filter").

Heavy-tailed measurement noise (and, optionally, a heavy-tailed prediction) written as a
Gaussian scale mixture: given a scale ``lambda ~ Gamma(nu/2, nu/2)`` (mean 1), the
measurement is Gaussian with covariance ``R / lambda``; integrating ``lambda`` out gives a
Student-t likelihood with ``nu`` degrees of freedom. Likewise the predicted state is
``N(x^-, P^- / xi)`` with ``xi ~ Gamma(omega/2, omega/2)`` (Huang 2017, eqs. 18-21).
The measurement update is a mean-field VB fixed point over ``q(x) q(lambda) q(xi)``
(Huang 2017, Table I), with ``dx`` the posterior mean about the prior mean and ``P+``
its covariance::

    B = e e^T + H P+ H^T,  e = z - H dx          (expected residual outer product)
    D = P+ + dx dx^T                              (expected state-error outer product)
    E[lambda]   = (nu + m) / (nu + tr(B R^-1))    one scale per epoch (Huang 2017), or
    E[lambda_i] = (nu + 1) / (nu + B_ii / r_i)    one per row (diagonal R: an NLOS
                                                  satellite is weighted down alone)
    E[xi]       = (omega + n) / (omega + tr(D (P^-)^-1))
    (dx, P+)    = Kalman update with P^- / E[xi] and R / E[lambda]

starting from the prior (``dx = 0``, ``P+ = P^-``: ``E[xi] = 1``, ``E[lambda]`` from the
prior innovation), the state updated last in each pass, until no scale changes by more
than ``tolerance`` (relative) or after ``iterations`` state updates. ``tr(D (P^-)^-1)``
is taken in closed form from the epoch's ``m x m`` quantities (no inverse of ``P^-``,
which may be singular): with ``G = H P^- H^T``, ``S = G / xi + R~`` and ``w = S^-1 z``,
``tr(P+ (P^-)^-1) = (n - tr(S^-1 G) / xi) / xi`` and ``dx^T (P^-)^-1 dx = w^T G w / xi^2``.
``nu = inf`` (and no process ``omega``) is the EKF exactly (tested bitwise).

Each state update is the compiled gated Joseph-form correction the EKF uses
(:func:`mixnav.filters._ekf_kernels.kalman_correct`); the absurd-innovation gate is
applied once, before the iteration, with the model's own ``R`` and ``P^-``. The NIS
returned is the last pass's (with the scaled noise), as the VB-AKF reports it.

Corrections only (the engine feeds them back); a stochastic clone (TDCP) is carried as
:class:`~mixnav.filters.ekf.KalmanEstimator` carries it (the augmented prior is one
Student-t); ``carry_mean`` children (IMM modes) work unchanged. The class only sees
transitions and epochs, so it runs on every motion model.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..engine.protocols import Correction, Epoch
from ..engine.status import ABSURD, NEEDS_REPAIR, OK
from ..errors import ArgumentError
from ._ekf_kernels import kalman_correct
from .ekf import KalmanEstimator
from .kalman import innovation_is_absurd
from .registry import register_estimator
from .registry import ABSURD_SIGMA

__all__ = ["StudentTEstimator", "StudentTOptions"]

_WARM: set = set()


class _OptionsCalled(type(BaseModel)):
    """Building the options by calling the class words a bad value as an ArgumentError
    naming the option; validation from a table (``model_validate``, or as a field of a
    bigger model) is untouched: pydantic's ValidationError with the key's location, which
    the config layer turns into a ConfigError naming the key."""

    def __call__(cls, *args, **options):
        try:
            return super().__call__(*args, **options)
        except ValidationError as exc:
            err = exc.errors()[0]
            key = ".".join(map(str, err["loc"])) or "options"
            what = "unknown option" if err["type"] == "extra_forbidden" else err["msg"]
            raise ArgumentError(f"{what} (got {err.get('input')!r}; options: {', '.join(cls.model_fields)})",
                                argument=key) from None


class StudentTOptions(BaseModel, metaclass=_OptionsCalled):
    """Options of ``estimator = "student-t"`` (all dimensionless)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    #: degrees of freedom of the measurement noise's Student-t (> 0; ``inf``: Gaussian).
    #: Small is heavy-tailed (3-5 is usual for urban GNSS); a row whose innovation is
    #: k predicted sigmas off gets about ``(nu + 1) / (nu + k^2)`` of its weight.
    nu: float = Field(default=5.0, gt=0)
    #: degrees of freedom of the predicted state's Student-t (Huang 2017's omega;
    #: > 0, ``inf``: Gaussian); None (default): a Gaussian prediction, no scale ``xi``.
    process_nu: float | None = Field(default=None, gt=0)
    #: "row": one scale per measurement row (needs a diagonal R); "epoch": one scale
    #: shared by all rows of an epoch (Huang 2017; any R).
    measurement_scale: Literal["row", "epoch"] = "row"
    #: at most this many state updates per epoch (>= 1).
    iterations: int = Field(default=10, ge=1)
    #: stop when no scale expectation changes by more than this, relative (>= 0).
    tolerance: float = Field(default=1e-6, ge=0)


@njit(cache=True)
def _scales_into(lam, b, r, nu, per_row):
    """``E[lambda]`` (m,) from ``B_ii`` (module docstring), written into ``lam``."""
    m = lam.shape[0]
    if per_row:
        for i in range(m):
            lam[i] = (nu + 1.0) / (nu + b[i] / r[i])
    else:
        t = 0.0
        for i in range(m):
            t += b[i] / r[i]
        for i in range(m):
            lam[i] = (nu + m) / (nu + t)


@njit(cache=True)
def _b_diagonal(b, z, H, dx, P_post):
    """``B_ii = e_i^2 + (H P+ H^T)_ii``, ``e = z - H dx``, written into ``b``."""
    m, n = H.shape
    HP = H @ P_post
    for i in range(m):
        e = z[i]
        s = 0.0
        for k in range(n):
            e -= H[i, k] * dx[k]
            s += HP[i, k] * H[i, k]
        b[i] = e * e + s


@njit(cache=True)
def _vb_diagonal(P, z, H, r, nu, per_row, iterations, tol):
    """The fixed point for a diagonal ``r`` (m,) and a Gaussian prediction, in one compiled
    call (the module docstring's loop, as :meth:`StudentTEstimator.correct` writes it):
    ``(P_post, dx, nis, status, lam, iters, hit_limit)``, ``lam`` the scales the state used."""
    m, n = H.shape
    b = np.empty(m)
    lam = np.empty(m)
    _b_diagonal(b, z, H, np.zeros(n), P)            # from the prior
    _scales_into(lam, b, r, nu, per_row)
    used = lam.copy()
    P_post, dx, nis, status = kalman_correct(P, z, H, r / used, np.inf)
    iters = 1
    while True:
        if status != OK and status != NEEDS_REPAIR:
            return P_post, dx, nis, status, used, iters, False
        if iters >= iterations:
            return P_post, dx, nis, status, used, iters, True
        _b_diagonal(b, z, H, dx, P_post)
        _scales_into(lam, b, r, nu, per_row)
        change = 0.0
        for i in range(m):
            change = max(change, abs(lam[i] - used[i]) / used[i])
        if change <= tol:
            return P_post, dx, nis, status, used, iters, False
        used = lam.copy()
        P_post, dx, nis, status = kalman_correct(P, z, H, r / used, np.inf)
        iters += 1


def _relative_change(new, old) -> float:
    return float(np.max(np.abs(np.asarray(new) - old) / np.asarray(old)))


@register_estimator("student-t", options=StudentTOptions,
                    motions=("strapdown", "dead-reckoning", "constant-velocity"),
                    description="Student-t filter with VB noise scale (Roth 2013, Huang 2017)")
class StudentTEstimator(KalmanEstimator):
    """The EKF's Gaussian updated by the Student-t VB fixed point (module docstring).

    Parameters
    ----------
    options : StudentTOptions
    absurd_sigma : float
        Innovations beyond this many predicted sigmas (model ``R``, prior ``P``) reject
        the epoch, as in :class:`~mixnav.filters.ekf.KalmanEstimator`.
    carry_mean : bool
        As :class:`~mixnav.filters.ekf.KalmanEstimator` (an IMM mode).
    """

    def __init__(self, options: StudentTOptions | None = None, absurd_sigma: float = ABSURD_SIGMA,
                 carry_mean: bool = False):
        super().__init__(absurd_sigma, carry_mean)
        if options is None:
            options = StudentTOptions()
        if not isinstance(options, StudentTOptions):
            raise ArgumentError(f"must be StudentTOptions, got {type(options).__name__}", argument="options")
        self.options = options
        self._gaussian_meas = math.isinf(options.nu)
        self._process = options.process_nu is not None and not math.isinf(options.process_nu)
        self._time = math.nan
        self._reset_trace()

    def _reset_trace(self):
        self.trace = {"time": [], "iterations": [], "process_scale": [], "min_measurement_scale": []}
        self.limit_hits = 0

    def init(self, motion, P0, n_clone, rng):
        super().init(motion, P0, n_clone, rng)
        self._reset_trace()

    def update(self, epoch: Epoch) -> Correction | None:
        self._time = epoch.time
        return super().update(epoch)

    # --- the VB fixed point ------------------------------------------------------------------
    def correct(self, P, z, H, r):
        """One epoch's update: ``(P_post, dx, nis, status)`` (no feedback; ``dx`` about the
        prior mean)."""
        o = self.options
        if self._gaussian_meas and not self._process:
            return kalman_correct(P, z, H, r, self.absurd_sigma)
        n = P.shape[0]
        m = len(z)
        r = np.asarray(r, dtype=float)
        per_row = o.measurement_scale == "row"
        if r.ndim == 2:
            if per_row:
                if np.count_nonzero(r - np.diag(np.diag(r))):
                    raise ArgumentError("a scale per row needs independent rows (diagonal R); use "
                                        "measurement_scale = \"epoch\"", argument="measurement_scale")
                r = np.ascontiguousarray(np.diag(r))
            else:
                L_R = np.linalg.cholesky(r)
        rd = r if r.ndim == 1 else np.ascontiguousarray(np.diag(r))
        if innovation_is_absurd(z, H, P, rd, self.absurd_sigma):
            return P, np.zeros(n), np.inf, ABSURD
        if r.ndim == 1 and not self._process and not self._gaussian_meas:
            P_post, dx, nis, status, lam, iters, hit = _vb_diagonal(P, z, H, r, float(o.nu), per_row,
                                                                    o.iterations, o.tolerance)
            if status != OK and status != NEEDS_REPAIR:
                return P, np.zeros(n), nis, status
            self.limit_hits += int(hit)
            self._record(iters, 1.0, float(lam.min()))
            return P_post, dx, nis, status

        def meas_scale(dx, P_post):
            if self._gaussian_meas:
                return np.ones(m) if per_row else 1.0
            e = z - H @ dx
            if per_row:
                b = e * e + (H @ P_post * H).sum(axis=1)
                return (o.nu + 1.0) / (o.nu + b / r)
            if r.ndim == 1:
                tr = float(np.sum((e * e + (H @ P_post * H).sum(axis=1)) / r))
            else:  # tr(B R^-1) = |L^-1 e|^2 + tr(L^-1 H P+ H^T L^-T)
                u = np.linalg.solve(L_R, e)
                V = np.linalg.solve(L_R, H @ P_post @ H.T)
                tr = float(u @ u) + float(np.trace(np.linalg.solve(L_R, V.T)))
            return (o.nu + m) / (o.nu + tr)

        if self._process:
            omega = o.process_nu
            G = H @ P @ H.T

        def process_scale(xi, lam):
            # tr(D (P^-)^-1) of the pass that used (xi, lam), in closed form (module docstring)
            if not self._process:
                return 1.0
            R_used = np.diag(r / lam) if r.ndim == 1 else r / lam
            S = G / xi + R_used
            SG = np.linalg.solve(S, G)
            w = np.linalg.solve(S, z)
            tr = (n - np.trace(SG) / xi) / xi + float(w @ G @ w) / (xi * xi)
            return (omega + n) / (omega + tr)

        xi = 1.0                                  # from the prior: D = P^-, tr = n
        lam = meas_scale(np.zeros(n), P)
        iters = 0
        while True:
            P_used = P if xi == 1.0 else P / xi
            P_post, dx, nis, status = kalman_correct(P_used, z, H, r / lam, np.inf)
            iters += 1
            if status != OK and status != NEEDS_REPAIR:
                return P, np.zeros(n), nis, status
            if iters >= o.iterations:
                self.limit_hits += 1
                break
            lam_new = meas_scale(dx, P_post)
            xi_new = process_scale(xi, lam)
            change = max(_relative_change(lam_new, lam), abs(xi_new - xi) / xi)
            lam, xi = lam_new, xi_new
            if change <= o.tolerance:
                break
        self._record(iters, xi, float(np.min(lam)))
        return P_post, dx, nis, status

    def _record(self, iters, xi, lam_min):
        tr = self.trace
        tr["time"].append(self._time)
        tr["iterations"].append(iters)
        tr["process_scale"].append(xi)
        tr["min_measurement_scale"].append(lam_min)

    def warm_up(self) -> None:
        """Compile (or load) the EKF's correction and the compiled fixed point once."""
        super().warm_up()
        if "student_t" in _WARM:
            return
        H = np.zeros((3, 15))
        H[:, 6:9] = np.eye(3)
        for per_row in (True, False):
            _vb_diagonal(np.eye(15), np.ones(3), H, np.ones(3), 4.0, per_row, 3, 1e-6)
        _WARM.add("student_t")

    # --- reporting ---------------------------------------------------------------------------
    def diagnostics(self) -> dict:
        it = self.trace["iterations"]
        if not it:
            return {}
        return {"student_t_iterations_mean": float(np.mean(it)), "student_t_iteration_limit": self.limit_hits}

    def outputs(self) -> dict:
        """Per VB update: ``student_t_time``, ``student_t_iterations``, ``student_t_process_scale``
        (``E[xi]``) and ``student_t_min_measurement_scale`` (smallest ``E[lambda]`` of the epoch)."""
        if not self.trace["time"]:
            return {}
        return {f"student_t_{k}": np.array(v) for k, v in self.trace.items()}
