"""Compiled kernels of the particle filters (numba, ``cache=True``).

- :func:`pf_propagate`: one propagation step of the whole particle array in one
  call: each particle (an error-state deviation ``D[j]`` about the nominal)
  becomes a full state ``nav0 (+) D[j]``, is mechanized with its own sensor
  errors over the step's IMU block, and is differenced from the mechanized
  nominal; process noise ``SQ z_j`` is added per particle. The merging of the
  block, the mechanization of the members and the difference map are the
  UKF's (:mod:`._ukf_kernels`), not copies.
- :func:`particle_navs`: the particles of a measurement epoch as full states.
- :func:`add_log_likelihood`: the Gaussian log-likelihood of each particle's
  prediction, added to its log-weight.

Serial on purpose: particles are independent, but at 1000-5000 particles and
15 states one step is dominated by the mechanization (measured in
benchmarks/results/pf.md); numba ``parallel`` is not used, so results do not
depend on the thread count.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..ins._error_kernels import apply_feedback
from ._ukf_kernels import difference_members, mechanize_members, merge_block


@njit(cache=True)
def pf_propagate(nav0, prev0, sensor0, D, SQ, Z, dtheta, dvel, dt, substeps, layout, tau, T,
                 navs, prevs, sensors, Dn):
    """Propagate the particles ``D`` (N, n) about ``nav0`` over one IMU block.

    ``navs`` (N+1, 10), ``prevs`` (N+1, 6), ``sensors`` (N+1, 12) are scratch (row
    N the reference, the nominal itself); ``Dn`` (N, n) receives the propagated
    deviations plus the process noise ``SQ @ Z[j]`` (``SQ SQ^T = Qd``; ``Z`` (N, n)
    standard normals drawn by the caller from the estimator's stream).
    """
    N, n = D.shape
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
    for j in range(N):
        for a in range(n):
            s = 0.0
            for b in range(n):
                s += SQ[a, b] * Z[j, b]
            Dn[j, a] += s


@njit(cache=True)
def particle_navs(nav, D, layout, navs):
    """The particles ``D`` (N, n) about ``nav`` as full navigation states ``navs`` (N, 10)."""
    sensor = np.zeros(12)
    clock = np.zeros(2)
    for j in range(D.shape[0]):
        for i in range(10):
            navs[j, i] = nav[i]
        apply_feedback(navs[j], sensor, clock, D[j], layout)


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
