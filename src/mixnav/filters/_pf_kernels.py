"""Compiled kernels of the particle filters (numba, ``cache=True``).

- :func:`pf_step`: one propagation step of the whole particle array in one call,
  fused per particle: the particle (an error-state deviation ``D[j]`` about the
  nominal) becomes a full state ``nav0 (+) D[j]``, is mechanized with its own
  sensor errors over the step's merged IMU block, is differenced from the
  mechanized nominal, and gains its process noise ``SQ z_j``. The maps are the
  UKF's (:func:`~._ukf_kernels.nav_difference`, the engine's ``apply_feedback``,
  the strapdown ``mechanize_step``), not copies.
- :func:`pf_member_navs`: the particles of a measurement epoch as full states.
- :func:`pf_log_weights`: the Gaussian log-likelihood of each particle's
  prediction added to its log-weight, normalised (weights, ESS), and the predictions'
  prior-weighted moments and the NIS, in one pass.
- :func:`pf_moments`: the weighted mean and covariance of the particles.
- :func:`pf_jitter`: the resampled particles with the Liu-West kernel jitter.

Threads (docs/particle.md, "Speed"): the per-particle loops run over ``prange``
(numba ``parallel=True``); each particle's arithmetic depends on its own row
only, and every random number is drawn by the caller from the estimator's numpy
Generator before the call, so a seed gives the same particles bit for bit on any
thread count (tested). The sums over particles (moments) are split into a fixed
number of chunks (:data:`CHUNKS`, independent of the thread count) whose partial
sums are added in order, serially: also thread-count independent.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..ins._error_kernels import L_BA, L_BG, L_CLK, L_SA, L_SG
from ..ins._error_kernels import apply_feedback as _apply_feedback
from ..ins._kernels import mechanize_step as _mechanize_step
from ..linalg import cholesky_lower
from ._ukf_kernels import merge_block_into
from ._ukf_kernels import nav_difference as _nav_difference
from ._ukf_kernels import propagate_members

# The shared maps, compiled again to be inlined into the per-particle loops (the same
# source, so bitwise the same arithmetic; ~10 % faster than a call per particle, which
# passes and reference-counts every array view). Not cached on their own: only the
# kernels that inline them are (after editing the originals, clear __pycache__).
mechanize_step = njit(inline="always")(_mechanize_step.py_func)
apply_feedback = njit(inline="always")(_apply_feedback.py_func)
nav_difference = njit(inline="always")(_nav_difference.py_func)

#: the fixed number of partial sums of a reduction over particles (thread-count independent)
CHUNKS = 16
#: per-particle scratch row: dth (0:3), dv (3:6), dvn (6:9), clock (9:11)
SCRATCH = 11


@njit(cache=True, inline="always")
def _mechanize_one(nav, prev, sensor, scr, gth, gdv, gdt, S):
    """One state over the first ``S`` merged sub-intervals (as ``mechanize_members``)."""
    dth, dv, dvn = scr[0:3], scr[3:6], scr[6:9]
    for k in range(S):
        h = gdt[k]
        for i in range(3):
            dth[i] = (gth[k, i] - sensor[i] * h) / (1.0 + sensor[6 + i])
            dv[i] = (gdv[k, i] - sensor[3 + i] * h) / (1.0 + sensor[9 + i])
        mechanize_step(nav, dth, dv, prev[0:3], prev[3:6], h, dvn)
        for i in range(3):
            prev[i] = dth[i]
            prev[3 + i] = dv[i]


@njit(cache=True, inline="always")
def _start_member(j, nav0, prev0, sensor0, D, layout, navs, prevs, sensors, scr):
    """Row ``j`` of the scratch: the nominal, corrected by ``D[j]`` when ``j < N``."""
    for i in range(10):
        navs[j, i] = nav0[i]
    for i in range(6):
        prevs[j, i] = prev0[i]
    for i in range(12):
        sensors[j, i] = sensor0[i]
    scr[j, 9] = 0.0
    scr[j, 10] = 0.0
    if j < D.shape[0]:
        apply_feedback(navs[j], sensors[j], scr[j, 9:11], D[j], layout)


@njit(cache=True, inline="always")
def _finish_member(j, D, navs, layout, fdec, T, SQT, Z, Dn):
    """``Dn[j]``: the mechanized particle differenced from the mechanized nominal
    (row N), its sensor deviations decayed by ``fdec``, its clock moved by its drift,
    plus the process noise ``SQ z_j`` (``SQT = SQ^T``, row-wise: vectorizable)."""
    N, n = D.shape
    i_bg, i_ba, i_sg, i_sa, i_clk = layout[L_BG], layout[L_BA], layout[L_SG], layout[L_SA], layout[L_CLK]
    d = Dn[j]
    for i in range(n):
        d[i] = D[j, i]
    nav_difference(navs[j], navs[N], d)
    for i in range(3):
        d[i_bg + i] = D[j, i_bg + i] * fdec[0]
        d[i_ba + i] = D[j, i_ba + i] * fdec[1]
        if i_sg >= 0:
            d[i_sg + i] = D[j, i_sg + i] * fdec[2]
        if i_sa >= 0:
            d[i_sa + i] = D[j, i_sa + i] * fdec[3]
    if i_clk >= 0:
        d[i_clk] = D[j, i_clk] + D[j, i_clk + 1] * T
    for b in range(n):
        zb = Z[j, b]
        for a in range(n):
            Dn[j, a] += SQT[b, a] * zb


@njit(cache=True)
def _decay(tau, T, fdec):
    for b in range(4):
        fdec[b] = math.exp(-T / tau[b]) if tau[b] > 0.0 and np.isfinite(tau[b]) else 1.0


@njit(cache=True, parallel=True)
def pf_step(nav0, prev0, sensor0, D, SQT, Z, dtheta, dvel, dt, substeps, layout, tau, T,
            navs, prevs, sensors, scr, gth, gdv, gdt, fdec, Dn):
    """Propagate the particles ``D`` (N, n) about ``nav0`` over one IMU block, fused
    per particle, parallel over particles (``prange``).

    ``nav0`` (10,), ``prev0`` (6,), ``sensor0`` (12,): the nominal before the step;
    ``dtheta``, ``dvel`` (K, 3), ``dt`` (K,) the raw increments, merged into at most
    ``substeps`` sub-intervals (0: every increment); ``layout`` the INS layout array;
    ``tau`` (4,) the sensor Gauss-Markov times [s]; ``T`` the step [s]. ``SQT`` (n, n)
    the transpose of a square root of ``Qd``; ``Z`` (N, n) standard normals drawn by the
    caller. Scratch (no allocation here): ``navs`` (N+1, 10), ``prevs`` (N+1, 6),
    ``sensors`` (N+1, 12), ``scr`` (N+1, 11), ``gth``, ``gdv`` (>= S, 3), ``gdt``
    (>= S,), ``fdec`` (4,). Row N of the scratch is the reference (the nominal
    itself). ``Dn`` (N, n) receives the propagated deviations plus noise.
    """
    N = D.shape[0]
    S = merge_block_into(dtheta, dvel, dt, substeps, gth, gdv, gdt)
    _decay(tau, T, fdec)
    _start_member(N, nav0, prev0, sensor0, D, layout, navs, prevs, sensors, scr)
    _mechanize_one(navs[N], prevs[N], sensors[N], scr[N], gth, gdv, gdt, S)
    for j in prange(N):
        _start_member(j, nav0, prev0, sensor0, D, layout, navs, prevs, sensors, scr)
        _mechanize_one(navs[j], prevs[j], sensors[j], scr[j], gth, gdv, gdt, S)
        _finish_member(j, D, navs, layout, fdec, T, SQT, Z, Dn)


@njit(cache=True)
def pf_step_serial(nav0, prev0, sensor0, D, SQT, Z, dtheta, dvel, dt, substeps, layout, tau, T,
                   navs, prevs, sensors, scr, gth, gdv, gdt, fdec, Dn):
    """:func:`pf_step` compiled without ``parallel`` (the same arithmetic; for the
    serial-versus-parallel measurement in benchmarks/bench_pf.py)."""
    N = D.shape[0]
    S = merge_block_into(dtheta, dvel, dt, substeps, gth, gdv, gdt)
    _decay(tau, T, fdec)
    _start_member(N, nav0, prev0, sensor0, D, layout, navs, prevs, sensors, scr)
    _mechanize_one(navs[N], prevs[N], sensors[N], scr[N], gth, gdv, gdt, S)
    for j in range(N):
        _start_member(j, nav0, prev0, sensor0, D, layout, navs, prevs, sensors, scr)
        _mechanize_one(navs[j], prevs[j], sensors[j], scr[j], gth, gdv, gdt, S)
        _finish_member(j, D, navs, layout, fdec, T, SQT, Z, Dn)


@njit(cache=True, parallel=True)
def pf_mechanize(navs, prevs, sensors, scr, gth, gdv, gdt, S):
    """Every row of ``navs`` mechanized over ``S`` merged sub-intervals (in place,
    parallel over rows): one "IMU step" of the array, timed in benchmarks/bench_pf.py."""
    for j in prange(navs.shape[0]):
        _mechanize_one(navs[j], prevs[j], sensors[j], scr[j], gth, gdv, gdt, S)


@njit(cache=True)
def pf_mechanize_serial(navs, prevs, sensors, scr, gth, gdv, gdt, S):
    """:func:`pf_mechanize`, serial."""
    for j in range(navs.shape[0]):
        _mechanize_one(navs[j], prevs[j], sensors[j], scr[j], gth, gdv, gdt, S)


@njit(cache=True)
def pf_propagate(nav0, prev0, sensor0, D, SQ, Z, dtheta, dvel, dt, substeps, layout, tau, T,
                 navs, prevs, sensors, Dn):
    """The first (serial, unfused) propagation: members through the UKF's
    ``propagate_members``, then the noise ``SQ @ Z[j]``. Kept as the reference the
    fused :func:`pf_step` is tested against (tests/test_particle.py)."""
    N, n = D.shape
    propagate_members(nav0, prev0, sensor0, D, dtheta, dvel, dt, substeps, layout, tau, T, navs, prevs, sensors,
                      Dn)
    for j in range(N):
        for a in range(n):
            s = 0.0
            for b in range(n):
                s += SQ[a, b] * Z[j, b]
            Dn[j, a] += s


@njit(cache=True, inline="always")
def _member_nav(j, nav, D, layout, navs, sensors, scr):
    for i in range(10):
        navs[j, i] = nav[i]
    for i in range(12):
        sensors[j, i] = 0.0
    scr[j, 9] = 0.0
    scr[j, 10] = 0.0
    apply_feedback(navs[j], sensors[j], scr[j, 9:11], D[j], layout)


@njit(cache=True, parallel=True)
def pf_member_navs(nav, D, layout, navs, sensors, scr):
    """The particles ``D`` (N, n) about ``nav`` as full navigation states ``navs``
    (>= N, 10) (the engine's feedback map on a copy of ``nav``); ``sensors`` (>= N, 12)
    and ``scr`` (>= N, 11) receive the sensor and clock parts (scratch, not used).
    Parallel over particles."""
    for j in prange(D.shape[0]):
        _member_nav(j, nav, D, layout, navs, sensors, scr)


@njit(cache=True)
def pf_member_navs_serial(nav, D, layout, navs, sensors, scr):
    """:func:`pf_member_navs`, serial."""
    for j in range(D.shape[0]):
        _member_nav(j, nav, D, layout, navs, sensors, scr)


@njit(cache=True)
def add_log_likelihood(logw, y, Y, r):
    """``logw[j] += -1/2 sum_i (y_i - Y[j, i])^2 / r_i``; returns the smallest
    ``sum_i (y_i - Y[j, i])^2 / r_i`` over the particles (inf when none is finite)."""
    N, m = Y.shape
    best = np.inf
    for j in range(N):
        s = 0.0
        for i in range(m):
            e = y[i] - Y[j, i]
            s += e * e / r[i]
        logw[j] -= 0.5 * s
        if s < best:
            best = s
    return best


@njit(cache=True)
def _heaviest(w):
    """The index of the largest weight (the first, if tied)."""
    k0 = 0
    for j in range(w.shape[0]):
        if w[j] > w[k0]:
            k0 = j
    return k0


@njit(cache=True)
def pf_log_weights(logw0, w0, y, Y, r, logw, w, ym, Pyy):
    """The measurement's log-likelihood added to the prior log-weights ``logw0`` (into
    ``logw``), normalised into ``w`` (subtract the largest finite log-weight,
    exponentiate, divide by the sum; non-finite log-weights weigh 0); in the same pass
    over the predictions ``Y`` (N, m), their mean ``ym`` (m,) and covariance ``Pyy``
    (m, m) under the prior weights ``w0`` (summing to 1). Serial: every sum's order is
    fixed. Returns ``(best, ess, nis)``: the smallest squared normalised innovation over
    the particles (inf when none is finite), the effective sample size ``1 / sum w^2``
    (0 and ``w`` untouched when no log-weight is finite) and the NIS of the weighted
    mean prediction, ``e^T (Pyy + diag r)^-1 e``, ``e = y - ym`` (inf when not finite or
    that matrix is not positive definite)."""
    N, m = Y.shape
    best = np.inf
    top = -np.inf
    k0 = _heaviest(w0)
    for i in range(m):
        ym[i] = 0.0
        for k in range(m):
            Pyy[i, k] = 0.0
    for j in range(N):
        s = 0.0
        wj = w0[j]
        for i in range(m):
            e = y[i] - Y[j, i]
            s += e * e / r[i]
            wa = wj * (Y[j, i] - Y[k0, i])   # moments about the heaviest particle's (one pass)
            ym[i] += wa
            for k in range(i, m):
                Pyy[i, k] += wa * (Y[j, k] - Y[k0, k])
        lw = logw0[j] - 0.5 * s
        logw[j] = lw
        if s < best:
            best = s
        if np.isfinite(lw) and lw > top:
            top = lw
    for i in range(m):
        for k in range(i, m):
            Pyy[i, k] -= ym[i] * ym[k]
            Pyy[k, i] = Pyy[i, k]
    for i in range(m):
        ym[i] += Y[k0, i]
    nis = _nis(y, ym, Pyy, r)
    if not np.isfinite(top):
        return best, 0.0, nis
    tot = 0.0
    for j in range(N):
        lw = logw[j]
        e = math.exp(lw - top) if np.isfinite(lw) else 0.0
        w[j] = e
        tot += e
    ss = 0.0
    for j in range(N):
        w[j] /= tot
        ss += w[j] * w[j]
    return best, 1.0 / ss, nis


@njit(cache=True)
def _nis(y, ym, Pyy, r):
    """``e^T (Pyy + diag r)^-1 e``, ``e = y - ym`` (Cholesky); inf when not finite or not
    positive definite."""
    m = y.shape[0]
    S = np.empty((m, m))
    L = np.empty((m, m))
    for i in range(m):
        for k in range(m):
            S[i, k] = Pyy[i, k]
        S[i, i] += r[i]
    if not cholesky_lower(S, L):
        return np.inf
    nis = 0.0
    u = np.empty(m)
    for i in range(m):
        s = y[i] - ym[i]
        for k in range(i):
            s -= L[i, k] * u[k]
        u[i] = s / L[i, i]
        nis += u[i] * u[i]
    return nis if np.isfinite(nis) else np.inf


@njit(cache=True)
def pf_systematic(w, u0, idx):
    """Systematic resampling of the weights ``w`` (N,) with the offset ``u0`` in [0, 1)
    into ``idx`` (N,): ``idx_i`` the first ``k`` whose cumulative weight exceeds
    ``(u0 + i) / N`` (the last bin closed at 1; at most N - 1). One merge pass (the
    offsets are sorted) in place of a binary search per particle: the same indices as
    ``searchsorted(cumsum(w), (u0 + arange(N)) / N, side="right")``."""
    N = w.shape[0]
    k = 0
    c = w[0]
    for i in range(N):
        u = (u0 + i) / N
        while k < N - 1 and c <= u:
            k += 1
            c = c + w[k] if k < N - 1 else 1.0
        idx[i] = k


@njit(cache=True, inline="always")
def _mean_chunk(c, D, w, part):
    """Chunk ``c``'s ``sum w_j D_j`` into ``part[c, :n]``."""
    N, n = D.shape
    p = part[c]
    for i in range(n):
        p[i] = 0.0
    for j in range(c * N // CHUNKS, (c + 1) * N // CHUNKS):
        wj = w[j]
        for i in range(n):
            p[i] += wj * D[j, i]


@njit(cache=True, inline="always")
def _cov_chunk(c, D, w, x, part):
    """Chunk ``c``'s ``sum w_j (D_j - x)(D_j - x)^T`` (upper triangle) into ``part[c, n:]``."""
    N, n = D.shape
    p = part[c]
    for k in range(n * n):
        p[n + k] = 0.0
    for j in range(c * N // CHUNKS, (c + 1) * N // CHUNKS):
        wj = w[j]
        for a in range(n):
            da = wj * (D[j, a] - x[a])
            for b in range(a, n):   # the upper triangle, row by row (contiguous)
                p[n + a * n + b] += da * (D[j, b] - x[b])


@njit(cache=True)
def _sum_mean(part, x):
    n = x.shape[0]
    for i in range(n):
        s = 0.0
        for c in range(CHUNKS):
            s += part[c, i]
        x[i] = s


@njit(cache=True)
def _sum_cov(part, P):
    n = P.shape[0]
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            for c in range(CHUNKS):
                s += part[c, n + a * n + b]
            P[a, b] = s
            P[b, a] = s


@njit(cache=True, parallel=True)
def pf_moments(D, w, x, P, part):
    """``x = sum_j w_j D_j``, ``P = sum_j w_j (D_j - x)(D_j - x)^T`` of ``D`` (N, n).

    Two passes (the mean, then the centred products: a sum of positive semidefinite
    terms, so a collapsed or diverged cloud cannot give an indefinite covariance by
    cancellation, as a one-pass ``S2 - S1 S1^T`` did on a diverging loose-demo run), each
    over :data:`CHUNKS` fixed chunks of particles in parallel (partial sums in ``part``
    (CHUNKS, >= n + n n), scratch) added in chunk order serially: the result does not
    depend on the thread count."""
    for c in prange(CHUNKS):
        _mean_chunk(c, D, w, part)
    _sum_mean(part, x)
    for c in prange(CHUNKS):
        _cov_chunk(c, D, w, x, part)
    _sum_cov(part, P)


@njit(cache=True)
def pf_moments_serial(D, w, x, P, part):
    """:func:`pf_moments`, serial (the same chunks, the same sums: bitwise equal)."""
    for c in range(CHUNKS):
        _mean_chunk(c, D, w, part)
    _sum_mean(part, x)
    for c in range(CHUNKS):
        _cov_chunk(c, D, w, x, part)
    _sum_cov(part, P)


@njit(cache=True, inline="always")
def _jitter_one(j, D, idx, a, h, x, LT, Z, Dn):
    n = Dn.shape[1]
    k = idx[j]
    if h == 0.0:
        for i in range(n):
            Dn[j, i] = D[k, i]
    else:
        for i in range(n):
            Dn[j, i] = a * D[k, i] + (1.0 - a) * x[i]
        for b in range(n):
            zb = h * Z[j, b]
            for i in range(n):
                Dn[j, i] += LT[b, i] * zb


@njit(cache=True, parallel=True)
def pf_jitter(D, idx, a, h, x, LT, Z, Dn):
    """The resampled particles ``D[idx]`` with the Liu-West jitter, into ``Dn``:
    ``Dn[j] = a D[idx_j] + (1 - a) x + h L z_j`` (``LT = L^T``, ``Z`` (N, n) standard
    normals drawn by the caller); ``h = 0``: the plain copy. Parallel over particles."""
    for j in prange(Dn.shape[0]):
        _jitter_one(j, D, idx, a, h, x, LT, Z, Dn)


@njit(cache=True)
def pf_jitter_serial(D, idx, a, h, x, LT, Z, Dn):
    """:func:`pf_jitter`, serial."""
    for j in range(Dn.shape[0]):
        _jitter_one(j, D, idx, a, h, x, LT, Z, Dn)


@njit(cache=True, inline="always")
def _linear_one(j, D, FT, SQT, Z, Dn):
    n = D.shape[1]
    for i in range(n):
        Dn[j, i] = 0.0
    for b in range(n):
        db = D[j, b]
        zb = Z[j, b]
        for i in range(n):
            Dn[j, i] += FT[b, i] * db + SQT[b, i] * zb


@njit(cache=True, parallel=True)
def pf_linear_step(D, FT, SQT, Z, Dn):
    """``Dn[j] = F D[j] + SQ z_j`` (``FT = F^T``, ``SQT = SQ^T``, ``Z`` (N, n) standard
    normals): the propagation of a linear-Gaussian model, parallel over particles."""
    for j in prange(D.shape[0]):
        _linear_one(j, D, FT, SQT, Z, Dn)


@njit(cache=True)
def pf_linear_step_serial(D, FT, SQT, Z, Dn):
    """:func:`pf_linear_step`, serial."""
    for j in range(D.shape[0]):
        _linear_one(j, D, FT, SQT, Z, Dn)


class Kernels:
    """The kernels an estimator calls, serial or parallel (the same arithmetic)."""

    def __init__(self, parallel: bool):
        self.parallel = bool(parallel)
        sfx = "" if parallel else "_serial"
        g = globals()
        for name in ("pf_step", "pf_member_navs", "pf_moments", "pf_jitter", "pf_linear_step"):
            setattr(self, name[3:], g[name + sfx])


SERIAL = Kernels(False)
PARALLEL = Kernels(True)
