"""Fixed-interval Rauch-Tung-Striebel smoother of the closed-loop error-state filter.

The forward run (``Engine(..., history=True)``) keeps per event ``Phi``,
``P_pred``, ``P_filt``, the correction ``dx`` fed back and the nominal after
the feedback (:class:`~mixnav.engine.result.History`). Because the filter is
closed loop, its filtered error mean is zero about the post-feedback nominal
and its predicted mean zero about the pre-feedback one, so the RTS recursion
reduces to (docs/smoother.md derives it)::

    G_k    = P_filt(k) Phi(k+1)^T P_pred(k+1)^-1
    d_s(k) = G_k (d_s(k+1) + dx(k+1))
    P_s(k) = P_filt(k) + G_k (P_s(k+1) - P_pred(k+1)) G_k^T
    d_s(E-1) = 0,  P_s(E-1) = P_filt(E-1)

with ``d_s(k)`` the smoothed error about the post-feedback nominal at ``k``
(``dx = x_true - x_est``); the smoothed state is that nominal with ``d_s(k)``
injected. ``P_pred(k+1)^-1`` is applied through its Cholesky factor, never
inverted.

- :func:`rts_backward`: the recursion on plain arrays (one compiled call);
- :func:`rts_smooth`: a :class:`~mixnav.engine.result.FilterResult` in, the
  smoothed one out at the same output epochs.

Recovery (counted in ``recoveries["smoother_not_pd"]``, never NaN): when
``P_pred(k+1)`` is not numerically positive definite the step retries with
``eps I`` added, ``eps = 1e-12, 1e-10, ..., 1e-4`` times its largest variance;
if none of these factors, the step is skipped: the smoothed solution restarts
from the filtered one at ``k`` (``d_s(k) = 0``, ``P_s(k) = P_filt(k)``), which
is still a valid (filtered) estimate.
"""

from __future__ import annotations

import math
import time as _time

import numpy as np
from numba import njit

from ..errors import ArgumentError
from ..ins._error_kernels import apply_feedback
from ..linalg import cholesky_lower
from .result import FilterResult

#: Relative jitter tried, in turn, on a P_pred that does not factor (times its largest variance).
JITTER = np.array([1e-12, 1e-10, 1e-8, 1e-6, 1e-4])


@njit(cache=True)
def _factor(A, L, jitter):
    """Cholesky factor of ``A`` into ``L``; on failure retry with ``A + eps I`` for each
    relative ``eps`` of ``jitter``. Returns 0 (factored as is), 1 (with jitter), 2 (failed)."""
    if cholesky_lower(A, L):
        return 0
    n = A.shape[0]
    top = 0.0
    for i in range(n):
        if A[i, i] > top:
            top = A[i, i]
    if not (top > 0.0) or not math.isfinite(top):
        return 2
    B = A.copy()
    for eps in jitter:
        for i in range(n):
            B[i, i] = A[i, i] + eps * top
        if cholesky_lower(B, L):
            return 1
    return 2


@njit(cache=True)
def _backward(Phi, P_pred, P_filt, dx, slot, jitter, d_out, P_out):
    """The recursion (see the module docstring), in place; returns the number of
    steps whose ``P_pred`` needed jitter or was skipped.

    ``slot[k]`` is the row of ``P_out`` that receives ``P_s(k)``, or -1.
    """
    E, n = dx.shape[0], dx.shape[1]
    Ps = P_filt[E - 1].copy()  # P_s(k+1), carried
    d = np.zeros(n)            # d_s(k+1), carried
    L = np.empty((n, n))
    X = np.empty((n, n))
    W = np.empty((n, n))
    v = np.empty(n)
    bad = 0
    for i in range(n):
        d_out[E - 1, i] = 0.0
    if slot[E - 1] >= 0:
        P_out[slot[E - 1]] = Ps
    for k in range(E - 2, -1, -1):
        Pf = P_filt[k]
        Pp = P_pred[k + 1]
        F = Phi[k + 1]
        status = _factor(Pp, L, jitter)
        if status > 0:
            bad += 1
        if status == 2:  # skipped: restart from the filter at k
            for i in range(n):
                d[i] = 0.0
                for j in range(n):
                    Ps[i, j] = Pf[i, j]
        else:
            # X = G^T = P_pred^-1 (Phi P_filt): X <- Phi P_filt, then two triangular solves per column
            for i in range(n):
                for j in range(n):
                    X[i, j] = 0.0
                for m in range(n):
                    f = F[i, m]
                    if f != 0.0:  # Phi is sparse (about half zeros for the INS)
                        for j in range(n):
                            X[i, j] += f * Pf[m, j]
            for j in range(n):
                for i in range(n):  # forward: L y = x
                    s = X[i, j]
                    for m in range(i):
                        s -= L[i, m] * X[m, j]
                    X[i, j] = s / L[i, i]
                for i in range(n - 1, -1, -1):  # backward: L^T z = y
                    s = X[i, j]
                    for m in range(i + 1, n):
                        s -= L[m, i] * X[m, j]
                    X[i, j] = s / L[i, i]
            # d_s(k) = G (d_s(k+1) + dx(k+1)) = X^T v
            for i in range(n):
                v[i] = d[i] + dx[k + 1, i]
            for i in range(n):
                s = 0.0
                for m in range(n):
                    s += X[m, i] * v[m]
                d[i] = s
            # P_s(k) = P_filt + X^T (P_s(k+1) - P_pred) X, symmetric by construction
            for i in range(n):
                for j in range(n):
                    s = 0.0
                    for m in range(n):
                        s += (Ps[i, m] - Pp[i, m]) * X[m, j]
                    W[i, j] = s
            for i in range(n):
                for j in range(i, n):
                    s = Pf[i, j]
                    for m in range(n):
                        s += X[m, i] * W[m, j]
                    Ps[i, j] = s
                    Ps[j, i] = s
        for i in range(n):
            d_out[k, i] = d[i]
        if slot[k] >= 0:
            P_out[slot[k]] = Ps
    return bad


def rts_backward(Phi: np.ndarray, P_pred: np.ndarray, P_filt: np.ndarray, dx: np.ndarray,
                 keep: np.ndarray | None = None):
    """The backward RTS pass of a closed-loop (feedback-reset) error-state filter.

    Parameters
    ----------
    Phi : ndarray (E, n, n)
        ``Phi[k]``: error-state transition from event ``k-1`` to ``k`` (``Phi[0]`` unused).
    P_pred : ndarray (E, n, n)
        Covariance at each event after propagation, before its updates.
    P_filt : ndarray (E, n, n)
        Covariance after the event's updates.
    dx : ndarray (E, n)
        Sum of the corrections fed back at each event (zero without an update), in the
        error state's units (``dx = x_true - x_est``).
    keep : ndarray of int (K,), optional
        Events whose smoothed covariance to return (default: all). The means of all
        events are returned (``E n`` doubles); the covariances only where asked, so a
        long INS run does not hold a fourth ``(E, n, n)`` array.

    Returns
    -------
    d_s : ndarray (E, n)
        Smoothed error about the post-feedback nominal of each event (inject it).
    P_s : ndarray (K, n, n)
        Smoothed covariance at the events of ``keep``.
    not_pd : int
        Steps whose ``P_pred`` needed jitter or was skipped (module docstring).
    """
    Phi, P_pred, P_filt, dx = (np.ascontiguousarray(a, dtype=float) for a in (Phi, P_pred, P_filt, dx))
    if dx.ndim != 2 or P_pred.shape != (dx.shape[0], dx.shape[1], dx.shape[1]) \
            or P_filt.shape != P_pred.shape or Phi.shape != P_pred.shape:
        raise ArgumentError(f"expected Phi, P_pred, P_filt (E, n, n) and dx (E, n), got {Phi.shape}, "
                            f"{P_pred.shape}, {P_filt.shape}, {dx.shape}", argument="dx")
    E, n = dx.shape
    keep = np.arange(E) if keep is None else np.asarray(keep, dtype=np.int64).ravel()
    if keep.size and (keep.min() < 0 or keep.max() >= E):
        raise ArgumentError(f"must be event indices in [0, {E})", argument="keep")
    d_s = np.zeros((E, n))
    if E == 0:
        return d_s, np.empty((0, n, n)), 0
    uk, inv = np.unique(keep, return_inverse=True)  # any order, repeats allowed
    P_s = np.empty((len(uk), n, n))
    slot = np.full(E, -1, dtype=np.int64)
    slot[uk] = np.arange(len(uk))
    bad = _backward(Phi, P_pred, P_filt, dx, slot, JITTER, d_s, P_s)
    if len(uk) != len(keep) or np.any(uk != keep):
        P_s = P_s[inv]
    return d_s, P_s, int(bad)


@njit(cache=True)
def _inject_rows(nav, sensor, clock, d, layout):
    """``apply_feedback`` of row ``i`` of ``d`` into row ``i`` of ``nav``, ``sensor``, ``clock``."""
    for i in range(nav.shape[0]):
        apply_feedback(nav[i], sensor[i], clock[i], d[i], layout)


_WARM = []


def warm_up() -> None:
    """Compile (or load from numba's cache) the smoother's kernels once per process, so
    ``smoother_time_s`` is the recursion, not compilation."""
    if _WARM:
        return
    for n in (2, 15):  # the kernels are size-generic; one compilation per dtype signature
        E = 3
        P = np.broadcast_to(np.eye(n), (E, n, n)).copy()
        _backward(P, P, P, np.zeros((E, n)), np.zeros(E, dtype=np.int64), JITTER, np.zeros((E, n)),
                  np.zeros((E, n, n)))
    lay = np.array([15, 9, 12, -1, -1, -1], dtype=np.int64)
    _inject_rows(np.array([[1.0, 0, 0, 0, 0, 0, 0, 0.5, 0.5, 0.0]]), np.zeros((1, 12)), np.zeros((1, 2)),
                 np.zeros((1, 15)), lay)
    _WARM.append(True)


def event_rows(event_times: np.ndarray, times: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Index of each of ``times`` among the sorted ``event_times``, matched within ``tol`` [s]
    (never by float equality); an :class:`ArgumentError` if one has no event."""
    event_times = np.asarray(event_times, dtype=float)
    times = np.asarray(times, dtype=float)
    if times.size == 0:
        return np.zeros(0, dtype=np.int64)
    if event_times.size == 0:
        raise ArgumentError("the history has no events but the result has output epochs", argument="result")
    k = np.clip(np.searchsorted(event_times, times - tol), 0, len(event_times) - 1)
    off = np.abs(event_times[k] - times)
    if off.max() > tol:
        i = int(np.argmax(off))
        raise ArgumentError(f"output epoch {times[i]:.6f} s is not an event of the history "
                            f"(nearest {event_times[k[i]]:.6f} s)", argument="result")
    return k.astype(np.int64)


def rts_smooth(result: FilterResult) -> FilterResult:
    """Smooth a closed-loop filter run (fixed interval, Rauch-Tung-Striebel).

    Parameters
    ----------
    result : FilterResult
        Of a run with ``history=True`` (``ErrorStateEkf.run(..., history=True)`` or
        ``Engine(..., history=True)``).

    Returns
    -------
    FilterResult
        At the same output epochs (``result.time``):

        - ``nav``: the recorded nominal with the smoothed error injected (attitude,
          velocity, position);
        - ``sensor``, ``estimates`` (biases, scale factors, clock, auxiliary blocks):
          the filter's estimates at the output epochs plus the smoothed correction of
          their blocks (exact: the engine records them at every output epoch);
        - ``sigma`` = sqrt(diag P_s) (n,), ``pv_cov`` = ``P_s[3:9, 3:9]`` (velocity
          then position errors, the filter's layout; ``_record_kernel.record_epoch``);
          ``P`` the last event's covariance (smoothed = filtered there);
        - copied from the filter: ``gnss_used``, ``w_b`` (the compensated rate of the
          forward pass; not re-compensated with the smoothed biases), ``layout``;
        - ``recoveries``: the filter's plus ``smoother_not_pd`` (module docstring);
        - ``timing``: ``smoother_time_s`` only (backward pass and injection); the forward
          pass's timing and counts (``epoch_time_mean_us``, ``wall_time_s``, ...) are its
          own, not the smoother's, and stay in ``result``;
        - ``nis``, ``nis_dim``, ``nis_kind`` empty and ``outputs`` empty: innovations
          and estimator series belong to the forward pass (still in ``result``);
        - ``history`` None.

    Raises
    ------
    ArgumentError
        ``history`` when the run did not keep one; ``result`` when an output epoch
        is not among the history's events (within 1e-6 s).

    Notes
    -----
    Stochastic clones (TDCP) are not in the history: the smoother then works on the
    marginal of the error state, and a bank or robust estimator is smoothed on the
    merged Gaussian it reports; both are approximations (docs/smoother.md).
    """
    if not isinstance(result, FilterResult):
        raise ArgumentError(f"expected a FilterResult, got {type(result).__name__}", argument="result")
    h = result.history
    if h is None:
        raise ArgumentError("the run kept no history: run the filter with history=True to smooth it",
                            argument="history")
    warm_up()
    t0 = _time.perf_counter()
    lay = result.layout
    rows = event_rows(h.time, result.time)
    d_s, P_s, not_pd = rts_backward(h.Phi, h.P_pred, h.P_filt, h.dx, keep=rows)
    d = d_s[rows]
    nav = np.array(h.nav[rows], dtype=float)
    sensor = np.array(result.sensor, dtype=float)
    clock = (np.array(result.estimates["clock"], dtype=float) if lay.clk >= 0
             else np.zeros((len(rows), 2)))
    aux_s = {name: np.asarray(result.estimates[name], dtype=float) + d[:, sl] for name, sl in lay.aux}
    if lay.is_ins:
        _inject_rows(nav, sensor, clock, d, lay.as_array())
        pv = np.ascontiguousarray(P_s[:, 3:9, 3:9])
    else:   # another motion model: its own feedback, row by row (auxiliary blocks done above)
        if result.motion is None:
            raise ArgumentError("a run of a non-INS motion model must carry its motion model to be smoothed",
                                argument="result.motion")
        scratch = {name: np.zeros(sl.stop - sl.start) for name, sl in lay.aux}
        for i in range(len(rows)):
            result.motion.inject(nav[i], sensor[i], clock[i], scratch, d[i])
        pv = np.full((len(rows), 6, 6), np.nan)
        ip = lay.pos.start
        pv[:, 3:, 3:] = P_s[:, ip:ip + 3, ip:ip + 3]
        if lay.vel is not None:
            iv = lay.vel.start
            idx = np.r_[iv:iv + 3, ip:ip + 3]
            pv = np.ascontiguousarray(P_s[:, idx][:, :, idx])
    # round-off can leave a variance that should be ~0 slightly negative: floored, never NaN
    sigma = np.sqrt(np.maximum(np.diagonal(P_s, axis1=1, axis2=2), 0.0))
    estimates = lay.sensor_estimates(sensor)
    if lay.clk >= 0:
        estimates["clock"] = clock
    estimates.update(aux_s)
    timing = {"smoother_time_s": _time.perf_counter() - t0}
    recoveries = dict(result.recoveries)
    recoveries["smoother_not_pd"] = not_pd
    return FilterResult(
        time=np.array(result.time), nav=nav, sigma=sigma, gnss_used=np.array(result.gnss_used),
        sensor=sensor, nis=np.zeros(0), nis_dim=np.zeros(0, dtype=int), pv_cov=pv,
        w_b=np.array(result.w_b), recoveries=recoveries, timing=timing, layout=lay,
        P=None if result.P is None else np.array(result.P), estimates=estimates,
        nis_kind=np.zeros(0, dtype=object), outputs={}, history=None, motion=result.motion)
