"""The whole EKF correction of one epoch in one compiled call.

Gate, Kalman update, feedback into the INS and checks, fused so that a GNSS
epoch costs one dispatch from Python instead of a dozen small numpy calls
(measured: 45 us -> see benchmarks/results/core.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..ins._error_kernels import apply_feedback
from .kalman import OK, S_NOT_POSITIVE_DEFINITE, innovation_is_absurd, kalman_update

#: Status codes of :func:`ekf_correct` beyond those of ``kalman_update``.
from ..engine.status import ABSURD, NEEDS_REPAIR, NON_FINITE  # noqa: E402,F401

__all__ = ["ekf_correct", "ekf_correct_dx", "kalman_correct", "OK", "S_NOT_POSITIVE_DEFINITE", "ABSURD", "NON_FINITE", "NEEDS_REPAIR"]


@njit(cache=True)
def ekf_correct(P, z, H, r, n_sigma, nav, sensor, clock, layout):
    """:func:`ekf_correct_dx` without the correction vector (see there)."""
    P_post, dx, nis, status = ekf_correct_dx(P, z, H, r, n_sigma, nav, sensor, clock, layout)
    return P_post, nis, status


@njit(cache=True)
def ekf_correct_dx(P, z, H, r, n_sigma, nav, sensor, clock, layout):
    """:func:`kalman_correct` followed by the feedback of ``dx`` into ``nav``, ``sensor``
    and ``clock`` (in place) when the update is applied (``OK`` or ``NEEDS_REPAIR``)."""
    P_post, dx, nis, status = kalman_correct(P, z, H, r, n_sigma)
    if status == OK or status == NEEDS_REPAIR:
        apply_feedback(nav, sensor, clock, dx, layout)
    return P_post, dx, nis, status


@njit(cache=True)
def kalman_correct(P, z, H, r, n_sigma):
    """Gate and update one measurement; closed loop (prior dx = 0); no feedback.

    Parameters
    ----------
    P : ndarray (n, n)
        Prior covariance (not modified).
    z, H : ndarray (m,), (m, n)
        Innovation and Jacobian.
    r : ndarray (m,) or (m, m)
        Noise variances (diagonal) or full covariance.
    n_sigma : float
        Absurd-innovation threshold in predicted sigmas.

    Returns
    -------
    P_post : ndarray (n, n)
        Posterior (the prior when the epoch is rejected).
    dx : ndarray (n,)
        The correction (zeros when rejected), for the engine to feed back.
    nis : float
    status : int
        ``OK``, ``S_NOT_POSITIVE_DEFINITE``, ``ABSURD``, ``NON_FINITE`` (the
        posterior has a non-finite value: nothing is applied) or
        ``NEEDS_REPAIR`` (applied, but a variance of P is not positive).
    """
    m = z.shape[0]
    n = P.shape[0]
    if r.ndim == 1:
        R = np.diag(r)
    else:
        R = r
    rd = np.empty(m)
    for i in range(m):
        rd[i] = R[i, i]
    zero = np.zeros(n)
    if innovation_is_absurd(z, H, P, rd, n_sigma):
        return P, zero, np.inf, ABSURD
    dx, P_post, nis, status = kalman_update(zero, P, z, H, R)
    if status != OK:
        return P, zero, nis, status
    for i in range(n):
        if not np.isfinite(dx[i]):
            return P, zero, nis, NON_FINITE
        for j in range(n):
            if not np.isfinite(P_post[i, j]):
                return P, zero, nis, NON_FINITE
    for i in range(n):
        if P_post[i, i] <= 0.0:
            return P_post, dx, nis, NEEDS_REPAIR
    return P_post, dx, nis, OK
