"""Compiled strapdown kernels (numba, ``cache=True``).

The hot loop of every filter: one call mechanizes a block of IMU increments
(and, for the error-state filters, propagates the covariance over the block).
Everything here is scalar arithmetic on preallocated arrays: no allocation
per IMU step, no Python objects, so one step costs about a microsecond.

Navigation state vector ``nav`` (float64, length 10)::

    nav[0:4]  q_nb, Hamilton, scalar first (body to NED)
    nav[4:7]  v_n   velocity north, east, down [m/s]
    nav[7:10] lat [rad], lon [rad], h [m]

Algorithm (Savage 1998; Shin 2001; as in KF-GINS): two-sample coning and
sculling corrections with the previous increment, velocity projected with the
half-interval rotation of the n-frame, gravity/Coriolis and the n-frame
rotation evaluated at the extrapolated mid-point, trapezoidal position update.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..geodesy import earth as _earth

OMEGA_EARTH = _earth.OMEGA_EARTH
E2 = _earth.E2_WGS84
A = _earth.A_WGS84

# geodesy/earth.py's formulas compiled: from sin(lat) (inlined into the mechanization,
# which takes each latitude's sine once for the radii, the rates and gravity) and, as
# earth.radii / normal_gravity do in numpy, from the latitude
_radii_s = njit(inline="always")(_earth.radii_from_sin)
_gravity_s = njit(inline="always")(_earth.normal_gravity_from_sin)
normal_gravity_dh = njit(cache=True)(_earth.normal_gravity_dh)


@njit(cache=True)
def radii(lat):
    """:func:`mixnav.geodesy.earth.radii`, compiled (meridian, prime-vertical) [m]."""
    return _radii_s(np.sin(lat))


@njit(cache=True)
def normal_gravity(lat, h):
    """:func:`mixnav.geodesy.earth.normal_gravity`, compiled [m/s^2]."""
    return _gravity_s(np.sin(lat), h)

NAV_SIZE = 10


@njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def _rv2q(x, y, z):
    """Rotation vector to quaternion, series-safe near zero."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-16:
        k = 0.5 - a2 / 48.0
        return 1.0 - a2 / 8.0, k * x, k * y, k * z
    a = math.sqrt(a2)
    k = math.sin(0.5 * a) / a
    return math.cos(0.5 * a), k * x, k * y, k * z


@njit(cache=True, inline="always")
def _qmul(pw, px, py, pz, qw, qx, qy, qz):
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


@njit(cache=True)
def quat_to_dcm_into(q, c):
    """Write ``C_nb`` of unit quaternion ``q`` (length 4) into ``c`` (3x3)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    c[0, 0] = w * w + x * x - y * y - z * z
    c[0, 1] = 2.0 * (x * y - w * z)
    c[0, 2] = 2.0 * (x * z + w * y)
    c[1, 0] = 2.0 * (x * y + w * z)
    c[1, 1] = w * w - x * x + y * y - z * z
    c[1, 2] = 2.0 * (y * z - w * x)
    c[2, 0] = 2.0 * (x * z - w * y)
    c[2, 1] = 2.0 * (y * z + w * x)
    c[2, 2] = w * w - x * x - y * y + z * z


#: modes of :func:`mechanize_core`, compile-time constants at each call site (the branches
#: they select are folded away): ``PLAIN`` the library's sin/cos everywhere (every filter);
#: ``RECORD`` the same, writing each latitude's sin and cos into ``trig`` (a particle
#: filter's nominal); ``NEAR`` sin and cos of each latitude from the recorded ones by the
#: angle sum with series (:func:`sincos_near`) and the rotation vectors' sin and cos by
#: their series (:func:`_rv2q_near`) (the particles: ~40 % faster, round-off apart the
#: same numbers; docs/particle.md)
PLAIN, RECORD, NEAR = 0, 1, 2
#: |latitude - reference latitude| [rad] below which :func:`sincos_near` uses the series
#: of the difference (truncation below 1e-22 relative at the bound, 6 km); beyond it
#: math.sin/cos
SMALL_DLAT = 1e-3
#: |rotation vector|^2 [rad^2] below which :func:`_rv2q_near` uses series (truncation
#: below 1e-19 relative at the bound, 0.1 rad); beyond it math.sin/cos
SMALL_ROT2 = 1e-2
#: the latitudes of one increment whose sin and cos ``trig`` holds (RECORD / NEAR)
TRIG_POINTS = 4
_NO_TRIG = np.zeros((TRIG_POINTS, 3))


@njit(cache=True, inline="always")
def sincos_series(d, s0, c0):
    """``sin(lat0 + d), cos(lat0 + d)`` from ``s0, c0 = sin(lat0), cos(lat0)``: the angle
    sum with the series of ``d`` to ``d^5`` (sin) and ``d^6`` (cos); for ``|d| <
    SMALL_DLAT``."""
    d2 = d * d      # products by the constants' reciprocals (folded by Python): no division
    sd = d * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0)))
    cd = 1.0 - 0.5 * d2 * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0)))
    return s0 * cd + c0 * sd, c0 * cd - s0 * sd


@njit(cache=True, inline="always")
def sincos_near(lat, lat0, s0, c0):
    """``sin(lat), cos(lat)``: :func:`sincos_series` of ``lat - lat0`` while that is below
    ``SMALL_DLAT``; the library functions beyond."""
    d = lat - lat0
    if abs(d) < SMALL_DLAT:
        return sincos_series(d, s0, c0)
    return math.sin(lat), math.cos(lat)


@njit(cache=True, inline="always")
def _rv2q_near(x, y, z):
    """:func:`_rv2q` with ``cos(a/2)`` and ``sin(a/2)/a`` by their series to ``a^8`` while
    ``a^2 < SMALL_ROT2``."""
    a2 = x * x + y * y + z * z
    if a2 < SMALL_ROT2:
        c = 1.0 - a2 * 0.125 * (1.0 - a2 * (1.0 / 48.0) * (1.0 - a2 * (1.0 / 120.0) * (1.0 - a2 * (1.0 / 224.0))))
        k = 0.5 * (1.0 - a2 * (1.0 / 24.0) * (1.0 - a2 * (1.0 / 80.0) * (1.0 - a2 * (1.0 / 168.0)
                                                                          * (1.0 - a2 * (1.0 / 288.0)))))
        return c, k * x, k * y, k * z
    return _rv2q(x, y, z)


@njit(cache=True, inline="always")
def _rv2q_mode(x, y, z, mode):
    """:func:`_rv2q_near` in NEAR mode, :func:`_rv2q` otherwise."""
    if mode == NEAR:
        return _rv2q_near(x, y, z)
    return _rv2q(x, y, z)


@njit(cache=True, inline="always")
def _lat_sincos(lat, trig, i, mode):
    """sin and cos of the latitude ``lat``, point ``i`` of an increment, as ``mode`` says."""
    if mode == NEAR:
        return sincos_near(lat, trig[i, 0], trig[i, 1], trig[i, 2])
    s, c = math.sin(lat), math.cos(lat)
    if mode == RECORD:
        trig[i, 0], trig[i, 1], trig[i, 2] = lat, s, c
    return s, c


@njit(cache=True, inline="always")
def _omega_sc(sl, cl, h, vn, ve, rm, rn):
    """Earth rate plus transport rate in NED (the Earth rate's north and down, the
    transport rate's north, east and down) from ``sl, cl = sin(lat), cos(lat)``."""
    wie_n, wie_d = OMEGA_EARTH * cl, -OMEGA_EARTH * sl
    wen_n = ve / (rn + h)
    wen_e = -vn / (rm + h)
    wen_d = -ve * sl / cl / (rn + h)
    return wie_n, wie_d, wen_n, wen_e, wen_d


@njit(cache=True, inline="always")
def mechanize_core(nav, dth, dvb, dth_prev, dv_prev, dt, dvn_out, trig, mode):
    """:func:`mechanize_step` with the trigonometry as ``mode`` says (``PLAIN``,
    ``RECORD``, ``NEAR``; ``trig`` (TRIG_POINTS, 3): lat, sin, cos of the increment's four
    latitudes, written by RECORD, read by NEAR). In PLAIN mode bitwise the former
    ``mechanize_step`` (each latitude's sin and cos taken once and shared by the radii,
    the rates and gravity, which took them again: the same values)."""
    q0, q1, q2, q3 = nav[0], nav[1], nav[2], nav[3]
    vn, ve, vd = nav[4], nav[5], nav[6]
    lat, lon, h = nav[7], nav[8], nav[9]
    ax, ay, az = dth[0], dth[1], dth[2]
    ux, uy, uz = dvb[0], dvb[1], dvb[2]
    px, py, pz = dth_prev[0], dth_prev[1], dth_prev[2]
    wx, wy, wz = dv_prev[0], dv_prev[1], dv_prev[2]

    # --- velocity: rotation and sculling compensation in the body frame
    r1 = _cross(ax, ay, az, ux, uy, uz)
    s1 = _cross(px, py, pz, ux, uy, uz)
    s2 = _cross(wx, wy, wz, ax, ay, az)
    fbx = ux + 0.5 * r1[0] + (s1[0] + s2[0]) / 12.0
    fby = uy + 0.5 * r1[1] + (s1[1] + s2[1]) / 12.0
    fbz = uz + 0.5 * r1[2] + (s1[2] + s2[2]) / 12.0
    # body increment to the n-frame at the start of the interval
    cbx = (q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * fbx + 2.0 * (q1 * q2 - q0 * q3) * fby + 2.0 * (q1 * q3 + q0 * q2) * fbz
    cby = 2.0 * (q1 * q2 + q0 * q3) * fbx + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * fby + 2.0 * (q2 * q3 - q0 * q1) * fbz
    cbz = 2.0 * (q1 * q3 - q0 * q2) * fbx + 2.0 * (q2 * q3 + q0 * q1) * fby + (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * fbz

    # predictor: Earth terms at the start of the interval
    sl0, cl0 = _lat_sincos(lat, trig, 0, mode)
    rm0, rn0 = _radii_s(sl0)
    wie_n, wie_d, wen_n, wen_e, wen_d = _omega_sc(sl0, cl0, h, vn, ve, rm0, rn0)
    g = _gravity_s(sl0, h)
    zx, zy, zz = (wie_n + wen_n) * dt, wen_e * dt, (wie_d + wen_d) * dt
    t = _cross(zx, zy, zz, cbx, cby, cbz)
    dfn, dfe, dfd = cbx - 0.5 * t[0], cby - 0.5 * t[1], cbz - 0.5 * t[2]
    c = _cross(2.0 * wie_n + wen_n, wen_e, 2.0 * wie_d + wen_d, vn, ve, vd)
    mvn = vn + 0.5 * (dfn - c[0] * dt)
    mve = ve + 0.5 * (dfe - c[1] * dt)
    mvd = vd + 0.5 * (dfd + (g - c[2]) * dt)
    mh = h - 0.5 * mvd * dt
    mlat = lat + 0.5 * mvn * dt / (rm0 + mh)

    # corrector: Earth terms at the mid-point
    sl, cl = _lat_sincos(mlat, trig, 1, mode)
    rm, rn = _radii_s(sl)
    wie_n, wie_d, wen_n, wen_e, wen_d = _omega_sc(sl, cl, mh, mvn, mve, rm, rn)
    g = _gravity_s(sl, mh)
    zx, zy, zz = (wie_n + wen_n) * dt, wen_e * dt, (wie_d + wen_d) * dt
    t = _cross(zx, zy, zz, cbx, cby, cbz)
    dfn, dfe, dfd = cbx - 0.5 * t[0], cby - 0.5 * t[1], cbz - 0.5 * t[2]
    c = _cross(2.0 * wie_n + wen_n, wen_e, 2.0 * wie_d + wen_d, mvn, mve, mvd)
    nvn = vn + dfn - c[0] * dt
    nve = ve + dfe - c[1] * dt
    nvd = vd + dfd + (g - c[2]) * dt
    dvn_out[0], dvn_out[1], dvn_out[2] = dfn, dfe, dfd

    # --- position: trapezoidal in velocity, radii at the mid-point
    nh = h - 0.5 * (vd + nvd) * dt
    mh = 0.5 * (h + nh)
    nlat = lat + 0.5 * (vn + nvn) * dt / (rm0 + mh)
    mlat = 0.5 * (lat + nlat)
    rm, rn = _radii_s(_lat_sincos(mlat, trig, 2, mode)[0])
    nlat = lat + 0.5 * (vn + nvn) * dt / (rm + mh)
    mlat = 0.5 * (lat + nlat)
    sl, cl = _lat_sincos(mlat, trig, 3, mode)
    nlon = lon + 0.5 * (ve + nve) * dt / ((rn + mh) * cl)

    # --- attitude: q_nb(k) = q_nn * q_nb(k-1) * q_bb, rates at the mid-point
    cn = _cross(px, py, pz, ax, ay, az)
    bq = _rv2q_mode(ax + cn[0] / 12.0, ay + cn[1] / 12.0, az + cn[2] / 12.0, mode)
    rm, rn = _radii_s(sl)
    wie_n, wie_d, wen_n, wen_e, wen_d = _omega_sc(sl, cl, mh, 0.5 * (vn + nvn), 0.5 * (ve + nve), rm, rn)
    nq = _rv2q_mode(-(wie_n + wen_n) * dt, -wen_e * dt, -(wie_d + wen_d) * dt, mode)
    r = _qmul(q0, q1, q2, q3, bq[0], bq[1], bq[2], bq[3])
    r = _qmul(nq[0], nq[1], nq[2], nq[3], r[0], r[1], r[2], r[3])
    norm = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3])
    s = 1.0 / norm if r[0] >= 0.0 else -1.0 / norm

    nav[0], nav[1], nav[2], nav[3] = r[0] * s, r[1] * s, r[2] * s, r[3] * s
    nav[4], nav[5], nav[6] = nvn, nve, nvd
    nav[7], nav[8], nav[9] = nlat, nlon, nh


@njit(cache=True)
def mechanize_step(nav, dth, dvb, dth_prev, dv_prev, dt, dvn_out):
    """Advance ``nav`` in place by one IMU increment.

    Parameters
    ----------
    nav : ndarray (10,)
        Navigation state, updated in place.
    dth, dvb : ndarray (3,)
        Compensated angle [rad] and velocity [m/s] increments of this interval.
    dth_prev, dv_prev : ndarray (3,)
        Increments of the previous interval (for coning and sculling).
    dt : float
        Interval length [s].
    dvn_out : ndarray (3,)
        Receives the specific-force velocity increment projected to NED
        [m/s]; the covariance propagation uses it as the mean specific force.
    """
    mechanize_core(nav, dth, dvb, dth_prev, dv_prev, dt, dvn_out, _NO_TRIG, PLAIN)


@njit(cache=True)
def mechanize_block(nav, prev, dtheta, dvel, dt, out):
    """Mechanize a block of increments, in place on ``nav`` and ``prev``.

    Parameters
    ----------
    nav : ndarray (10,)
        Navigation state at the start of the block; holds the end state after.
    prev : ndarray (6,)
        Previous angle and velocity increment ``[dth(3), dv(3)]``; holds the
        block's last increment after.
    dtheta, dvel : ndarray (N, 3)
        Compensated angle [rad] and velocity [m/s] increments.
    dt : ndarray (N,)
        Interval lengths [s].
    out : ndarray (N, 10) or (0, 10)
        Receives the state after each increment, when it has N rows.
    """
    dvn = np.empty(3)
    store = out.shape[0] == dtheta.shape[0]
    for k in range(dtheta.shape[0]):
        mechanize_step(nav, dtheta[k], dvel[k], prev[0:3], prev[3:6], dt[k], dvn)
        prev[0:3] = dtheta[k]
        prev[3:6] = dvel[k]
        if store:
            out[k, :] = nav
