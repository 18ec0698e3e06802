"""Compiled EM loop of the whole-epoch mixture update (:mod:`mixnav.filters.epoch_mixture`).

The epoch's EM alternates responsibilities and a Kalman update up to 20 times per epoch;
in Python each iteration cost a few numpy calls and a compiled update (about 1 ms per
epoch on smartLoc); here the loop is one compiled call. The arithmetic is the module
docstring's; the tests check it against the Kalman update in its closed cases and the
responsibilities against scipy's densities.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._ekf_kernels import NEEDS_REPAIR, OK, kalman_correct


@njit(cache=True)
def responsibilities(e, r, h, mix, w, s, mu, sd):
    """LOS responsibility of each row (1 for rows outside the mixture or with ``w >= 1``)."""
    m = e.shape[0]
    g = np.ones(m)
    for j in range(m):
        if not mix[j] or w[j] >= 1.0:
            continue
        vl = s * r[j] + h[j]
        vn = sd * sd + h[j]
        a = math.log(w[j]) - 0.5 * e[j] * e[j] / vl - 0.5 * math.log(vl)
        d = e[j] - mu
        b = math.log1p(-w[j]) - 0.5 * d * d / vn - 0.5 * math.log(vn)
        mx = max(a, b)
        g[j] = math.exp(a - mx) / (math.exp(a - mx) + math.exp(b - mx))
    return g


@njit(cache=True)
def _row_variances(H, P):
    m, n = H.shape
    h = np.empty(m)
    for j in range(m):
        acc = 0.0
        for a in range(n):
            if H[j, a] == 0.0:
                continue
            row = 0.0
            for b in range(n):
                row += P[a, b] * H[j, b]
            acc += H[j, a] * row
        h[j] = acc
    return h


@njit(cache=True)
def epoch_em(P0, z, H, r, mix, w, s, mu, sd, inflate, iterations, tolerance, n_sigma):
    """EM of one epoch from the prior ``P0`` (closed loop: prior ``dx = 0``).

    Returns ``(P_post, dx, nis, status, e, g, converged)``: the last M-step's posterior
    and correction, the posterior residuals ``z - H dx`` and the LOS responsibilities at
    them. A failed Kalman step returns ``status`` with ``dx = 0`` and ``P0``."""
    n = P0.shape[0]
    m = z.shape[0]
    x = np.zeros(n)
    h = _row_variances(H, P0)
    g = responsibilities(z, r, h, mix, w, s, mu, sd)
    P_new = P0
    nis = 0.0
    status = OK
    e = z.copy()
    r_eff = np.empty(m)
    z_eff = np.empty(m)
    converged = False
    for _ in range(iterations):
        for j in range(m):
            if mix[j]:
                info = g[j] / (s * r[j]) + (1.0 - g[j]) / (sd * sd)
                rv = 1.0 / info
                z_eff[j] = rv * (g[j] * z[j] / (s * r[j]) + (1.0 - g[j]) * (z[j] - mu) / (sd * sd))
                r_eff[j] = rv * inflate[j]
            else:
                z_eff[j] = z[j]
                r_eff[j] = r[j] * inflate[j]
        P_new, dx, nis, status = kalman_correct(P0, z_eff, H, r_eff, n_sigma)
        if status != OK and status != NEEDS_REPAIR:
            return P0, np.zeros(n), nis, status, e, g, False
        moved = 0.0
        for a in range(n):
            moved = max(moved, abs(dx[a] - x[a]))
        x = dx
        for j in range(m):
            acc = z[j]
            for a in range(n):
                acc -= H[j, a] * x[a]
            e[j] = acc
        h = _row_variances(H, P_new)
        g = responsibilities(e, r, h, mix, w, s, mu, sd)
        if moved < tolerance:
            converged = True
            break
    return P_new, x, nis, status, e, g, converged


@njit(cache=True)
def predictive_log_density(z, r, h, mix, w, s, mu, sd):
    """Sum over the rows of the log predictive density of each innovation alone: the
    mixture's for ``mix`` rows, ``N(0, r + h)`` for the others."""
    total = 0.0
    l2p = math.log(2.0 * math.pi)
    for j in range(z.shape[0]):
        if mix[j]:
            vl = s * r[j] + h[j]
            a = math.log(w[j]) - 0.5 * (z[j] * z[j] / vl + math.log(vl) + l2p)
            if w[j] < 1.0:
                vn = sd * sd + h[j]
                d = z[j] - mu
                b = math.log1p(-w[j]) - 0.5 * (d * d / vn + math.log(vn) + l2p)
                mx = max(a, b)
                total += mx + math.log(math.exp(a - mx) + math.exp(b - mx))
            else:
                total += a
        else:
            v = r[j] + h[j]
            total += -0.5 * (z[j] * z[j] / v + math.log(v) + l2p)
    return total
