"""The loose GNSS model's fused update of an ensemble's members (numba, ``cache=True``):
:meth:`~mixnav.measurements.loose.LooseGnss.member_update` hands it to the particle filter
(the seam: :class:`~mixnav.measurements.base.MemberUpdate`), which never names the model.

- :func:`pf_loose_update`: a loose GNSS update straight from the particle array (each
  particle's position and velocity prediction from its attitude, position and the lever
  arm, no full state built), state-major per chunk (vectorised): log-weights, NIS,
  weights, effective sample size, weighted mean and covariance; its sums over particles
  in the fixed chunks of :data:`mixnav.linalg.CHUNKS`, as the particle filter's other
  kernels.
- :func:`pf_loose_predict`: the predictions alone (tested against ``predict_batch``).

The members are error-state deviations ``D`` (N, n) about the nominal over an INS layout
(attitude rotation vector 0:3, velocity 3:6, NED position 6:9, the gyro bias at the
layout's ``bg``); each member's position is the engine's feedback map's (the same
expressions), its attitude enters only through Rodrigues' rotation of the nominal's
rotated lever arm. The prediction itself is the loose model's one per-state function,
:func:`~mixnav.measurements._loose_kernel.antenna_from_fix` (with the latitudes' sines by
series about the nominal's: ``TRIG_SERIES``, ``TRIG_NEAR``) and ``lever_rate``.

Each kernel with a parallel loop is one body (``prange``) compiled twice by
:func:`mixnav._jit.serial_and_parallel`: ``name`` (parallel) and ``name_serial``; the
threading contract is filters/_pf_kernels.py's (bitwise the same on any thread count).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._jit import serial_and_parallel
from ..ins._error_kernels import L_BG
from ..ins._kernels import quat_to_dcm_into, radii
from ..linalg import CHUNKS
from ..linalg import chunk_dots_cols as _chunk_dots_cols
from ..linalg import heaviest as _heaviest
from ..linalg import innovation_nis as _nis
from ..linalg import sum_chunked_cov as _sum_cov
from ._loose_kernel import TRIG_NEAR, TRIG_SERIES, antenna_from_fix, lever_rate


#: |rotation vector|^2 [rad^2] below which Rodrigues' coefficients come from their series
#: (truncation below 3e-18 at the bound, 0.1 rad); beyond it math.sin
SMALL_ROT2 = 1e-2
#: entries of the per-epoch constants of :func:`_loose_constants`
LOOSE_CONSTANTS = 16


@njit(cache=True, inline="always")
def _rodrigues_series(a2):
    """``sin a / a`` and ``(1 - cos a) / a^2`` by their series to ``a^8`` (``a2 = a^2 <
    SMALL_ROT2``)."""
    s = 1.0 - a2 * (1.0 / 6.0) * (1.0 - a2 * (1.0 / 20.0) * (1.0 - a2 * (1.0 / 42.0) * (1.0 - a2 * (1.0 / 72.0))))
    c = 0.5 * (1.0 - a2 * (1.0 / 12.0) * (1.0 - a2 * (1.0 / 30.0) * (1.0 - a2 * (1.0 / 56.0)
                                                                      * (1.0 - a2 * (1.0 / 90.0)))))
    return s, c


@njit(cache=True, inline="always")
def _rodrigues(px, py, pz):
    """``(s, c)`` with ``exp([p x]) = I + s [p x] + c [p x]^2``: ``sin a / a`` and
    ``(1 - cos a) / a^2``, ``a = |p|`` (series to ``a^8`` while ``a^2 < SMALL_ROT2``)."""
    a2 = px * px + py * py + pz * pz
    if a2 < SMALL_ROT2:
        return _rodrigues_series(a2)
    a = math.sqrt(a2)
    t = math.sin(0.5 * a) / a
    return math.sin(a) / a, 2.0 * t * t


@njit(cache=True, inline="always")
def _rotate(px, py, pz, s, c, vx, vy, vz):
    """``exp([p x]) v = v + s p x v + c p x (p x v)`` (``s, c`` from :func:`_rodrigues`)."""
    tx, ty, tz = py * vz - pz * vy, pz * vx - px * vz, px * vy - py * vx
    ux, uy, uz = py * tz - pz * ty, pz * tx - px * tz, px * ty - py * tx
    return vx + s * tx + c * ux, vy + s * ty + c * uy, vz + s * tz + c * uz


@njit(cache=True)
def _loose_constants(nav, w_b, lever, fix, g, C0, y, r):
    """The epoch's constants for :func:`_loose_member`: ``g`` = [lat0, lon0, h0,
    rm0 + h0, (rn0 + h0) cos lat0, sin lat0, cos lat0, C0 l (3), v0 (3), w_b (3)], ``C0``
    the nominal's ``C_nb``; the measurement ``y`` (zero position rows, the fix's velocity)
    and its variances ``r`` (``len(y)`` rows: 3 or 6)."""
    quat_to_dcm_into(nav[0:4], C0)
    lat, h = nav[7], nav[9]
    rm, rn = radii(lat)
    g[0], g[1], g[2] = lat, nav[8], h
    g[3] = rm + h                       # the feedback map's denominators (bitwise the same)
    g[4] = (rn + h) * math.cos(lat)
    g[5], g[6] = math.sin(lat), math.cos(lat)
    for i in range(3):
        g[7 + i] = C0[i, 0] * lever[0] + C0[i, 1] * lever[1] + C0[i, 2] * lever[2]
        g[10 + i] = nav[4 + i]
        g[13 + i] = w_b[i]
    for i in range(y.shape[0]):
        if i < 3:
            y[i] = 0.0
            r[i] = fix[3 + i] * fix[3 + i]
        else:
            y[i] = fix[3 + i]
            r[i] = fix[6 + i] * fix[6 + i]


@njit(cache=True, inline="always")
def _loose_velocity_values(px, py, pz, s, c, vx, vy, vz, bx, by, bz, g, C0, lever):
    """The velocity rows of a loose prediction: ``v0 + d_v + C_j ((w_b - d_bg) x l)``, ``C_j =
    exp([p x]) C0`` (``s, c`` from :func:`_rodrigues`); ``g``, ``C0``, ``lever`` tuples."""
    wl0, wl1, wl2 = lever_rate(g[13] - bx, g[14] - by, g[15] - bz, lever[0], lever[1], lever[2])
    ux = C0[0] * wl0 + C0[1] * wl1 + C0[2] * wl2
    uy = C0[3] * wl0 + C0[4] * wl1 + C0[5] * wl2
    uz = C0[6] * wl0 + C0[7] * wl1 + C0[8] * wl2
    cx, cy, cz = _rotate(px, py, pz, s, c, ux, uy, uz)
    return (g[10] + vx) + cx, (g[11] + vy) + cy, (g[12] + vz) + cz


@njit(cache=True, inline="always")
def _loose_position_values(px, py, pz, s, c, dn, de, dd, g, fix, series):
    """The position rows of a loose prediction and whether they held: the member's
    position by the feedback map, its lever arm rotated by Rodrigues, then the loose
    model's :func:`~mixnav.measurements._loose_kernel.antenna_from_fix` with the latitudes'
    sines and cosines about the nominal's: by series when ``series`` (straight-line code;
    the flag then says whether both latitude differences were below ``SMALL_DLAT`` and
    the longitude needed no wrap), else by ``sincos_near`` with the full wrap."""
    clx, cly, clz = _rotate(px, py, pz, s, c, g[7], g[8], g[9])
    lat = g[0] + dn / g[3]       # the feedback map's position (its denominators: bitwise the same)
    lon = g[1] + de / g[4]
    h = g[2] - dd
    return antenna_from_fix(lat, lon, h, clx, cly, clz, fix[0], fix[1], fix[2],
                            TRIG_SERIES if series else TRIG_NEAR, g[0], g[5], g[6])


@njit(cache=True, inline="always")
def _loose_tuples(g, C0, lever, fix):
    """The epoch's constants as tuples (registers in the loops, no aliasing with the stores)."""
    G = (g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8], g[9], g[10], g[11], g[12], g[13], g[14], g[15])
    C = (C0[0, 0], C0[0, 1], C0[0, 2], C0[1, 0], C0[1, 1], C0[1, 2], C0[2, 0], C0[2, 1], C0[2, 2])
    return G, C, (lever[0], lever[1], lever[2]), (fix[0], fix[1], fix[2])


@njit(cache=True)
def _loose_member(d, i_bg, g, C0, lever, fix, yrow):
    """The loose prediction of the particle ``d`` (an error-state row) into ``yrow``
    (3 or 6): what ``LooseGnss.predict_batch`` gives at the full state ``nominal (+) d``
    with the body rate ``w_b - d[bg]``, without building that state. The attitude enters
    only through ``C_j = exp([phi x]) C0`` acting on the lever arm (Rodrigues on ``C0 l``
    and ``C0 (w x l)``: the feedback map's quaternion product, then its DCM, in exact
    arithmetic); the position is the feedback map's (the same expressions); sin and cos
    of the particle's and its antenna's latitudes come from the nominal's
    (:func:`_sincos_near`). Round-off apart, the generic path's numbers. With branches:
    for the rows :func:`_loose_predict_soa`'s series could not do."""
    G, C, L, F = _loose_tuples(g, C0, lever, fix)
    px, py, pz = d[0], d[1], d[2]
    s, c = _rodrigues(px, py, pz)
    yrow[0], yrow[1], yrow[2], _ = _loose_position_values(px, py, pz, s, c, d[6], d[7], d[8], G, F, False)
    if yrow.shape[0] > 3:
        yrow[3], yrow[4], yrow[5] = _loose_velocity_values(px, py, pz, s, c, d[3], d[4], d[5], d[i_bg],
                                                           d[i_bg + 1], d[i_bg + 2], G, C, L)


@njit(cache=True, error_model="numpy")
def _loose_predict_soa(j0, j1, DT, D, i_bg, g, C0, lever, fix, YT):
    """``YT[:, j0:j1]`` (m = 3 or 6 rows, state-major) the loose predictions of the particles
    ``j0..j1``, read from their transposed deviations ``DT`` (n, N): every function by its
    series (:func:`_rodrigues_series`, :func:`_sincos_series`), no branch, so the compiler
    runs four particles per vector instruction; the particles where a series was used
    beyond its bound or the longitude needs its wrap are then redone by
    :func:`_loose_member` (rare: marked NaN in the first loop). Where the series held,
    bitwise :func:`_loose_member`'s numbers (the same expressions). ``error_model="numpy"``:
    no zero-division check, which would keep the loop scalar."""
    G, C, L, F = _loose_tuples(g, C0, lever, fix)
    k = j1 - j0         # zero-based loops over row slices: provably non-negative indices, vectorised
    dx, dy, dz, dn, de, dd = DT[0, j0:j1], DT[1, j0:j1], DT[2, j0:j1], DT[6, j0:j1], DT[7, j0:j1], DT[8, j0:j1]
    y0, y1, y2 = YT[0, j0:j1], YT[1, j0:j1], YT[2, j0:j1]
    for t in range(k):
        px, py, pz = dx[t], dy[t], dz[t]
        a2 = px * px + py * py + pz * pz
        s, c = _rodrigues_series(a2)
        u0, u1, u2, ok = _loose_position_values(px, py, pz, s, c, dn[t], de[t], dd[t], G, F, True)
        y0[t] = u0 if ok & (a2 < SMALL_ROT2) else np.nan
        y1[t] = u1
        y2[t] = u2
    if YT.shape[0] > 3:
        vx, vy, vz = DT[3, j0:j1], DT[4, j0:j1], DT[5, j0:j1]
        bx, by, bz = DT[i_bg, j0:j1], DT[i_bg + 1, j0:j1], DT[i_bg + 2, j0:j1]
        y3, y4, y5 = YT[3, j0:j1], YT[4, j0:j1], YT[5, j0:j1]
        for t in range(k):
            px, py, pz = dx[t], dy[t], dz[t]
            s, c = _rodrigues_series(px * px + py * py + pz * pz)
            y3[t], y4[t], y5[t] = _loose_velocity_values(px, py, pz, s, c, vx[t], vy[t], vz[t], bx[t], by[t], bz[t],
                                                         G, C, L)
    row = np.empty(YT.shape[0])
    for t in range(j0, j1):
        if not YT[0, t] == YT[0, t]:
            _loose_member(D[t], i_bg, g, C0, lever, fix, row)
            for i in range(YT.shape[0]):
                YT[i, t] = row[i]


@njit(cache=True, error_model="numpy")
def _transpose_into(D, j0, j1, DT):
    """``DT[:, j0:j1] = D[j0:j1].T``."""
    for j in range(j0, j1):
        for a in range(D.shape[1]):
            DT[a, j] = D[j, a]


@njit(cache=True)
def pf_loose_predict(D, layout, nav, w_b, lever, fix, YT):
    """``YT`` (m, N; m = 3 or 6) the loose predictions of the particles ``D`` (N, n) about
    ``nav`` (10,) with the body rate ``w_b`` (3,) [rad/s], the antenna ``lever`` (3,) [m]
    and the fix row ``fix`` (12,) (:func:`_loose_predict_soa`, as in the update; tested
    against the generic path)."""
    N, n = D.shape
    g = np.empty(LOOSE_CONSTANTS)
    C0 = np.empty((3, 3))
    m = YT.shape[0]
    _loose_constants(nav, w_b, lever, fix, g, C0, np.empty(m), np.empty(m))
    DT = np.empty((n, N))
    _transpose_into(D, 0, N, DT)
    _loose_predict_soa(np.int64(0), N, DT, D, layout[L_BG], g, C0, lever, fix, YT)   # not a literal 0: one compile with _loose_chunk's call


@njit(cache=True, error_model="numpy", fastmath={"reassoc"})
def _chunk_sums(W, j0, j1, p):
    """``p[a] = sum_t W[a, t]`` over ``j0 <= t < j1`` (summed in vector lanes: see
    :func:`_chunk_dots_cols`)."""
    for a in range(W.shape[0]):
        wa = W[a, j0:j1]
        s = 0.0
        for t in range(j1 - j0):
            s += wa[t]
        p[a] = s


@njit(cache=True, error_model="numpy", fastmath={"reassoc"})
def _weight_sums(w, DT, j0, j1, p):
    """``p`` = [sum w_t, sum w_t^2, sum_t w_t DT[a, t] (n)] over ``j0 <= t < j1`` (in
    vector lanes: see :func:`_chunk_dots_cols`)."""
    wc = w[j0:j1]
    s0, s1 = 0.0, 0.0
    for t in range(j1 - j0):
        s0 += wc[t]
        s1 += wc[t] * wc[t]
    p[0], p[1] = s0, s1
    for a in range(DT.shape[0]):
        da = DT[a, j0:j1]
        s = 0.0
        for t in range(j1 - j0):
            s += wc[t] * da[t] if wc[t] != 0.0 else 0.0    # a weightless non-finite row adds 0, not NaN
        p[2 + a] = s


@njit(cache=True, error_model="numpy")
def _loose_chunk(c, D, i_bg, g, C0, lever, fix, y, ir, logw0, w0, yk0, YT, logw, yp, DT, S):
    """Chunk ``c`` (particles ``j0..j1``) of the fused update's first pass: the chunk's
    deviations transposed into ``DT`` (n, N; kept for the later passes), their
    predictions (``YT``, :func:`_loose_predict_soa`), squared normalised innovations (``ir``
    the inverse noise variances; into ``S`` (N,)) and log-weights (into ``logw``); ``yp[c]`` = [smallest
    squared normalised innovation, largest finite log-weight, prior-weighted sums of
    ``Y_j - yk0`` (m) and of their products (m m, upper triangle)]. Every loop runs
    along the particles on contiguous rows (vectorised); the same compiled function for
    both kernel twins, so the same sums on any thread count."""
    N = D.shape[0]
    m = y.shape[0]
    j0, j1 = c * N // CHUNKS, (c + 1) * N // CHUNKS
    _transpose_into(D, j0, j1, DT)
    _loose_predict_soa(j0, j1, DT, D, i_bg, g, C0, lever, fix, YT)
    k = j1 - j0         # zero-based loops over row slices (vectorised: _loose_predict_soa)
    C, W = np.empty((m, k)), np.empty((m, k))   # the chunk's own: stays in cache
    Sc, w0c, lw0c, lwc = S[j0:j1], w0[j0:j1], logw0[j0:j1], logw[j0:j1]
    for t in range(k):
        Sc[t] = 0.0
    for i in range(m):
        yi, ri, ki = y[i], ir[i], yk0[i]
        Yi, Ci, Wi = YT[i, j0:j1], C[i], W[i]
        for t in range(k):
            e = yi - Yi[t]
            Sc[t] += e * e * ri
            u = Yi[t] - ki            # moments about the heaviest particle's (one pass)
            Ci[t] = u
            Wi[t] = w0c[t] * u
    best, top = np.inf, -np.inf
    for t in range(k):
        lw = lw0c[t] - 0.5 * Sc[t]
        lwc[t] = lw
        if Sc[t] < best:
            best = Sc[t]
        if np.isfinite(lw) and lw > top:
            top = lw
    p = yp[c]
    p[0], p[1] = best, top
    _chunk_sums(W, 0, k, p[2:])
    _chunk_dots_cols(W, C, 0, k, 2 + m, p)


@njit(cache=True, error_model="numpy")
def _exp_chunk(c, logw, top, w, DT, pa):
    """Chunk ``c``: ``w_j = exp(logw_j - top)`` (0 when not finite); ``pa[c]`` = [sum w_j,
    sum w_j^2, sum w_j D_j (n)], ``D`` from its transpose ``DT`` (n, N)."""
    N = logw.shape[0]
    j0, j1 = c * N // CHUNKS, (c + 1) * N // CHUNKS
    lwc, wc = logw[j0:j1], w[j0:j1]
    for t in range(j1 - j0):
        lw = lwc[t]
        wc[t] = math.exp(lw - top) if np.isfinite(lw) else 0.0
    _weight_sums(w, DT, j0, j1, pa[c])


@njit(cache=True, error_model="numpy")
def _normalise_cov_chunk(c, w, tot, x, DT, part):
    """Chunk ``c``: ``w_j /= tot``; ``part[c, n:]`` the upper triangle of
    ``sum w_j (D_j - x)(D_j - x)^T`` from the transposed deviations ``DT`` (n, N)."""
    N = w.shape[0]
    n = x.shape[0]
    j0, j1 = c * N // CHUNKS, (c + 1) * N // CHUNKS
    k = j1 - j0         # zero-based loops over row slices (vectorised: _loose_predict_soa)
    E, W = np.empty((n, k)), np.empty((n, k))   # the chunk's own: stays in cache
    wc = w[j0:j1]
    for t in range(k):
        wc[t] = wc[t] / tot
    for a in range(n):
        xa = x[a]
        Da, Ea, Wa = DT[a, j0:j1], E[a], W[a]
        for t in range(k):
            e = Da[t] - xa if wc[t] != 0.0 else 0.0      # a weightless non-finite row adds 0, not NaN
            Ea[t] = e
            Wa[t] = wc[t] * e
    _chunk_dots_cols(W, E, 0, k, n, part[c])


@njit(cache=True)
def _sum_loose(yp, yk0, ym, Pyy):
    """The chunks' partial sums of :func:`_loose_chunk` added in chunk order: ``(best,
    top)`` returned, ``ym`` and ``Pyy`` the prior-weighted mean and covariance of ``Y``."""
    m = ym.shape[0]
    best, top = np.inf, -np.inf
    for c in range(CHUNKS):
        if yp[c, 0] < best:
            best = yp[c, 0]
        if yp[c, 1] > top:
            top = yp[c, 1]
    for i in range(m):
        s = 0.0
        for c in range(CHUNKS):
            s += yp[c, 2 + i]
        ym[i] = s
    for i in range(m):
        for k in range(i, m):
            s = 0.0
            for c in range(CHUNKS):
                s += yp[c, 2 + m + i * m + k]
            Pyy[i, k] = s - ym[i] * ym[k]
            Pyy[k, i] = Pyy[i, k]
    for i in range(m):
        ym[i] += yk0[i]
    return best, top


@njit(cache=True)
def _sum_exp(pa, x):
    """``(tot, sum of squares)`` of :func:`_exp_chunk`'s chunks in order; ``x`` the mean."""
    n = x.shape[0]
    tot, sq = 0.0, 0.0
    for c in range(CHUNKS):
        tot += pa[c, 0]
        sq += pa[c, 1]
    for i in range(n):
        s = 0.0
        for c in range(CHUNKS):
            s += pa[c, 2 + i]
        x[i] = s / tot
    return tot, sq


@njit(cache=True)
def _loose_prologue(D, layout, nav, w_b, lever, fix, w0, m, work):
    """What both twins of :func:`pf_loose_update` compute before their chunk loops: the
    gyro-bias index, the epoch's constants (:func:`_loose_constants`), the measurement
    ``y``, its variances ``r`` and their inverses, the heaviest particle's prediction (the
    point the NIS moments are taken about), and the views of ``work``: the transposed
    particles ``DT`` (n, N) and the squared innovations ``S`` (N,)."""
    n = D.shape[1]
    i_bg = layout[L_BG]
    g = np.empty(LOOSE_CONSTANTS)
    C0 = np.empty((3, 3))
    y, r, yk0 = np.empty(m), np.empty(m), np.empty(m)
    _loose_constants(nav, w_b, lever, fix, g, C0, y, r)
    _loose_member(D[_heaviest(w0)], i_bg, g, C0, lever, fix, yk0)
    return i_bg, g, C0, y, r, 1.0 / r, yk0, work[0:n], work[n]


def _pf_loose_update(D, nav, w_b, logw0, w0, thr, YT, logw, w, ym, Pyy, x, P, yp, pa, part, work, layout, lever,
                     fix):
    """A loose GNSS update of the particles ``D`` (N, n), fused, parallel over the
    :data:`CHUNKS` chunks: each particle's prediction (into ``YT`` (m, N), m = 3 or 6,
    state-major), its log-likelihood added to the prior log-weight ``logw0`` (into
    ``logw``), the prior-weighted (``w0``) moments of the predictions ``ym``, ``Pyy`` and
    the NIS; then, unless degenerate (no finite log-weight, or the smallest squared
    normalised innovation beyond ``thr``), the normalised weights ``w``, the effective
    sample size and the weighted mean ``x`` (n,) and covariance ``P`` (n, n), in two more
    passes. ``nav`` (10,) the nominal, ``w_b`` (3,) [rad/s]; last, the model's constants
    (:meth:`~mixnav.measurements.loose.LooseGnss.member_update`): ``layout`` the INS layout
    array, ``lever`` (3,) [m], ``fix`` the fix's row (12,: lat, lon, h [rad, m], position
    sigmas [m], velocity, velocity sigmas [m/s]). Scratch: ``yp`` (CHUNKS, >= 2 + m + m m), ``pa`` (CHUNKS, >= 2 + n), ``part``
    (CHUNKS, >= n + n n), ``work`` (n + 1, N): the particles transposed (state-major)
    once, so that every later loop runs along contiguous rows, four particles per vector
    instruction. Every sum over particles is taken in fixed chunks added in order, each
    by the same compiled function: bitwise the serial twin's on any thread count.
    Returns ``(best, ess, nis)`` as ``filters._pf_kernels.pf_log_weights`` (``ess`` 0 when
    degenerate): the contract of :class:`~mixnav.measurements.base.MemberUpdate`."""
    i_bg, g, C0, y, r, ir, yk0, DT, S = _loose_prologue(D, layout, nav, w_b, lever, fix, w0, YT.shape[0], work)
    for c in prange(CHUNKS):
        _loose_chunk(np.int64(c), D, i_bg, g, C0, lever, fix, y, ir, logw0, w0, yk0, YT, logw, yp, DT, S)
    best, top = _sum_loose(yp, yk0, ym, Pyy)
    nis = _nis(y, ym, Pyy, r)
    if not np.isfinite(top) or not best <= thr:
        return best, 0.0, nis
    for c in prange(CHUNKS):
        _exp_chunk(np.int64(c), logw, top, w, DT, pa)
    tot, sq = _sum_exp(pa, x)
    for c in prange(CHUNKS):
        _normalise_cov_chunk(np.int64(c), w, tot, x, DT, part)
    _sum_cov(part, P)
    return best, tot * tot / sq, nis


pf_loose_update_serial, pf_loose_update = serial_and_parallel(_pf_loose_update, "pf_loose_update")


def warm_loose_update(layout, n: int, parallel: bool = False) -> None:
    """Compile (or load from numba's cache) :func:`pf_loose_update` (``parallel``) or its
    serial twin for 3 and 6 rows, on three members over the layout array ``layout``."""
    kernel = pf_loose_update if parallel else pf_loose_update_serial
    N = 3
    nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.5, 0.5, 0.0])
    D = np.zeros((N, n))
    w = np.full(N, 1.0 / N)
    fix = np.r_[nav[7:10], np.ones(3), np.zeros(3), np.ones(3)]
    for m in (3, 6):
        kernel(D, nav, np.zeros(3), np.zeros(N), w, 1e8, np.empty((m, N)), np.empty(N), np.empty(N), np.empty(m),
               np.empty((m, m)), np.empty(n), np.empty((n, n)), np.empty((CHUNKS, 2 + m + m * m)), np.empty((CHUNKS, 2 + n)),
               np.empty((CHUNKS, n + n * n)), np.empty((n + 1, N)), layout, np.zeros(3), fix)
