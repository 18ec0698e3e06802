"""Compiled kernels of the unscented filters (numba, ``cache=True``).

- :func:`ukf_predict`: one propagation step of the sigma points in one call
  (Cholesky, sigma points as full states ``nominal (+) deviation``, their
  mechanization over the step's IMU block, the difference map back to error
  states, the weighted mean and covariance);
- :func:`ukf_sigma_navs`: the sigma points of a measurement epoch as full
  navigation states (for ``model.predict_batch``);
- :func:`measurement_moments`: predicted measurement mean, ``Pyy`` and ``Pxy``
  of the sigma points;
- :func:`vb_correct`: the (variational-Bayes adaptive) Kalman correction from
  those moments, shared by the UKF, the VB-AUKF and the VB-AKF.

Error-state convention (:mod:`mixnav.ins._error_kernels`): ``dx = x_true -
x_est``, ``C_true = exp([phi x]) C_est``, position error in NED metres,
sensor errors added to the sensor estimates. The *difference* map
(:func:`nav_difference`) is the exact inverse of the feedback map
(:func:`~mixnav.ins._error_kernels.apply_feedback`) for the attitude,
velocity and position parts: ``difference(inject(nav, d), nav) == d`` to
round-off (tested).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..engine.status import ABSURD, NEEDS_REPAIR, NON_FINITE, OK, S_NOT_POSITIVE_DEFINITE
from ..ins._error_kernels import L_BA, L_BG, L_CLK, L_SA, L_SG, apply_feedback
from ..ins._kernels import mechanize_step, radii
from ..linalg import cholesky_lower


@njit(cache=True)
def sigma_deviations(x, L, c, D):
    """``D[0] = x``, ``D[1 + k] = x + c L[:, k]``, ``D[1 + n + k] = x - c L[:, k]``
    (the 2n + 1 scaled sigma points of N(x, L L^T) as error states)."""
    n = x.shape[0]
    for i in range(n):
        D[0, i] = x[i]
    for k in range(n):
        for i in range(n):
            d = c * L[i, k]
            D[1 + k, i] = x[i] + d
            D[1 + n + k, i] = x[i] - d


@njit(cache=True)
def weighted_moments(D, wm, wc, x, P):
    """``x = sum_j wm_j D_j``, ``P = sum_j wc_j (D_j - x)(D_j - x)^T`` (written into x, P)."""
    N, n = D.shape
    for i in range(n):
        s = 0.0
        for j in range(N):
            s += wm[j] * D[j, i]
        x[i] = s
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            xa, xb = x[a], x[b]
            for j in range(N):
                s += wc[j] * (D[j, a] - xa) * (D[j, b] - xb)
            P[a, b] = s
            P[b, a] = s


@njit(cache=True)
def nav_difference(nav, ref, out):
    """``out[0:9]`` = ``nav (-) ref``: rotation vector ``log(C_nav C_ref^T)``, velocity
    difference, NED metres of the position (radii at ``ref``, the inverse of
    ``apply_feedback``)."""
    # q_err = q_nav (x) conj(q_ref)
    a0, a1, a2, a3 = nav[0], nav[1], nav[2], nav[3]
    b0, b1, b2, b3 = ref[0], -ref[1], -ref[2], -ref[3]
    w = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    x = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    y = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    z = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        k = 2.0 / w  # small angle: 2 atan(s/w)/s -> 2/w (1 - s^2/(3 w^2))
        k *= 1.0 - s * s / (3.0 * w * w)
    else:
        k = 2.0 * math.atan2(s, w) / s
    out[0], out[1], out[2] = k * x, k * y, k * z
    for i in range(3):
        out[3 + i] = nav[4 + i] - ref[4 + i]
    lat, h = ref[7], ref[9]
    rm, rn = radii(lat)
    out[6] = (nav[7] - lat) * (rm + h)
    out[7] = (nav[8] - ref[8]) * ((rn + h) * math.cos(lat))
    out[8] = h - nav[9]


@njit(cache=True)
def merge_block_into(dtheta, dvel, dt, substeps, gth, gdv, gdt):
    """The block's increments merged into at most ``substeps`` sub-intervals (0 or
    ``substeps >= K``: as they are), written into ``gth``, ``gdv`` (>= S, 3) and
    ``gdt`` (>= S,); returns S. :func:`merge_block` without its allocation
    (the particle kernels' preallocated buffers)."""
    K = dtheta.shape[0]
    S = K if substeps <= 0 or substeps >= K else substeps
    for g in range(S):
        gdt[g] = 0.0
        for i in range(3):
            gth[g, i] = 0.0
            gdv[g, i] = 0.0
    for k in range(K):
        g = (k * S) // K
        for i in range(3):
            gth[g, i] += dtheta[k, i]
            gdv[g, i] += dvel[k, i]
        gdt[g] += dt[k]
    return S


@njit(cache=True)
def merge_block(dtheta, dvel, dt, substeps):
    """The block's raw increments merged into at most ``substeps`` sub-intervals (0 or
    ``substeps >= K``: as they are): ``(gth, gdv, gdt)``."""
    K = dtheta.shape[0]
    S = K if substeps <= 0 or substeps >= K else substeps
    gth = np.empty((S, 3))
    gdv = np.empty((S, 3))
    gdt = np.empty(S)
    merge_block_into(dtheta, dvel, dt, substeps, gth, gdv, gdt)
    return gth, gdv, gdt


@njit(cache=True)
def mechanize_members(navs, prevs, sensors, gth, gdv, gdt):
    """Mechanize every row of ``navs`` (with its ``prevs``, ``sensors``) over the merged
    increments ``gth``, ``gdv``, ``gdt`` (in place)."""
    S = gdt.shape[0]
    dth = np.empty(3)
    dv = np.empty(3)
    dvn = np.empty(3)
    for j in range(navs.shape[0]):
        nav, prev, sensor = navs[j], prevs[j], sensors[j]
        for k in range(S):
            h = gdt[k]
            for i in range(3):
                dth[i] = (gth[k, i] - sensor[i] * h) / (1.0 + sensor[6 + i])
                dv[i] = (gdv[k, i] - sensor[3 + i] * h) / (1.0 + sensor[9 + i])
            mechanize_step(nav, dth, dv, prev[0:3], prev[3:6], h, dvn)
            for i in range(3):
                prev[i] = dth[i]
                prev[3 + i] = dv[i]


@njit(cache=True)
def difference_members(navs, ref, D, Dn, layout, tau, T):
    """The propagated error states ``Dn[j]`` (j < len(D)) of the mechanized members
    ``navs[j]`` against the mechanized reference ``ref``: attitude, velocity and
    position by :func:`nav_difference`; sensor deviations ``D[j]`` decayed by their
    Gauss-Markov model ``exp(-T / tau)``; the clock deviation ``+= drift T``;
    auxiliary deviations kept."""
    N, n = D.shape
    i_bg, i_ba, i_sg, i_sa, i_clk = layout[L_BG], layout[L_BA], layout[L_SG], layout[L_SA], layout[L_CLK]
    f = np.empty(4)
    for b in range(4):
        f[b] = math.exp(-T / tau[b]) if tau[b] > 0.0 and np.isfinite(tau[b]) else 1.0
    for j in range(N):
        for i in range(n):
            Dn[j, i] = D[j, i]
        nav_difference(navs[j], ref, Dn[j])
        for i in range(3):
            Dn[j, i_bg + i] = D[j, i_bg + i] * f[0]
            Dn[j, i_ba + i] = D[j, i_ba + i] * f[1]
            if i_sg >= 0:
                Dn[j, i_sg + i] = D[j, i_sg + i] * f[2]
            if i_sa >= 0:
                Dn[j, i_sa + i] = D[j, i_sa + i] * f[3]
        if i_clk >= 0:
            Dn[j, i_clk] = D[j, i_clk] + D[j, i_clk + 1] * T


@njit(cache=True)
def propagate_members(nav0, prev0, sensor0, D, dtheta, dvel, dt, substeps, layout, tau, T, navs, prevs, sensors,
                      Dn):
    """The members ``D`` (N, n) (sigma points, particles) as full states ``nav0 (+) D_j``
    (``prev0`` their previous increments, ``sensor0`` corrected by their sensor
    deviations), and a reference (row N: the nominal itself) mechanized over the block
    merged into ``substeps`` sub-intervals (:func:`merge_block`); their propagated error
    states against the reference into ``Dn`` (N, n) (:func:`difference_members`).
    ``navs`` (N+1, 10), ``prevs`` (N+1, 6), ``sensors`` (N+1, 12) are scratch."""
    N = D.shape[0]
    clock = np.zeros(2)
    for j in range(N + 1):
        for i in range(10):
            navs[j, i] = nav0[i]
        for i in range(6):
            prevs[j, i] = prev0[i]
        for i in range(12):
            sensors[j, i] = sensor0[i]
        if j < N:
            apply_feedback(navs[j], sensors[j], clock, D[j], layout)
    gth, gdv, gdt = merge_block(dtheta, dvel, dt, substeps)
    mechanize_members(navs, prevs, sensors, gth, gdv, gdt)
    difference_members(navs, navs[N], D, Dn, layout, tau, T)


@njit(cache=True)
def ukf_predict(nav0, prev0, sensor0, x, P, Qd, c, wm, wc, dtheta, dvel, dt, substeps, layout, tau, T,
                L, D, navs, prevs, sensors, Dn, x_out, P_out):
    """Propagate the sigma points of ``N(x, P)`` about ``nav0`` over one IMU block.

    Each sigma point ``D_j`` (error state) becomes a full state ``nav0 (+) D_j``
    (attitude, velocity, position, sensor errors; ``prev0`` its previous
    increments) and is mechanized over the block; a reference point (``D = 0``:
    the nominal) is mechanized the same way, and each propagated point is
    differenced from the propagated reference. ``substeps > 0`` merges the
    block's increments into at most that many sub-intervals before mechanizing
    the points and the reference (their common merging error cancels in the
    difference); 0 mechanizes every increment. Sensor deviations decay as their
    Gauss-Markov model (``exp(-T / tau)``); the clock deviation moves as
    ``d_bias += d_drift T``; auxiliary deviations stay.

    Writes ``x_out``, ``P_out = sum wc (D - x)(D - x)^T + Qd``. ``L`` (n, n),
    ``D`` (2n+1, n), ``navs`` (2n+2, 10), ``prevs`` (2n+2, 6), ``sensors``
    (2n+2, 12), ``Dn`` (2n+1, n) are scratch. Returns False (nothing written)
    when ``P`` is not positive definite.
    """
    n = x.shape[0]
    if not cholesky_lower(P, L):
        return False
    sigma_deviations(x, L, c, D)
    propagate_members(nav0, prev0, sensor0, D, dtheta, dvel, dt, substeps, layout, tau, T, navs, prevs, sensors,
                      Dn)
    weighted_moments(Dn, wm, wc, x_out, P_out)
    for a in range(n):
        for b in range(n):
            P_out[a, b] += Qd[a, b]
    return True


@njit(cache=True)
def ukf_sigma_navs(nav, x, P, c, layout, L, D, navs):
    """The sigma points of ``N(x, P)`` about ``nav``: error states ``D`` (2n+1, n) and
    full navigation states ``navs`` (2n+1, 10) (``L`` scratch). False when ``P`` is
    not positive definite."""
    if not cholesky_lower(P, L):
        return False
    sigma_deviations(x, L, c, D)
    member_navs(nav, D, layout, navs)
    return True


@njit(cache=True)
def member_navs(nav, D, layout, navs):
    """The members ``D`` (N, n) (sigma points, particles) about ``nav`` as full navigation
    states ``navs`` (N, 10) (the engine's feedback map applied to a copy of ``nav``)."""
    sensor = np.zeros(12)
    clock = np.zeros(2)
    for j in range(D.shape[0]):
        for i in range(10):
            navs[j, i] = nav[i]
        apply_feedback(navs[j], sensor, clock, D[j], layout)


@njit(cache=True)
def measurement_moments(D, Y, y, wm, wc):
    """``(innovation y - E[Y], Pyy, Pxy)`` of the sigma points ``D`` (N, n) and their
    predictions ``Y`` (N, m)."""
    N, n = D.shape
    m = Y.shape[1]
    ym = np.zeros(m)
    xm = np.zeros(n)
    for j in range(N):
        for i in range(m):
            ym[i] += wm[j] * Y[j, i]
        for i in range(n):
            xm[i] += wm[j] * D[j, i]
    Pyy = np.zeros((m, m))
    Pxy = np.zeros((n, m))
    dy = np.empty(m)
    for j in range(N):
        w = wc[j]
        for i in range(m):
            dy[i] = Y[j, i] - ym[i]
        for a in range(m):
            for b in range(m):
                Pyy[a, b] += w * dy[a] * dy[b]
        for a in range(n):
            da = w * (D[j, a] - xm[a])
            for b in range(m):
                Pxy[a, b] += da * dy[b]
    innov = np.empty(m)
    for i in range(m):
        innov[i] = y[i] - ym[i]
    return innov, Pyy, Pxy


@njit(cache=True)
def _forward(L, B, out):
    """``out = L^-1 B`` (L lower triangular (m, m), B (m, k))."""
    m, k = B.shape
    for col in range(k):
        for i in range(m):
            s = B[i, col]
            for p in range(i):
                s -= L[i, p] * out[p, col]
            out[i, col] = s / L[i, i]


@njit(cache=True)
def linearized_pyy(L, Pxy):
    """``G = Pxy^T P^-1 Pxy`` (m, m) from ``L`` (the lower Cholesky factor of ``P``): the
    statistically linearised ``H P H^T``; the VB step's posterior residual moments
    use it (exactly ``H P H^T`` for a linear ``h``)."""
    n, m = Pxy.shape
    V = np.empty((n, m))
    _forward(L, Pxy, V)
    G = np.zeros((m, m))
    for a in range(m):
        for b in range(m):
            s = 0.0
            for i in range(n):
                s += V[i, a] * V[i, b]
            G[a, b] = s
    return G


@njit(cache=True)
def vb_correct(x, P, Pxy, Pyy, G, innov, r, alpha0, beta0, vb, iterations, tol, n_sigma):
    """One Kalman correction from the moments; with ``vb`` the variational-Bayes
    noise adaptation of Sarkka & Nummenmaa (2009) per row.

    Parameters
    ----------
    x, P : ndarray (n,), (n, n)
        Prior mean and covariance (not modified).
    Pxy, Pyy : ndarray (n, m), (m, m)
        Cross and measurement covariances of the prior (``P H^T``, ``H P H^T``
        for a linear model).
    G : ndarray (m, m)
        ``Pxy^T P^-1 Pxy`` (see :func:`linearized_pyy`); used only with ``vb``.
    innov : ndarray (m,)
        ``y - E[h(x)]`` under the prior.
    r : ndarray (m,)
        Noise variances (without ``vb``).
    alpha0, beta0 : ndarray (m,)
        Predicted inverse-Gamma parameters per row (with ``vb``).
    vb : bool
    iterations : int
        At most this many fixed-point iterations (``vb``).
    tol : float
        Stop when no row's variance ``beta / alpha`` changes by more than ``tol``
        relative.
    n_sigma : float
        Absurd-innovation gate in predicted sigmas (with the prior variance).

    Returns
    -------
    x_post, P_post, nis, status, alpha, beta, used_iterations
        With ``vb``: ``alpha = alpha0 + 1/2``, ``beta = beta0 + (e^2 + (H P+ H^T)_ii) / 2``
        at the fixed point (``e`` the posterior residual). Rejected: the prior.
    """
    n = x.shape[0]
    m = innov.shape[0]
    alpha = alpha0.copy()
    beta = beta0.copy()
    R = np.empty(m)
    if vb:
        for i in range(m):
            alpha[i] = alpha0[i] + 0.5
            R[i] = beta0[i] / alpha[i]
    else:
        for i in range(m):
            R[i] = r[i]
    for i in range(m):  # the gate, with the prior noise level
        if not np.isfinite(innov[i]):
            return x, P, np.inf, ABSURD, alpha0, beta0, 0
        if innov[i] * innov[i] > n_sigma * n_sigma * (Pyy[i, i] + R[i]):
            return x, P, np.inf, ABSURD, alpha0, beta0, 0
    S = np.empty((m, m))
    Ls = np.empty((m, m))
    W = np.empty((m, n))
    PxyT = np.ascontiguousarray(Pxy.T)
    u = np.empty((m, 1))
    iv = np.empty((m, 1))
    for i in range(m):
        iv[i, 0] = innov[i]
    U = np.empty((m, m))
    it = 0
    n_iter = max(iterations, 1) if vb else 1
    # Sarkka & Nummenmaa (2009), algorithm 1: per pass (1) the state with R = beta / alpha,
    # (2) beta from that posterior; the state returned is the last pass's (1).
    while it < n_iter:
        for a in range(m):
            for b in range(m):
                S[a, b] = Pyy[a, b]
            S[a, a] += R[a]
        if not cholesky_lower(S, Ls):
            return x, P, np.inf, S_NOT_POSITIVE_DEFINITE, alpha0, beta0, it
        _forward(Ls, iv, u)        # u = Ls^-1 innov
        it += 1
        if not vb:
            break
        # posterior residual moments (statistical linearisation): e = innov - G S^-1 innov,
        # its variance diag(G - G S^-1 G)
        _forward(Ls, G, U)         # U = Ls^-1 G
        change = 0.0
        for i in range(m):
            gsi = 0.0
            gsg = 0.0
            for k in range(m):
                gsi += U[k, i] * u[k, 0]
                gsg += U[k, i] * U[k, i]
            e = innov[i] - gsi
            beta[i] = beta0[i] + 0.5 * (e * e + max(G[i, i] - gsg, 0.0))
            r_new = beta[i] / alpha[i]
            d = abs(r_new - R[i]) / R[i]
            if d > change:
                change = d
            R[i] = r_new
        if change <= tol:
            break
    _forward(Ls, PxyT, W)          # W = Ls^-1 Pxy^T  (m, n)
    x_post = np.empty(n)
    P_post = np.empty((n, n))
    nis = 0.0
    for k in range(m):
        nis += u[k, 0] * u[k, 0]
    for i in range(n):
        s = x[i]
        for k in range(m):
            s += W[k, i] * u[k, 0]
        x_post[i] = s
    for a in range(n):
        for b in range(a, n):
            s = P[a, b]
            for k in range(m):
                s -= W[k, a] * W[k, b]
            P_post[a, b] = s
            P_post[b, a] = s
    for i in range(n):
        if not np.isfinite(x_post[i]):
            return x, P, nis, NON_FINITE, alpha0, beta0, it
        for j in range(n):
            if not np.isfinite(P_post[i, j]):
                return x, P, nis, NON_FINITE, alpha0, beta0, it
    for i in range(n):
        if P_post[i, i] <= 0.0:
            return x_post, P_post, nis, NEEDS_REPAIR, alpha, beta, it
    return x_post, P_post, nis, OK, alpha, beta, it
