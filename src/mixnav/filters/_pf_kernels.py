"""Compiled kernels of the particle filters (numba, ``cache=True``).

- the strapdown kernels (the fused propagation step, the particles as full states) live
  in :mod:`mixnav.ins._particle_kernels`, reached through the motion model
  (:meth:`~mixnav.ins.strapdown.StrapdownMotion.particle_kernels`); a fused measurement
  update is the measurement model's (``member_update``: the loose model's in
  :mod:`mixnav.measurements._loose_members`): this module knows neither.
- :func:`pf_log_weights`: the Gaussian log-likelihood of each particle's
  prediction added to its log-weight, normalised (weights, ESS), and the predictions'
  prior-weighted moments and the NIS, in one pass.
- :func:`pf_moments`: the weighted mean and covariance of the particles.
- :func:`pf_jitter`: the resampled particles with the Liu-West kernel jitter;
  :func:`pf_jitter_drawn` the same with its normals drawn in the kernel (:mod:`._normals`),
  the one the estimator calls (``pf_jitter``: the reference it is tested against);
  likewise :func:`pf_linear_step_drawn` and :func:`pf_linear_step` (linear-Gaussian models).

Each kernel with a parallel loop is one body (``prange``) compiled twice by
:func:`mixnav._jit.serial_and_parallel`: ``name`` (parallel) and ``name_serial``.

Threads (docs/particle.md, "Speed"): the per-particle loops run over ``prange``
(numba ``parallel=True``); each particle's arithmetic depends on its own row
only (and on the nominal's recorded latitudes' sin and cos, written before the
parallel loop), and every random number is drawn by the caller from the estimator's numpy
Generator before the call (the jitter's normals: from one stream per fixed chunk of
particles, seeded by the caller from that Generator), so a seed gives the same particles
bit for bit on any thread count (tested). The sums over particles (moments) are split into a fixed
number of chunks (:data:`CHUNKS`, independent of the thread count) whose partial
sums are added in order, serially: also thread-count independent.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._jit import serial_and_parallel
from ..linalg import CHUNKS
from ..linalg import chunk_dots_cols as _chunk_dots_cols
from ..linalg import heaviest as _heaviest
from ..linalg import innovation_nis as _nis
from ..linalg import sum_chunked_cov as _sum_cov
from ._normals import standard_normals_into


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
        if wj != 0.0:       # a weightless non-finite row adds 0, not NaN
            for i in range(n):
                p[i] += wj * D[j, i]


@njit(cache=True, inline="always")
def _cov_chunk(c, D, w, x, part):
    """Chunk ``c``'s ``sum w_j (D_j - x)(D_j - x)^T`` (upper triangle) into ``part[c, n:]``:
    the chunk's centred deviations transposed (state-major, ``E``) and weighted (``W``),
    then one dot product per pair of states (:func:`_chunk_dots_cols`)."""
    N, n = D.shape
    j0, j1 = c * N // CHUNKS, (c + 1) * N // CHUNKS
    k = j1 - j0
    E = np.empty((n, k))
    W = np.empty((n, k))
    for t in range(k):
        wj = w[j0 + t]
        for a in range(n):
            e = D[j0 + t, a] - x[a] if wj != 0.0 else 0.0   # a weightless non-finite row adds 0
            E[a, t] = e
            W[a, t] = wj * e
    _chunk_dots_cols(W, E, 0, k, n, part[c])


@njit(cache=True)
def _sum_mean(part, x):
    n = x.shape[0]
    for i in range(n):
        s = 0.0
        for c in range(CHUNKS):
            s += part[c, i]
        x[i] = s



def _pf_moments(D, w, x, P, part):
    """``x = sum_j w_j D_j``, ``P = sum_j w_j (D_j - x)(D_j - x)^T`` of ``D`` (N, n).

    Two passes (the mean, then the centred products: a sum of positive semidefinite
    terms, so a collapsed or diverged cloud cannot give an indefinite covariance by
    cancellation, as a one-pass ``S2 - S1 S1^T`` did on a diverging loose-demo run), each
    over :data:`CHUNKS` fixed chunks of particles (in parallel in :func:`pf_moments`;
    partial sums in ``part`` (CHUNKS, >= n + n n), scratch) added in chunk order serially:
    the result does not depend on the thread count."""
    for c in prange(CHUNKS):
        _mean_chunk(np.int64(c), D, w, part)
    _sum_mean(part, x)
    for c in prange(CHUNKS):
        _cov_chunk(np.int64(c), D, w, x, part)
    _sum_cov(part, P)


pf_moments_serial, pf_moments = serial_and_parallel(_pf_moments, "pf_moments")


@njit(cache=True, error_model="numpy")
def _jitter_chunk(c, D, idx, a, h, x, hL, ZT, Dn):
    """Chunk ``c`` of :func:`pf_jitter`: state-major in a scratch ``B`` (n, chunk) of its
    own (it stays in cache), each state a row along the particles (``a D[idx] + (1 - a)
    x`` gathered, then one ``hL[i, b] z_b`` row after another: vector instructions, the
    same sum order as one particle at a time), then written to the particles' rows
    ``Dn[j0:j1]``."""
    N, n = Dn.shape
    j0, j1 = c * N // CHUNKS, (c + 1) * N // CHUNKS
    if h == 0.0:
        for t in range(j0, j1):
            k = idx[t]
            for i in range(n):
                Dn[t, i] = D[k, i]
        return
    k = j1 - j0         # zero-based loops over row slices (vectorised: measurements._loose_members)
    B = np.empty((n, k))
    for t in range(k):          # the drawn rows, read whole, into columns
        r = idx[j0 + t]
        for i in range(n):
            B[i, t] = a * D[r, i] + (1.0 - a) * x[i]
    for i in range(n):
        Bi = B[i]
        for b in range(i + 1):   # row i of h L (lower triangular)
            hb = hL[i, b]
            Zb = ZT[b, j0:j1]
            for t in range(k):
                Bi[t] += hb * Zb[t]
    for t in range(k):
        for i in range(n):
            Dn[j0 + t, i] = B[i, t]


def _pf_jitter(D, idx, a, h, x, hL, ZT, Dn):
    """The resampled particles ``D[idx]`` with the Liu-West jitter, into ``Dn``:
    ``Dn[j] = a D[idx_j] + (1 - a) x + (h L) z_j`` (``hL`` (n, n) the lower-triangular
    ``h L``, ``L L^T`` the weighted covariance: only its lower triangle is read; ``ZT``
    (n, N) standard normals drawn by the caller, ``z_j`` its column ``j``); ``h = 0``:
    the plain copy. Over the :data:`CHUNKS` chunks (in parallel in :func:`pf_jitter`)."""
    for c in prange(CHUNKS):
        _jitter_chunk(np.int64(c), D, idx, a, h, x, hL, ZT, Dn)


pf_jitter_serial, pf_jitter = serial_and_parallel(_pf_jitter, "pf_jitter")


@njit(cache=True, error_model="numpy")
def _draw_chunk(c, seeds, ZT):
    """Chunk ``c``'s columns of ``ZT`` (n, N) filled with standard normals from the
    chunk's own stream, started at ``seeds[c]`` (state by state, particle by particle)."""
    N = ZT.shape[1]
    j0, j1 = c * N // CHUNKS, (c + 1) * N // CHUNKS
    spill = np.empty(1, dtype=np.uint64)
    s = seeds[c]
    for b in range(ZT.shape[0]):
        s = standard_normals_into(s, ZT[b, j0:j1], spill)


def _pf_jitter_drawn(D, idx, a, h, x, hL, seeds, ZT, Dn):
    """:func:`pf_jitter` with its normals drawn here: chunk ``c`` fills its columns of
    ``ZT`` (n, N) from the stream ``seeds[c]`` (:data:`CHUNKS` uint64 seeds from the
    caller's Generator; :mod:`._normals`), then jitters its particles (while its normals
    are in cache). ``h = 0``: the plain copy, no draws. The same particles on any
    thread count (each chunk's stream is its own)."""
    for c in prange(CHUNKS):
        if h != 0.0:
            _draw_chunk(np.int64(c), seeds, ZT)
        _jitter_chunk(np.int64(c), D, idx, a, h, x, hL, ZT, Dn)


pf_jitter_drawn_serial, pf_jitter_drawn = serial_and_parallel(_pf_jitter_drawn, "pf_jitter_drawn")


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


def _pf_linear_step(D, FT, SQT, Z, Dn):
    """``Dn[j] = F D[j] + SQ z_j`` (``FT = F^T``, ``SQT = SQ^T``, ``Z`` (N, n) standard
    normals): the propagation of a linear-Gaussian model (over particles in parallel in
    :func:`pf_linear_step`)."""
    for j in prange(D.shape[0]):
        _linear_one(np.int64(j), D, FT, SQT, Z, Dn)


pf_linear_step_serial, pf_linear_step = serial_and_parallel(_pf_linear_step, "pf_linear_step")


def _pf_linear_step_drawn(D, FT, SQT, seeds, Z, Dn):
    """:func:`pf_linear_step` with its normals drawn here: chunk ``c`` of the
    :data:`CHUNKS` fills its rows of ``Z`` (N, n) from the stream ``seeds[c]`` (as
    :func:`pf_jitter_drawn`), then propagates its particles. The same particles on any
    thread count."""
    N = D.shape[0]
    for c in prange(CHUNKS):
        j0, j1 = c * N // CHUNKS, (c + 1) * N // CHUNKS
        standard_normals_into(seeds[c], Z[j0:j1].reshape(-1), np.empty(1, dtype=np.uint64))
        for j in range(j0, j1):
            _linear_one(np.int64(j), D, FT, SQT, Z, Dn)


pf_linear_step_drawn_serial, pf_linear_step_drawn = serial_and_parallel(_pf_linear_step_drawn,
                                                                        "pf_linear_step_drawn")



class Kernels:
    """The kernels an estimator calls, serial or parallel (the same arithmetic); the strapdown
    ones (propagation, full states) are the motion model's
    (:meth:`~mixnav.ins.strapdown.StrapdownMotion.particle_kernels`), a fused update the
    measurement model's (``member_update``)."""

    def __init__(self, parallel: bool):
        self.parallel = bool(parallel)
        pick = 1 if self.parallel else 0
        self.moments = (pf_moments_serial, pf_moments)[pick]
        self.jitter_drawn = (pf_jitter_drawn_serial, pf_jitter_drawn)[pick]
        self.linear_step_drawn = (pf_linear_step_drawn_serial, pf_linear_step_drawn)[pick]


SERIAL = Kernels(False)
PARALLEL = Kernels(True)
