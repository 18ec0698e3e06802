"""The second-order divided-difference filter DD2 (Norgaard, Poulsen & Ravn 2000).

A derivative-free Gaussian filter: the mean and covariance of ``f(x)`` are
taken from Stirling's interpolation formula of second order, evaluated at the
``2n + 1`` points ``x``, ``x +- h s_p`` (``s_p`` the columns of a square root
``S`` of ``P``, ``S S^T = P``; ``h`` the divided-difference step, ``h^2 = 3``
the Gaussian optimum, the paper's eq. 3.44). With ``f_0 = f(x)``,
``f_p^+- = f(x +- h s_p)`` (paper eqs. 4.7-4.12, additive noise)::

    mean  = (h^2 - n) / h^2 f_0 + 1 / (2 h^2) sum_p (f_p^+ + f_p^-)
    S1_p  = (f_p^+ - f_p^-) / (2 h)                        (first-order columns)
    S2_p  = sqrt(h^2 - 1) / (2 h^2) (f_p^+ + f_p^- - 2 f_0)  (second-order columns)
    cov   = S1 S1^T + S2 S2^T (+ Q or R, additive noise)

The measurement update (paper section 4.3): ``Pyy = Sy1 Sy1^T + Sy2 Sy2^T + R``,
``Pxy = S Sy1^T``, ``K = Pxy Pyy^-1``, ``x+ = x + K (y - y_hat)`` and the
covariance in the paper's square-root form ``P+ = (S - K Sy1)(S - K Sy1)^T +
K (Sy2 Sy2^T + R) K^T`` (= ``P - K Pyy K^T``, but a sum of outer products:
never loses positive semi-definiteness). On a linear model the second-order
columns vanish and DD2 is the Kalman filter.

Everything here is batched over ``K`` Gaussians (the components of a mixture:
:mod:`mixnav.filters.gmpf`); ``f`` and ``g`` are vectorised over rows. On the
navigation core :class:`Dd2Estimator` is a mean-carrying error-state estimator
like the UKF's (docs/ukf.md): the points become full states ``nominal (+)
D_j``, are propagated over each step by the motion model in one call (its
``propagate_members``: the strapdown INS mechanizes them, and the dead-reckoning and
constant-velocity models run theirs) and predicted by the measurement model's
``predict_batch``.
"""

from __future__ import annotations

import numpy as np

from ..engine.protocols import Correction, Epoch, Transition
from ..engine.status import ABSURD, OK
from ..errors import ArgumentError
from ._no_clone import NoCloneEstimator
from pydantic import Field

from .facade import facade
from .registry import MOTIONS, GateOptions, register_estimator
from .ukf import predict_members
from .registry import ABSURD_SIGMA

__all__ = ["DEFAULT_STEP", "check_dd2_step", "dd2_points", "dd2_moments", "dd2_time", "dd2_measure",
           "dd2_predict", "dd2_update", "psd_cholesky", "Dd2Estimator", "Dd2Filter"]

#: the divided-difference step ``h``: ``h^2 = 3`` is the kurtosis of a Gaussian (Norgaard et al. 2000)
DEFAULT_STEP = float(np.sqrt(3.0))
_LOG2PI = float(np.log(2.0 * np.pi))

_WARM: set = set()


def check_dd2_step(h, argument: str = "dd2_step") -> float:
    """``h`` as a float; ArgumentError naming ``argument`` unless ``h > 1`` and finite
    (``sqrt(h^2 - 1)`` weighs the second-order columns)."""
    try:
        h = float(h)
    except (TypeError, ValueError):
        raise ArgumentError(f"must be a number > 1, got {h!r}", argument=argument) from None
    if not (np.isfinite(h) and h > 1.0):
        raise ArgumentError(f"must be finite and > 1 (sqrt(h^2 - 1) weighs the second-order terms), got {h}",
                            argument=argument)
    return h


def psd_cholesky(P: np.ndarray):
    """``(L, repaired)``: lower Cholesky factors of ``P`` (K, n, n); a matrix that is not
    positive definite gets its eigenvalues floored at ``1e-12`` times its largest
    (at least 1e-300) first, and ``repaired`` counts those."""
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    try:
        return np.linalg.cholesky(P), 0
    except np.linalg.LinAlgError:
        pass
    L = np.empty_like(P)
    repaired = 0
    for k in range(P.shape[0]):
        try:
            L[k] = np.linalg.cholesky(P[k])
        except np.linalg.LinAlgError:
            lam, V = np.linalg.eigh(P[k])
            floor = max(1e-12 * max(float(lam[-1]), 0.0), 1e-300)
            Pk = (V * np.maximum(lam, floor)) @ V.T
            L[k] = np.linalg.cholesky(0.5 * (Pk + Pk.T))
            repaired += 1
    return L, repaired


def dd2_points(x: np.ndarray, S: np.ndarray, h: float) -> np.ndarray:
    """The points (K, 2n+1, n) of means ``x`` (K, n) and square roots ``S`` (K, n, n): row 0
    the mean, rows 1..n ``x + h s_p``, rows n+1..2n ``x - h s_p`` (``s_p`` column p of S)."""
    K, n = x.shape
    hs = h * np.swapaxes(S, 1, 2)          # row p = h s_p
    pts = np.empty((K, 2 * n + 1, n))
    pts[:, 0] = x
    pts[:, 1:n + 1] = x[:, None, :] + hs
    pts[:, n + 1:] = x[:, None, :] - hs
    return pts


def dd2_moments(Fp: np.ndarray, h: float):
    """``(mean (K, m), S1 (K, m, n), S2 (K, m, n))`` of the images ``Fp`` (K, 2n+1, m) of the
    points of :func:`dd2_points` (module docstring)."""
    n = (Fp.shape[1] - 1) // 2
    h2 = h * h
    f0 = Fp[:, 0]
    fp, fm = Fp[:, 1:n + 1], Fp[:, n + 1:]
    mean = (h2 - n) / h2 * f0 + (fp + fm).sum(axis=1) / (2.0 * h2)
    S1 = np.swapaxes((fp - fm) / (2.0 * h), 1, 2)
    S2 = np.swapaxes((fp + fm - 2.0 * f0[:, None, :]) * (np.sqrt(h2 - 1.0) / (2.0 * h2)), 1, 2)
    return mean, S1, S2


def _outer(A: np.ndarray) -> np.ndarray:
    return A @ np.swapaxes(A, 1, 2)


def dd2_time(Fp: np.ndarray, h: float, Q) -> tuple:
    """The DD2 time update ``(x (K, n), P (K, n, n))`` from the propagated points ``Fp``
    (K, 2n+1, n) and the additive process noise ``Q`` (n, n)."""
    x, S1, S2 = dd2_moments(Fp, h)
    P = _outer(S1) + _outer(S2) + np.asarray(Q, dtype=float)[None]
    return x, 0.5 * (P + np.swapaxes(P, 1, 2))


def _noise_matrix(R, m: int) -> np.ndarray:
    R = np.asarray(R, dtype=float)
    return np.diag(R) if R.ndim == 1 else R.reshape(m, m)


def dd2_measure(x: np.ndarray, S: np.ndarray, Yp: np.ndarray, y, R, h: float) -> dict:
    """The DD2 measurement update of the Gaussians ``N(x[k], S[k] S[k]^T)`` (x (K, n), S (K, n, n))
    whose points (:func:`dd2_points`) predict ``Yp`` (K, 2n+1, m) for the measurement ``y`` (m,)
    with noise ``R`` (m,) variances or (m, m).

    Returns a dict: ``x``, ``P`` the posteriors; ``y_hat`` (K, m), ``Pyy`` (K, m, m), ``e`` (K, m)
    the innovations; ``nis`` (K,) ``e^T Pyy^-1 e``; ``loglik`` (K,) ``log N(y; y_hat, Pyy)``;
    ``ok`` (K,) whether ``Pyy`` was positive definite and everything finite (a component
    with ``ok`` False keeps its prior and has ``loglik = -inf``).
    """
    K, n = x.shape
    y = np.asarray(y, dtype=float)
    m = y.shape[0]
    Rm = _noise_matrix(R, m)
    yh, Sy1, Sy2 = dd2_moments(Yp, h)
    Pyy = _outer(Sy1) + _outer(Sy2) + Rm[None]
    Pyy = 0.5 * (Pyy + np.swapaxes(Pyy, 1, 2))
    e = y[None, :] - yh
    out = {"x": x.copy(), "P": _outer(S), "y_hat": yh, "Pyy": Pyy, "e": e,
           "nis": np.full(K, np.inf), "loglik": np.full(K, -np.inf), "ok": np.zeros(K, dtype=bool)}
    finite = np.isfinite(Pyy).all(axis=(1, 2)) & np.isfinite(e).all(axis=1)
    for k in np.flatnonzero(finite):
        with np.errstate(over="ignore", invalid="ignore"):   # an absurd y: inf, flagged below
            _measure_one(k, x, S, Sy1, Sy2, Pyy, e, Rm, m, out)
    return out


def _measure_one(k, x, S, Sy1, Sy2, Pyy, e, Rm, m, out) -> None:
    """One component of :func:`dd2_measure` (written into ``out``)."""
    try:
        Ly = np.linalg.cholesky(Pyy[k])
    except np.linalg.LinAlgError:
        return
    Pxy = S[k] @ Sy1[k].T                                   # (n, m)
    # K = Pxy Pyy^-1 through the Cholesky factor (no inverse)
    G = np.linalg.solve(Ly, Pxy.T)                           # Ly^-1 Pxy^T
    Kg = np.linalg.solve(Ly.T, G).T                          # (n, m)
    v = np.linalg.solve(Ly, e[k])
    A = S[k] - Kg @ Sy1[k]
    B = Kg @ Sy2[k]
    C = Kg @ Rm
    Pk = A @ A.T + B @ B.T + C @ Kg.T
    out["x"][k] = x[k] + Kg @ e[k]
    out["P"][k] = 0.5 * (Pk + Pk.T)
    out["nis"][k] = float(v @ v)
    out["loglik"][k] = -0.5 * (float(v @ v) + 2.0 * float(np.log(np.diag(Ly)).sum()) + m * _LOG2PI)
    out["ok"][k] = bool(np.isfinite(out["x"][k]).all() and np.isfinite(Pk).all()
                        and np.isfinite(out["nis"][k]))
    if not out["ok"][k]:
        out["x"][k], out["P"][k], out["loglik"][k] = x[k], _outer(S[k:k + 1])[0], -np.inf


def _batched(x, P):
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    single = x.ndim == 1
    return (x[None], P[None], single) if single else (x, P, single)


def dd2_predict(x, P, f, Q, h: float = DEFAULT_STEP):
    """One DD2 time update of ``N(x, P)`` through ``f`` (a function of a (M, n) array of
    states, row by row, returning (M, n)) with additive process noise ``Q`` (n, n).
    ``x`` (n,) or (K, n), ``P`` (n, n) or (K, n, n): one Gaussian or a batch of them.
    Returns ``(x, P)`` of the same shapes."""
    xb, Pb, single = _batched(x, P)
    K, n = xb.shape
    L, _ = psd_cholesky(Pb)
    pts = dd2_points(xb, L, h)
    Fp = np.asarray(f(pts.reshape(-1, n)), dtype=float).reshape(K, 2 * n + 1, n)
    xn, Pn = dd2_time(Fp, h, Q)
    return (xn[0], Pn[0]) if single else (xn, Pn)


def dd2_update(x, P, g, y, R, h: float = DEFAULT_STEP) -> dict:
    """One DD2 measurement update of ``N(x, P)`` (shapes as :func:`dd2_predict`) with the
    measurement function ``g`` ((M, n) -> (M, m)), the measurement ``y`` (m,) and its noise
    ``R`` ((m,) variances or (m, m)). Returns :func:`dd2_measure`'s dict (a single Gaussian's
    entries without the leading K axis)."""
    xb, Pb, single = _batched(x, P)
    K, n = xb.shape
    L, _ = psd_cholesky(Pb)
    pts = dd2_points(xb, L, h)
    Yp = np.asarray(g(pts.reshape(-1, n)), dtype=float)
    Yp = Yp.reshape(K, 2 * n + 1, -1)
    out = dd2_measure(xb, L, Yp, y, R, h)
    return {k: v[0] for k, v in out.items()} if single else out


class Dd2Estimator(NoCloneEstimator):
    """The DD2 filter's belief ``N(x, P)`` about the error state (module docstring).

    Parameters
    ----------
    dd2_step : float
        The divided-difference step ``h`` (> 1; default sqrt(3)).
    substeps : int
        The points are mechanized over at most this many merged sub-intervals of each
        propagation step (0: every IMU increment), as the UKF's.
    absurd_sigma : float
        An epoch whose innovation exceeds this many predicted sigmas per row is rejected.
    """

    needs_step_inputs = True
    carry_mean = True

    label = "the DD2 filter"

    def __init__(self, dd2_step: float = DEFAULT_STEP, substeps: int = 4, absurd_sigma: float = ABSURD_SIGMA):
        self.h = check_dd2_step(dd2_step)
        if int(substeps) != substeps or substeps < 0:
            raise ArgumentError(f"must be an integer >= 0, got {substeps}", argument="substeps")
        if not absurd_sigma > 0:
            raise ArgumentError(f"must be positive, got {absurd_sigma}", argument="absurd_sigma")
        self.substeps = int(substeps)
        self.absurd_sigma = float(absurd_sigma)
        self.counts = {"sigma_repair": 0, "covariance_repair": 0}

    # --- the estimator protocol --------------------------------------------------------------
    def init(self, motion, P0, n_clone, rng) -> None:
        self.refuse_clone(n_clone)
        lay = motion.layout
        self.n = n = lay.n
        self.motion = motion
        self._clk = lay.clk
        self._sensor = np.zeros(12)   # the engine's sensor estimates, once a step has shown them
        self.x = np.zeros(n)
        self.P = np.array(P0, dtype=float)
        self._scratch = np.zeros((n, n))
        self.rng = rng
        self.counts = {"sigma_repair": 0, "covariance_repair": 0}

    @property
    def kernel_covariance(self) -> np.ndarray:
        """A scratch the motion model's kernel may propagate (its ``Qd`` is what is used)."""
        return self._scratch

    def _points(self):
        L, rep = psd_cholesky(self.P[None])
        self.counts["sigma_repair"] += rep
        return dd2_points(self.x[None], L, self.h), L

    def predict(self, step: Transition) -> None:
        """The points mechanized over the step's block (one compiled call), DD2 moments + Qd."""
        self._scratch[:, :] = 0.0
        inp = step.inputs
        if inp is None:
            raise ArgumentError("the DD2 filter needs the engine's step inputs (needs_step_inputs)",
                                argument="engine")
        self._sensor = inp.sensor
        pts, _ = self._points()
        x, P = dd2_time(mechanize_points(inp, pts, self.substeps, self.motion, step.T), self.h, step.Qd)
        self.x, self.P = x[0], P[0]

    def recentre(self, dx: np.ndarray) -> None:
        """The nominal moved by ``dx`` (fed back by the engine): ``x -= dx``."""
        self.x = self.x - dx[:self.n]

    def update(self, epoch: Epoch) -> Correction | None:
        pts, L = self._points()
        out = predict_points(epoch, pts, self.motion, self._sensor, self._clk, "the DD2 filter needs")
        if out is None:
            return None
        y, Yp, r = out
        res = dd2_measure(self.x[None], L, Yp, y, r, self.h)
        m = len(y)
        nis = float(res["nis"][0])
        if not res["ok"][0] or not nis <= m * self.absurd_sigma ** 2:
            return Correction(np.zeros(self.n), np.inf, ABSURD, m)
        self.x, self.P = res["x"][0], res["P"][0]
        return Correction(self.x.copy(), nis, OK, m)

    def mean(self) -> np.ndarray:
        return self.x

    def covariance(self) -> np.ndarray:
        return self.P

    def warm_up(self) -> None:
        """Nothing of its own to compile: the members' kernels are the motion model's (numpy
        moments here)."""


def mechanize_points(inp, pts: np.ndarray, substeps: int, motion, T: float) -> np.ndarray:
    """The points ``pts`` (K, M, n) (error states about the nominal before the step,
    :class:`~mixnav.engine.protocols.StepInputs` ``inp``) propagated over the step by
    ``motion.propagate_members`` (for the INS one compiled call); their error states about
    the propagated nominal, (K, M, n)."""
    K, M, n = pts.shape
    D = np.ascontiguousarray(pts.reshape(K * M, n))
    Dn = np.empty((K * M, n))
    motion.propagate_members(inp, D, substeps, T, Dn)
    return Dn.reshape(K, M, n)


def predict_points(epoch: Epoch, pts: np.ndarray, motion, sensor, clk: int, who: str):
    """``(y (m,), Y (..., m), r (m,))``: the measurement model's predictions at the points
    ``pts`` (..., n) (error states about ``epoch.nav`` and the sensor estimates ``sensor``,
    full states by ``motion.member_states``) by one ``predict_batch`` call; None without
    data."""
    shape = pts.shape[:-1]
    D = np.ascontiguousarray(pts.reshape(-1, pts.shape[-1]))
    navs = np.empty((D.shape[0], 10))
    motion.member_states(epoch.nav, sensor, D, navs)
    out = predict_members(epoch, D, navs, clk, who, motion)
    if out is None:
        return None
    y, Y, r = out
    y = np.asarray(y, dtype=float)
    return y, np.asarray(Y, dtype=float).reshape(*shape, len(y)), np.asarray(r, dtype=float)


class Dd2Options(GateOptions):
    """``[methods.options]`` of ``estimator = "dd2"`` (docs/particle.md)."""

    dd2_step: float = Field(default=DEFAULT_STEP, gt=1, description="divided-difference step (> 1; sqrt(3) "
                            "the Gaussian optimum)")
    substeps: int = Field(default=4, ge=0, description="merged sub-intervals the points are mechanized over "
                          "per step (0: every IMU increment)")


#: every motion model: the ensemble runs on the motion seam (member_states, propagate_members, ...)
register_estimator("dd2", options=Dd2Options, motions=MOTIONS, can_smooth=False,
                   build=lambda o, absurd_sigma, context: Dd2Estimator(o.dd2_step, o.substeps, absurd_sigma),
                   description="second-order divided-difference filter (Norgaard et al. 2000; issue 19): 2n+1 "
                   "points mechanized as full states (options: dd2_step, substeps)")(Dd2Estimator)

#: The DD2 filter on the strapdown INS: ``Dd2Filter(layout, imu_model, dd2_step=sqrt(3), substeps=4, ...)``.
Dd2Filter = facade("dd2", "Dd2Filter")
