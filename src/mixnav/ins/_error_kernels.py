"""Compiled INS error-state propagation (numba, ``cache=True``).

Error state ``dx = x_true - x_est`` in this order (see ``error_model.py`` for
the named layouts)::

    phi (3)   attitude error, rotation vector in n: C_true = exp([phi x]) C_est
    dv  (3)   velocity error north, east, down [m/s]
    dr  (3)   position error north, east, down [m]
    dbg (3)   gyro bias error [rad/s]            (IMU model: w_meas = (1+sg) w + bg)
    dba (3)   accelerometer bias error [m/s^2]   (f_meas = (1+sa) f + ba)
    [dsg (3), dsa (3)]  scale-factor errors (21-state layout)
    [dcb, dcd]          receiver clock bias [m] and drift [m/s] (17-state)

Continuous model (derived in docs/error_model.md, checked against finite
differences of the mechanization in tests/test_error_model.py)::

    phi' = -[w_in x] phi - Mr dr - Mv dv - C dbg - C diag(w_b) dsg
    dv'  = -[f_n x] phi - [(2w_ie + w_en) x] dv + [v x]((2Mr_ie + Mr_en) dr + Mv dv)
           + dg - C dba - C diag(f_b) dsa
    dr'  = Frr dr + dv
    db'  = -db / tau (first-order Gauss-Markov; tau = inf is a random walk)

with Mr, Mv the partials of w_in^n by position and velocity.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._kernels import (
    OMEGA_EARTH,
    mechanize_step,
    normal_gravity_dh,
    quat_to_dcm_into,
    radii,
)

# Positions in the integer layout array passed to the kernels.
L_N, L_BG, L_BA, L_SG, L_SA, L_CLK = 0, 1, 2, 3, 4, 5


@njit(cache=True)
def _skew_into(m, r0, c0, x, y, z, s):
    """Add ``s * [v x]`` into the 3x3 block of ``m`` at (r0, c0)."""
    m[r0 + 0, c0 + 1] += -s * z
    m[r0 + 0, c0 + 2] += s * y
    m[r0 + 1, c0 + 0] += s * z
    m[r0 + 1, c0 + 2] += -s * x
    m[r0 + 2, c0 + 0] += -s * y
    m[r0 + 2, c0 + 1] += s * x


@njit(cache=True)
def error_dynamics(F, nav, f_n, w_b, f_b, c_nb, layout, tau):
    """Fill the continuous error-state matrix ``F`` (n x n), zeroing it first.

    Parameters
    ----------
    F : ndarray (n, n)
        Output.
    nav : ndarray (10,)
        Navigation state where the model is linearised.
    f_n : ndarray (3,)
        Specific force in NED [m/s^2].
    w_b, f_b : ndarray (3,)
        Angular rate [rad/s] and specific force [m/s^2] in the body frame
        (for the scale-factor columns).
    c_nb : ndarray (3, 3)
        Body-to-NED rotation (averaged over the interval by the caller).
    layout : ndarray of int64 (6,)
        ``[n, i_bg, i_ba, i_sg, i_sa, i_clk]``, -1 where a block is absent.
    tau : ndarray (4,)
        Gauss-Markov correlation times of bg, ba, sg, sa [s]; ``inf`` gives a
        random walk.
    """
    F[:, :] = 0.0
    vn, ve, vd = nav[4], nav[5], nav[6]
    lat, h = nav[7], nav[9]
    rm, rn = radii(lat)
    rmh, rnh = rm + h, rn + h
    sl, cl = math.sin(lat), math.cos(lat)
    tl = sl / cl
    wie_n, wie_d = OMEGA_EARTH * cl, -OMEGA_EARTH * sl
    wen_n, wen_e, wen_d = ve / rnh, -vn / rmh, -ve * tl / rnh

    # Partials of w_ie and w_en by the position error (columns N, E, D) and of
    # w_en by the velocity error (columns vN, vE, vD).
    mr_ie = np.zeros((3, 3))
    mr_ie[0, 0] = -OMEGA_EARTH * sl / rmh
    mr_ie[2, 0] = -OMEGA_EARTH * cl / rmh
    mr_en = np.zeros((3, 3))
    mr_en[2, 0] = -ve / (cl * cl * rnh) / rmh
    mr_en[0, 2] = ve / (rnh * rnh)
    mr_en[1, 2] = -vn / (rmh * rmh)
    mr_en[2, 2] = -ve * tl / (rnh * rnh)
    mv = np.zeros((3, 3))
    mv[0, 1] = 1.0 / rnh
    mv[1, 0] = -1.0 / rmh
    mv[2, 1] = -tl / rnh

    # attitude rows
    _skew_into(F, 0, 0, wie_n + wen_n, wen_e, wie_d + wen_d, -1.0)
    for i in range(3):
        for j in range(3):
            F[i, 6 + j] -= mr_ie[i, j] + mr_en[i, j]
            F[i, 3 + j] -= mv[i, j]
    # velocity rows
    _skew_into(F, 3, 0, f_n[0], f_n[1], f_n[2], -1.0)
    _skew_into(F, 3, 3, 2.0 * wie_n + wen_n, wen_e, 2.0 * wie_d + wen_d, -1.0)
    vx = np.zeros((3, 3))
    _skew_into(vx, 0, 0, vn, ve, vd, 1.0)
    for i in range(3):
        for j in range(3):
            acc_r = 0.0
            acc_v = 0.0
            for k in range(3):
                acc_r += vx[i, k] * (2.0 * mr_ie[k, j] + mr_en[k, j])
                acc_v += vx[i, k] * mv[k, j]
            F[3 + i, 6 + j] += acc_r
            F[3 + i, 3 + j] += acc_v
    F[5, 8] += -normal_gravity_dh(lat, h)
    # position rows
    F[6, 3] = 1.0
    F[7, 4] = 1.0
    F[8, 5] = 1.0
    F[6, 6] = -vd / rmh
    F[6, 8] = vn / rmh
    F[7, 6] = ve * tl / rmh
    F[7, 7] = -(vd / rnh + vn * tl / rmh)
    F[7, 8] = ve / rnh
    # sensor errors
    i_bg, i_ba, i_sg, i_sa, i_clk = layout[L_BG], layout[L_BA], layout[L_SG], layout[L_SA], layout[L_CLK]
    for i in range(3):
        for j in range(3):
            F[i, i_bg + j] = -c_nb[i, j]
            F[3 + i, i_ba + j] = -c_nb[i, j]
            if i_sg >= 0:
                F[i, i_sg + j] = -c_nb[i, j] * w_b[j]
            if i_sa >= 0:
                F[3 + i, i_sa + j] = -c_nb[i, j] * f_b[j]
    for j in range(3):
        F[i_bg + j, i_bg + j] = -1.0 / tau[0]
        F[i_ba + j, i_ba + j] = -1.0 / tau[1]
        if i_sg >= 0:
            F[i_sg + j, i_sg + j] = -1.0 / tau[2]
        if i_sa >= 0:
            F[i_sa + j, i_sa + j] = -1.0 / tau[3]
    if i_clk >= 0:
        F[i_clk, i_clk + 1] = 1.0


@njit(cache=True)
def discretize(F, qc, T, phi, qd, tmp):
    """Discrete transition and process noise over ``T`` seconds.

    ``Phi = I + F T + (F T)^2 / 2 + (F T)^3 / 6``: the third-order term
    carries the gyro-bias -> attitude -> velocity -> position chain (``g
    T^3 / 6`` per rad/s), which the finite-difference test of
    tests/test_error_model.py sees if it is left out. For the diagonal
    continuous noise ``Qc = diag(qc)``:
    ``Qd = Qc T + (F Qc + Qc F^T) T^2/2 + F Qc F^T T^3/3`` (the series of
    the Van Loan integral to the same order). Accurate for ``T`` up to about
    a second at vehicle dynamics; the engine never propagates longer steps.
    """
    n = F.shape[0]
    # F is sparse (about a quarter of its entries are non-zero): the products
    # skip its zeros.
    # tmp <- (F T)^2 / 2
    tmp[:, :] = 0.0
    for i in range(n):
        for k in range(n):
            f = F[i, k]
            if f != 0.0:
                for j in range(n):
                    tmp[i, j] += f * F[k, j]
    for i in range(n):
        for j in range(n):
            tmp[i, j] *= 0.5 * T * T
    # phi <- I + F T + tmp + F tmp T / 3
    for i in range(n):
        for j in range(n):
            phi[i, j] = F[i, j] * T + tmp[i, j]
        for k in range(n):
            f = F[i, k]
            if f != 0.0:
                for j in range(n):
                    phi[i, j] += f * tmp[k, j] * T / 3.0
        phi[i, i] += 1.0
    discrete_noise(F, qc, T, qd)


@njit(cache=True)
def discrete_noise(F, qc, T, qd):
    """``Qd`` of :func:`discretize` alone (linear in ``qc``: mixture filters use
    it for the part of the noise whose scale differs between components)."""
    n = F.shape[0]
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(n):
                if qc[k] != 0.0:
                    s += F[i, k] * qc[k] * F[j, k]
            v = (F[i, j] * qc[j] + qc[i] * F[j, i]) * 0.5 * T * T + s * T * T * T / 3.0
            if i == j:
                v += qc[i] * T
            qd[i, j] = v
            qd[j, i] = v


@njit(cache=True)
def add_body_noise(F, qb, c, T, qd, qb_n):
    """Add the per-body-axis white noise to ``qd`` (in place).

    ``Qb`` is zero but for the attitude (0:3) and velocity (3:6) blocks,
    ``C diag(qb[0:3]) C^T`` and ``C diag(qb[3:6]) C^T`` with ``C`` the block's
    mean ``C_nb``; it enters as ``Qc`` does in :func:`discretize`:
    ``Qd += Qb T + (F Qb + Qb F^T) T^2/2 + F Qb F^T T^3/3``. ``qb_n`` (n, n)
    is scratch (holds ``Qb`` on return).
    """
    n = F.shape[0]
    qb_n[:, :] = 0.0
    for blk in range(2):
        o = 3 * blk
        for i in range(3):
            for j in range(3):
                v = 0.0
                for k in range(3):
                    v += c[i, k] * qb[o + k] * c[j, k]
                qb_n[o + i, o + j] = v
    for i in range(n):
        for j in range(i, n):
            fq_ij = 0.0
            fq_ji = 0.0
            s = 0.0
            for k in range(6):
                fq_ij += F[i, k] * qb_n[k, j]
                fq_ji += F[j, k] * qb_n[k, i]
                f = F[i, k]
                if f != 0.0:
                    for m in range(6):
                        s += f * qb_n[k, m] * F[j, m]
            v = qb_n[i, j] * T + (fq_ij + fq_ji) * 0.5 * T * T + s * T * T * T / 3.0
            qd[i, j] += v
            if j != i:
                qd[j, i] += v


@njit(cache=True)
def covariance_predict(P, phi, qd, tmp):
    """``P <- Phi P Phi^T + Qd`` in place, symmetric by construction."""
    n = P.shape[0]
    tmp[:, :] = 0.0
    for i in range(n):
        for k in range(n):
            f = phi[i, k]
            if f != 0.0:
                for j in range(n):
                    tmp[i, j] += f * P[k, j]
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(n):
                s += tmp[i, k] * phi[j, k]
            v = s + qd[i, j]
            P[i, j] = v
            P[j, i] = v


@njit(cache=True)
def propagate_block(nav, prev, sensor, dtheta, dvel, dt, P, qc, layout, tau, work, qb):
    """Mechanize a block of raw increments and propagate the covariance.

    The increments are compensated with the current sensor-error estimate
    before mechanization; the covariance takes one step over the whole block
    with ``F`` linearised at the block's end state and the block-averaged
    specific force (in NED, from the mechanization itself), body rates and
    attitude matrix.

    Parameters
    ----------
    nav : ndarray (10,), prev : ndarray (6,)
        As in :func:`mechanize_block`; updated in place.
    sensor : ndarray (12,)
        ``[bg(3), ba(3), sg(3), sa(3)]`` estimates [rad/s, m/s^2, -, -].
    dtheta, dvel : ndarray (N, 3)
        Raw (measured) increments.
    dt : ndarray (N,)
    P : ndarray (n, n)
        Error-state covariance, updated in place when ``P`` is non-empty.
    qc : ndarray (n,)
        Diagonal of the continuous process-noise spectral density.
    layout : ndarray of int64 (6,), tau : ndarray (4,)
        See :func:`error_dynamics`.
    work : ndarray (4, n, n)
        Scratch space.
    qb : ndarray (6,)
        White noise per body axis (:func:`mixnav.ins.error_model.body_noise`;
        all zero: none beyond ``qc``), added by :func:`add_body_noise`.

    Returns
    -------
    T : float
        Length of the block [s].
    """
    dth = np.empty(3)
    dv = np.empty(3)
    dvn = np.empty(3)
    f_n = np.zeros(3)
    w_b = np.zeros(3)
    f_b = np.zeros(3)
    c_sum = np.zeros((3, 3))
    c = np.empty((3, 3))
    T = 0.0
    for k in range(dtheta.shape[0]):
        h = dt[k]
        for i in range(3):
            dth[i] = (dtheta[k, i] - sensor[i] * h) / (1.0 + sensor[6 + i])
            dv[i] = (dvel[k, i] - sensor[3 + i] * h) / (1.0 + sensor[9 + i])
        quat_to_dcm_into(nav[0:4], c)
        mechanize_step(nav, dth, dv, prev[0:3], prev[3:6], h, dvn)
        for i in range(3):
            prev[i] = dth[i]
            prev[3 + i] = dv[i]
            f_n[i] += dvn[i]
            w_b[i] += dth[i]
            f_b[i] += dv[i]
            for j in range(3):
                c_sum[i, j] += c[i, j] * h
        T += h
    if P.shape[0] == 0 or T <= 0.0:
        return T
    for i in range(3):
        f_n[i] /= T
        w_b[i] /= T
        f_b[i] /= T
        for j in range(3):
            c_sum[i, j] /= T
    F, phi, qd, tmp = work[0], work[1], work[2], work[3]
    error_dynamics(F, nav, f_n, w_b, f_b, c_sum, layout, tau)
    discretize(F, qc, T, phi, qd, tmp)
    if qb[0] != 0.0 or qb[1] != 0.0 or qb[2] != 0.0 or qb[3] != 0.0 or qb[4] != 0.0 or qb[5] != 0.0:
        add_body_noise(F, qb, c_sum, T, qd, tmp)
    covariance_predict(P, phi, qd, tmp)
    return T


@njit(cache=True)
def apply_feedback(nav, sensor, clock, dx, layout):
    """Correct INS, sensor and clock estimates by the error estimate ``dx`` (in place).

    ``C_new = exp([phi x]) C_est``, ``v += dv``, position moved by ``dr``
    (NED metres), sensor and clock estimates incremented. The caller resets
    the error state to zero (closed loop).
    """
    px, py, pz = dx[0], dx[1], dx[2]
    a2 = px * px + py * py + pz * pz
    if a2 < 1e-16:
        k = 0.5 - a2 / 48.0
        qw = 1.0 - a2 / 8.0
    else:
        a = math.sqrt(a2)
        k = math.sin(0.5 * a) / a
        qw = math.cos(0.5 * a)
    qx, qy, qz = k * px, k * py, k * pz
    q0, q1, q2, q3 = nav[0], nav[1], nav[2], nav[3]
    r0 = qw * q0 - qx * q1 - qy * q2 - qz * q3
    r1 = qw * q1 + qx * q0 + qy * q3 - qz * q2
    r2 = qw * q2 - qx * q3 + qy * q0 + qz * q1
    r3 = qw * q3 + qx * q2 - qy * q1 + qz * q0
    norm = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    s = 1.0 / norm if r0 >= 0.0 else -1.0 / norm
    nav[0], nav[1], nav[2], nav[3] = r0 * s, r1 * s, r2 * s, r3 * s
    for i in range(3):
        nav[4 + i] += dx[3 + i]
    lat, h = nav[7], nav[9]
    rm, rn = radii(lat)
    nav[7] = lat + dx[6] / (rm + h)
    nav[8] += dx[7] / ((rn + h) * math.cos(lat))
    nav[9] = h - dx[8]
    i_bg, i_ba, i_sg, i_sa, i_clk = layout[L_BG], layout[L_BA], layout[L_SG], layout[L_SA], layout[L_CLK]
    for i in range(3):
        sensor[i] += dx[i_bg + i]
        sensor[3 + i] += dx[i_ba + i]
        if i_sg >= 0:
            sensor[6 + i] += dx[i_sg + i]
        if i_sa >= 0:
            sensor[9 + i] += dx[i_sa + i]
    if i_clk >= 0:
        clock[0] += dx[i_clk]
        clock[1] += dx[i_clk + 1]


@njit(cache=True)
def mechanize_batch(navs, prevs, sensors, dtheta, dvel, dt):
    """Mechanize a block of raw increments from each of N states (in place).

    The ensemble estimators' motion model (UKF sigma points, particles): the
    same compensation and mechanization step as :func:`propagate_block`, for
    every state, in one compiled call.

    Parameters
    ----------
    navs : ndarray (N, 10)
        ``[q_nb, v_n, lat, lon, h]`` per state; advanced in place.
    prevs : ndarray (N, 6)
        Previous compensated increments per state (coning/sculling); updated.
    sensors : ndarray (N, 12)
        Sensor-error estimates per state ``[bg, ba, sg, sa]``.
    dtheta, dvel : ndarray (K, 3)
        Raw increments of the block; ``dt`` (K,).
    """
    dth = np.empty(3)
    dv = np.empty(3)
    dvn = np.empty(3)
    for p in range(navs.shape[0]):
        nav, prev, sensor = navs[p], prevs[p], sensors[p]
        for k in range(dtheta.shape[0]):
            h = dt[k]
            for i in range(3):
                dth[i] = (dtheta[k, i] - sensor[i] * h) / (1.0 + sensor[6 + i])
                dv[i] = (dvel[k, i] - sensor[3 + i] * h) / (1.0 + sensor[9 + i])
            mechanize_step(nav, dth, dv, prev[0:3], prev[3:6], h, dvn)
            for i in range(3):
                prev[i] = dth[i]
                prev[3 + i] = dv[i]
