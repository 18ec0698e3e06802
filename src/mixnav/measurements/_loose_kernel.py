"""Compiled loose-coupling measurement model (see :class:`LooseGnss` for the maths)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..ins._kernels import quat_to_dcm_into, radii


@njit(cache=True)
def loose_zhr(nav, lever, fix, w_b, use_vel, n, i_bg):
    """Innovation, Jacobian and noise variances of one GNSS fix.

    ``fix`` is one row ``[lat, lon, h, sN, sE, sD, vN, vE, vD, svN, svE, svD]``
    (rad, m, m/s). Returns ``z (m,)``, ``H (m, n)``, ``r (m,)`` with
    ``m = 6`` when ``use_vel`` else 3.
    """
    lla_fix = fix[0:3]
    pos_sig = fix[3:6]
    vel_fix = fix[6:9]
    vel_sig = fix[9:12]
    c = np.empty((3, 3))
    quat_to_dcm_into(nav[0:4], c)
    cl = np.empty(3)
    for i in range(3):
        cl[i] = c[i, 0] * lever[0] + c[i, 1] * lever[1] + c[i, 2] * lever[2]
    lat, lon, h = nav[7], nav[8], nav[9]
    rm, rn = radii(lat)
    ant_lat = lat + cl[0] / (rm + h)
    ant_lon = lon + cl[1] / ((rn + h) * math.cos(lat))
    ant_h = h - cl[2]
    m = 6 if use_vel else 3
    z = np.empty(m)
    H = np.zeros((m, n))
    r = np.empty(m)
    # NED displacement fix - antenna, radii at the antenna estimate
    rm_a, rn_a = radii(ant_lat)
    dlon = lla_fix[1] - ant_lon
    dlon = (dlon + math.pi) % (2.0 * math.pi) - math.pi
    z[0] = (lla_fix[0] - ant_lat) * (rm_a + ant_h)
    z[1] = dlon * (rn_a + ant_h) * math.cos(ant_lat)
    z[2] = -(lla_fix[2] - ant_h)
    # H_pos = [-[(C l) x], 0, I]
    H[0, 1], H[0, 2] = cl[2], -cl[1]
    H[1, 0], H[1, 2] = -cl[2], cl[0]
    H[2, 0], H[2, 1] = cl[1], -cl[0]
    for i in range(3):
        H[i, 6 + i] = 1.0
        r[i] = pos_sig[i] * pos_sig[i]
    if use_vel:
        wl0 = w_b[1] * lever[2] - w_b[2] * lever[1]
        wl1 = w_b[2] * lever[0] - w_b[0] * lever[2]
        wl2 = w_b[0] * lever[1] - w_b[1] * lever[0]
        cw = np.empty(3)
        for i in range(3):
            cw[i] = c[i, 0] * wl0 + c[i, 1] * wl1 + c[i, 2] * wl2
            z[3 + i] = vel_fix[i] - (nav[4 + i] + cw[i])
            H[3 + i, 3 + i] = 1.0
            r[3 + i] = vel_sig[i] * vel_sig[i]
        H[3, 1], H[3, 2] = cw[2], -cw[1]
        H[4, 0], H[4, 2] = -cw[2], cw[0]
        H[5, 0], H[5, 1] = cw[1], -cw[0]
        # C [l x] on the gyro-bias columns
        lx = np.zeros((3, 3))
        lx[0, 1], lx[0, 2] = -lever[2], lever[1]
        lx[1, 0], lx[1, 2] = lever[2], -lever[0]
        lx[2, 0], lx[2, 1] = -lever[1], lever[0]
        for i in range(3):
            for j in range(3):
                H[3 + i, i_bg + j] = c[i, 0] * lx[0, j] + c[i, 1] * lx[1, j] + c[i, 2] * lx[2, j]
    return z, H, r


@njit(cache=True)
def loose_predict_batch(navs, lever, fix, w_b, use_vel, Y):
    """``h`` of one fix at each of N states, in one call (see ``LooseGnss.predict_batch``).

    ``navs`` (N, 10), ``w_b`` (N, 3) body rates, ``Y`` (N, m) written: the antenna
    position in NED metres from the fix (radii at each state's antenna), then with
    ``use_vel`` the antenna velocity [m/s].
    """
    c = np.empty((3, 3))
    cl = np.empty(3)
    for j in range(navs.shape[0]):
        nav = navs[j]
        quat_to_dcm_into(nav[0:4], c)
        for i in range(3):
            cl[i] = c[i, 0] * lever[0] + c[i, 1] * lever[1] + c[i, 2] * lever[2]
        lat, lon, h = nav[7], nav[8], nav[9]
        rm, rn = radii(lat)
        a_lat = lat + cl[0] / (rm + h)
        a_lon = lon + cl[1] / ((rn + h) * math.cos(lat))
        a_h = h - cl[2]
        rm_a, rn_a = radii(a_lat)
        dlon = (fix[1] - a_lon + math.pi) % (2.0 * math.pi) - math.pi
        Y[j, 0] = -(fix[0] - a_lat) * (rm_a + a_h)
        Y[j, 1] = -dlon * (rn_a + a_h) * math.cos(a_lat)
        Y[j, 2] = fix[2] - a_h
        if use_vel:
            w = w_b[j]
            wl0 = w[1] * lever[2] - w[2] * lever[1]
            wl1 = w[2] * lever[0] - w[0] * lever[2]
            wl2 = w[0] * lever[1] - w[1] * lever[0]
            for i in range(3):
                Y[j, 3 + i] = nav[4 + i] + c[i, 0] * wl0 + c[i, 1] * wl1 + c[i, 2] * wl2
