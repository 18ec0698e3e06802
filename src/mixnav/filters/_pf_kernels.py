"""Compiled kernels of the particle filters (numba, ``cache=True``).

- :func:`pf_propagate`: one propagation step of the whole particle array in one
  call: each particle (an error-state deviation ``D[j]`` about the nominal)
  becomes a full state ``nav0 (+) D[j]``, is mechanized with its own sensor
  errors over the step's IMU block, and is differenced from the mechanized
  nominal (the UKF's :func:`~._ukf_kernels.propagate_members`, not a copy);
  process noise ``SQ z_j`` is added per particle.
- the particles of a measurement epoch as full states: the UKF's
  :func:`~._ukf_kernels.member_navs`.
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

from ._ukf_kernels import propagate_members


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
    propagate_members(nav0, prev0, sensor0, D, dtheta, dvel, dt, substeps, layout, tau, T, navs, prevs, sensors,
                      Dn)
    for j in range(N):
        for a in range(n):
            s = 0.0
            for b in range(n):
                s += SQ[a, b] * Z[j, b]
            Dn[j, a] += s


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
