"""numba: the strapdown INS on a batch of member states (sigma points, particles).

What :class:`~mixnav.ins.strapdown.StrapdownMotion` runs for the ensemble estimators
(``member_states``, ``propagate_members``, ``difference_members``): members are
error states ``D_j`` about a nominal, turned into full states ``nominal (+) D_j`` by
the engine's feedback map (:func:`~mixnav.ins._error_kernels.apply_feedback`),
mechanized over an IMU block (merged into at most ``substeps`` sub-intervals) and
differenced back against a reference mechanized the same way. Moved here from
``filters/_ukf_kernels.py`` unchanged (the same operations in the same order: the
estimators' numbers are bitwise those of before).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._error_kernels import L_BA, L_BG, L_CLK, L_SA, L_SG, apply_feedback
from ._kernels import mechanize_step, radii

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
def member_navs(nav, D, layout, navs):
    """The members ``D`` (N, n) (sigma points, particles) about ``nav`` as full navigation
    states ``navs`` (N, 10) (the engine's feedback map applied to a copy of ``nav``)."""
    sensor = np.zeros(12)
    clock = np.zeros(2)
    for j in range(D.shape[0]):
        for i in range(10):
            navs[j, i] = nav[i]
        apply_feedback(navs[j], sensor, clock, D[j], layout)
