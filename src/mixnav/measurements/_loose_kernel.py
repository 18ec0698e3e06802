"""Compiled loose-coupling measurement model (see :class:`LooseGnss` for the maths).

The per-state loose prediction is written once here: :func:`antenna_from_fix` (the
antenna at a lever arm already rotated to NED, and its position relative to the fix in
NED metres, the longitude wrapped) and :func:`lever_rate` (the body rate crossed with the
lever arm, the velocity rows' lever term). Three callers inline them:
:func:`loose_zhr` (the EKF's rows, ``z = -Y``), :func:`loose_predict_batch` (``h`` at a
batch of full states: the UKF, DD2, GMPF and the particle filter's generic path) and the
particle filter's fused update (:mod:`mixnav.measurements._loose_members`), which takes
the latitudes' sines and cosines by series about the nominal's (``trig``).

What stays per caller, and why: the lever arm's rotation (the DCM of each state's
quaternion in the EKF rows and the batch; Rodrigues on the nominal's rotated lever arm in
the fused update, which builds no member state: a DCM per particle would cost it its
vector loop) and the velocity rows' order of addition (batch ``((v + C00 w0) + C01 w1) +
C02 w2``, EKF ``v + (C w)``, fused ``(v0 + dv) + exp(phi) (C0 w)``): one expression
for all would change the bits of the EKF or of the UKF/DD2/GMPF runs.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..geodesy.earth import A_WGS84, E2_WGS84
from ..ins._kernels import SMALL_DLAT, quat_to_dcm_into, radii
from ..ins._kernels import sincos_near as _sincos_near
from ..ins._kernels import sincos_series as _sincos_series

#: how :func:`antenna_from_fix` takes the sines and cosines of the state's and the
#: antenna's latitudes: the library functions and ``radii`` (the EKF rows, the batch
#: prediction); the series about a reference latitude, straight-line code that
#: vectorises, flagging where it did not hold (the particle filter's fused update);
#: ``sincos_near`` about it, exact where the series would not hold (its redo)
TRIG_PLAIN, TRIG_SERIES, TRIG_NEAR = 0, 1, 2


@njit(cache=True, inline="always")
def _radii_near(s):
    """Meridian and prime-vertical radii from ``s = sin(lat)`` with one division
    (``ins._kernels.radii`` to round-off; the fused update's, vectorised)."""
    iw = 1.0 / (1.0 - E2_WGS84 * (s * s))
    rn = A_WGS84 * math.sqrt(iw)
    return rn * (1.0 - E2_WGS84) * iw, rn


@njit(cache=True, inline="always")
def _latitude_terms(lat, trig, lat0, s0, c0):
    """The meridian and normal radii [m] and the cosine at ``lat`` [rad], by the ``trig`` mode
    of :func:`antenna_from_fix` (the state's latitude and the antenna's take the same path)."""
    if trig == TRIG_PLAIN:
        rm, rn = radii(lat)
        return rm, rn, math.cos(lat)
    if trig == TRIG_SERIES:
        sl, cl = _sincos_series(lat - lat0, s0, c0)
    else:
        sl, cl = _sincos_near(lat, lat0, s0, c0)
    rm, rn = _radii_near(sl)
    return rm, rn, cl


@njit(cache=True, inline="always")
def antenna_from_fix(lat, lon, h, cln, cle, cld, fix_lat, fix_lon, fix_h, trig, lat0, s0, c0):
    """The antenna of a state at ``lat, lon, h`` [rad, rad, m] whose lever arm rotated to
    NED is ``cln, cle, cld`` [m], relative to the fix ``fix_lat, fix_lon, fix_h``:
    ``(north, east, down, held)`` [m], NED metres with the radii at the antenna, the
    longitude difference wrapped to [-pi, pi). ``trig`` (:data:`TRIG_PLAIN`,
    :data:`TRIG_SERIES`, :data:`TRIG_NEAR`) says how the latitudes' sines and cosines are
    taken; ``lat0, s0, c0`` the reference latitude and its sine and cosine (unused with
    TRIG_PLAIN). ``held``: both latitudes within ``SMALL_DLAT`` of ``lat0`` and the
    longitude inside its wrap (with TRIG_SERIES the numbers are good only where it is
    True: no modulo there, so the loop vectorises). The modes differ in round-off only."""
    rm, rn, cl = _latitude_terms(lat, trig, lat0, s0, c0)
    a_lat = lat + cln / (rm + h)
    a_lon = lon + cle / ((rn + h) * cl)
    a_h = h - cld
    rm_a, rn_a, ca = _latitude_terms(a_lat, trig, lat0, s0, c0)
    t = fix_lon - a_lon + math.pi
    inside = (0.0 <= t) & (t < 2.0 * math.pi)
    if trig == TRIG_SERIES or inside:   # the wrap's own arithmetic, without the modulo
        dlon = t - math.pi
    else:
        dlon = t % (2.0 * math.pi) - math.pi
    held = (abs(lat - lat0) < SMALL_DLAT) & (abs(a_lat - lat0) < SMALL_DLAT) & inside
    return -(fix_lat - a_lat) * (rm_a + a_h), -dlon * (rn_a + a_h) * ca, fix_h - a_h, held


@njit(cache=True, inline="always")
def lever_rate(wx, wy, wz, l0, l1, l2):
    """``w x l``: the body rate ``w`` [rad/s] crossed with the lever arm ``l`` [m] (body
    frame [m/s]; rotated to NED it is the antenna's velocity relative to the IMU)."""
    return wy * l2 - wz * l1, wz * l0 - wx * l2, wx * l1 - wy * l0


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
    m = 6 if use_vel else 3
    z = np.empty(m)
    H = np.zeros((m, n))
    r = np.empty(m)
    # NED displacement fix - antenna, radii at the antenna estimate: minus the prediction
    y0, y1, y2, _ = antenna_from_fix(nav[7], nav[8], nav[9], cl[0], cl[1], cl[2], lla_fix[0], lla_fix[1],
                                     lla_fix[2], TRIG_PLAIN, 0.0, 0.0, 0.0)
    z[0], z[1], z[2] = -y0, -y1, -y2
    # H_pos = [-[(C l) x], 0, I]
    H[0, 1], H[0, 2] = cl[2], -cl[1]
    H[1, 0], H[1, 2] = -cl[2], cl[0]
    H[2, 0], H[2, 1] = cl[1], -cl[0]
    for i in range(3):
        H[i, 6 + i] = 1.0
        r[i] = pos_sig[i] * pos_sig[i]
    if use_vel:
        wl0, wl1, wl2 = lever_rate(w_b[0], w_b[1], w_b[2], lever[0], lever[1], lever[2])
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
        Y[j, 0], Y[j, 1], Y[j, 2], _ = antenna_from_fix(nav[7], nav[8], nav[9], cl[0], cl[1], cl[2], fix[0],
                                                        fix[1], fix[2], TRIG_PLAIN, 0.0, 0.0, 0.0)
        if use_vel:
            w = w_b[j]
            wl0, wl1, wl2 = lever_rate(w[0], w[1], w[2], lever[0], lever[1], lever[2])
            for i in range(3):
                Y[j, 3 + i] = nav[4 + i] + c[i, 0] * wl0 + c[i, 1] * wl1 + c[i, 2] * wl2
