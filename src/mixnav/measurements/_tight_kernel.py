"""Compiled tight-coupling measurement model (see :class:`TightGnss` for the maths).

One call per GNSS epoch: antenna position and velocity, line of sight, the
innovations, ``H`` and the noise variances of every valid satellite slot,
without per-satellite Python or temporary numpy arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..ins._kernels import E2, quat_to_dcm_into, radii


@njit(cache=True)
def tight_zhr(nav, lever, w_b, clock, sat_pos, sat_vel, pr, rr, valid, sig_pr, sig_rr, use_rr,
              n, i_bg, i_clk, sys_idx, offsets, i_off):
    """Innovation, Jacobian and noise variances of one epoch.

    Parameters
    ----------
    nav : ndarray (10,)
    lever, w_b : ndarray (3,)
        Antenna lever arm (body) [m]; compensated body rate [rad/s].
    clock : ndarray (2,)
        Clock bias [m] and drift [m/s] estimates.
    sat_pos, sat_vel : ndarray (K, 3)
        ECEF, receive-time frame [m], [m/s].
    pr, rr : ndarray (K,)
        Pseudorange [m] and range rate [m/s].
    valid : ndarray of bool (K,)
    sig_pr, sig_rr : float
    use_rr : bool
    n, i_bg, i_clk : int
        Number of states and first index of the gyro-bias and clock blocks.
    sys_idx : ndarray of int (K,)
        Each slot's system: 0 the clock's reference system, ``g >= 1`` the system of
        inter-system offset ``offsets[g]``.
    offsets : ndarray (S,)
        ``[0, o_1, ..., o_{S-1}]`` [m]: the offset each system adds to the pseudorange.
    i_off : int
        First index of the ``system_offset`` block (-1: one system, no offset columns).

    Returns
    -------
    z (m,), H (m, n), r (m,), with ``m = ns`` or ``2 ns`` for ``ns`` valid slots
    (pseudoranges first).
    """
    K = valid.shape[0]
    ns = 0
    for k in range(K):
        if valid[k]:
            ns += 1
    m = 2 * ns if use_rr else ns
    z = np.empty(m)
    H = np.zeros((m, n))
    r = np.empty(m)
    ra, cne, ln, c = _frame(nav, lever)
    wl = np.empty(3)   # C_nb (w x l)
    wxl0 = w_b[1] * lever[2] - w_b[2] * lever[1]
    wxl1 = w_b[2] * lever[0] - w_b[0] * lever[2]
    wxl2 = w_b[0] * lever[1] - w_b[1] * lever[0]
    va_n = np.empty(3)
    for i in range(3):
        wl[i] = c[i, 0] * wxl0 + c[i, 1] * wxl1 + c[i, 2] * wxl2
        va_n[i] = nav[4 + i] + wl[i]
    # C_nb [l x] for the gyro-bias columns of the range rate
    clx = np.empty((3, 3))
    for i in range(3):
        clx[i, 0] = c[i, 1] * lever[2] - c[i, 2] * lever[1]
        clx[i, 1] = -c[i, 0] * lever[2] + c[i, 2] * lever[0]
        clx[i, 2] = c[i, 0] * lever[1] - c[i, 1] * lever[0]
    j = 0
    d = np.empty(3)
    un = np.empty(3)
    for k in range(K):
        if not valid[k]:
            continue
        rho2 = 0.0
        for i in range(3):
            d[i] = sat_pos[k, i] - ra[i]
            rho2 += d[i] * d[i]
        rho = math.sqrt(rho2)
        us = 0.0
        for i in range(3):
            d[i] /= rho
            us += d[i] * sat_vel[k, i]
        for i in range(3):
            un[i] = cne[i, 0] * d[0] + cne[i, 1] * d[1] + cne[i, 2] * d[2]
        g = sys_idx[k]
        z[j] = pr[k] - (rho + clock[0] + offsets[g])   # + 0.0 for the reference system: bit for bit
        if i_off >= 0 and g > 0:
            H[j, i_off + g - 1] = 1.0
        # u_n^T [l_n x]
        H[j, 0] = un[1] * ln[2] - un[2] * ln[1]
        H[j, 1] = un[2] * ln[0] - un[0] * ln[2]
        H[j, 2] = un[0] * ln[1] - un[1] * ln[0]
        H[j, 6], H[j, 7], H[j, 8] = -un[0], -un[1], -un[2]
        H[j, i_clk] = 1.0
        r[j] = sig_pr * sig_pr
        if use_rr:
            q = ns + j
            z[q] = rr[k] - (us - (un[0] * va_n[0] + un[1] * va_n[1] + un[2] * va_n[2]) + clock[1])
            H[q, 0] = un[1] * wl[2] - un[2] * wl[1]
            H[q, 1] = un[2] * wl[0] - un[0] * wl[2]
            H[q, 2] = un[0] * wl[1] - un[1] * wl[0]
            H[q, 3], H[q, 4], H[q, 5] = -un[0], -un[1], -un[2]
            for b in range(3):
                H[q, i_bg + b] = -(un[0] * clx[0, b] + un[1] * clx[1, b] + un[2] * clx[2, b])
            H[q, i_clk + 1] = 1.0
            r[q] = sig_rr * sig_rr
        j += 1
    return z, H, r


@njit(cache=True)
def _frame(nav, lever):
    """Antenna ECEF position, ``C_ne`` (rows N, E, D in ECEF), ``l_n = C_nb l`` and ``C_nb``."""
    c = np.empty((3, 3))
    quat_to_dcm_into(nav[0:4], c)
    lat, lon, h = nav[7], nav[8], nav[9]
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    cne = np.empty((3, 3))
    cne[0, 0], cne[0, 1], cne[0, 2] = -sl * co, -sl * so, cl
    cne[1, 0], cne[1, 1], cne[1, 2] = -so, co, 0.0
    cne[2, 0], cne[2, 1], cne[2, 2] = -cl * co, -cl * so, -sl
    _, rn = radii(lat)
    ln = np.empty(3)
    for i in range(3):
        ln[i] = c[i, 0] * lever[0] + c[i, 1] * lever[1] + c[i, 2] * lever[2]
    ra = np.empty(3)
    ra[0] = (rn + h) * cl * co
    ra[1] = (rn + h) * cl * so
    ra[2] = (rn * (1.0 - E2) + h) * sl
    for i in range(3):
        ra[i] += cne[0, i] * ln[0] + cne[1, i] * ln[1] + cne[2, i] * ln[2]
    return ra, cne, ln, c


@njit(cache=True)
def antenna_frame(nav, lever):
    """Antenna ECEF position [m], ``C_ne`` (ECEF -> NED at the IMU) and ``l_n = C_nb l``."""
    ra, cne, ln, _ = _frame(nav, lever)
    return ra, cne, ln


@njit(cache=True)
def tdcp_rows(z, H, r, row0, ra, cne, ln, clock_bias, sat_now, sat_prev, carrier_now, carrier_prev,
              r_prev, cne_prev, b_prev, sig_cp, clone, n, i_clk):
    """Fill the TDCP rows ``row0:`` of ``(z, H, r)`` in place (mixnav.measurements.tdcp,
    P1 eq. (3)): one row per satellite tracked at both epochs, ``sat_now``/``sat_prev``
    (k, 3) ECEF at each epoch, ``r_prev``/``cne_prev``/``b_prev`` the cloned antenna
    position, its ECEF->NED and clock bias. With ``clone`` the clone columns are
    ``n:n+4`` (position NED, clock bias)."""
    k = sat_now.shape[0]
    lx = np.empty((3, 3))
    lx[0, 0], lx[0, 1], lx[0, 2] = 0.0, -ln[2], ln[1]
    lx[1, 0], lx[1, 1], lx[1, 2] = ln[2], 0.0, -ln[0]
    lx[2, 0], lx[2, 1], lx[2, 2] = -ln[1], ln[0], 0.0
    d = np.empty(3)
    un = np.empty(3)
    for j in range(k):
        q = row0 + j
        for a in range(3):
            d[a] = sat_now[j, a] - ra[a]
        rho = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        for a in range(3):
            un[a] = (cne[a, 0] * d[0] + cne[a, 1] * d[1] + cne[a, 2] * d[2]) / rho
        for a in range(3):
            d[a] = sat_prev[j, a] - r_prev[a]
        rho_c = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        z[q] = (carrier_now[j] - carrier_prev[j]) - (rho + clock_bias - rho_c - b_prev)
        for b in range(3):
            H[q, b] = un[0] * lx[0, b] + un[1] * lx[1, b] + un[2] * lx[2, b]
            H[q, 6 + b] = -un[b]
        H[q, i_clk] = 1.0
        if clone:
            for a in range(3):
                H[q, n + a] = (cne_prev[a, 0] * d[0] + cne_prev[a, 1] * d[1] + cne_prev[a, 2] * d[2]) / rho_c
            H[q, n + 3] = -1.0
        r[q] = 2.0 * sig_cp * sig_cp


@njit(cache=True)
def tight_predict_batch(navs, lever, w_b, clocks, sat_pos, sat_vel, valid, use_rr, sys_idx, offsets, Y):
    """Predicted pseudoranges (then range rates) of the valid slots at each of N states,
    in one call (see ``TightGnss.predict_batch``): ``navs`` (N, 10), ``w_b`` (N, 3),
    ``clocks`` (N, 2) bias [m] and drift [m/s], ``offsets`` (N, S) each state's
    inter-system offsets (column 0 zero: the reference system), ``sys_idx`` (K,) each
    slot's column of it; ``Y`` (N, m) written."""
    K = valid.shape[0]
    d = np.empty(3)
    un = np.empty(3)
    va_n = np.empty(3)
    for p in range(navs.shape[0]):
        nav = navs[p]
        ra, cne, ln, c = _frame(nav, lever)
        w = w_b[p]
        wxl0 = w[1] * lever[2] - w[2] * lever[1]
        wxl1 = w[2] * lever[0] - w[0] * lever[2]
        wxl2 = w[0] * lever[1] - w[1] * lever[0]
        for i in range(3):
            va_n[i] = nav[4 + i] + c[i, 0] * wxl0 + c[i, 1] * wxl1 + c[i, 2] * wxl2
        ns = 0
        for k in range(K):
            if valid[k]:
                ns += 1
        j = 0
        for k in range(K):
            if not valid[k]:
                continue
            rho2 = 0.0
            for i in range(3):
                d[i] = sat_pos[k, i] - ra[i]
                rho2 += d[i] * d[i]
            rho = math.sqrt(rho2)
            us = 0.0
            for i in range(3):
                d[i] /= rho
                us += d[i] * sat_vel[k, i]
            Y[p, j] = rho + clocks[p, 0] + offsets[p, sys_idx[k]]
            if use_rr:
                for i in range(3):
                    un[i] = cne[i, 0] * d[0] + cne[i, 1] * d[1] + cne[i, 2] * d[2]
                Y[p, ns + j] = us - (un[0] * va_n[0] + un[1] * va_n[1] + un[2] * va_n[2]) + clocks[p, 1]
            j += 1
