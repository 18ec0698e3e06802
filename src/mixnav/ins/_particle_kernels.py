"""Compiled strapdown kernels of the particle filter (numba, ``cache=True``): the parts of
its step that are strapdown maths (its fused loose GNSS update is the loose model's:
:mod:`mixnav.measurements._loose_members`). The estimator
(filters/particle.py) reaches them only through
:meth:`~mixnav.ins.strapdown.StrapdownMotion.particle_kernels`.

- :func:`pf_step`: one propagation step of the whole particle array in one call,
  fused per particle: the particle (an error-state deviation ``D[j]`` about the
  nominal) becomes a full state ``nav0 (+) D[j]``, is mechanized with its own
  sensor errors over the step's merged IMU block, is differenced from the
  mechanized nominal, and gains its process noise ``SQ z_j``. The maps are the
  strapdown member maps' (:func:`~mixnav.ins._batch_kernels.nav_difference`, the engine's ``apply_feedback``,
  the strapdown ``mechanize_core``: the nominal in RECORD mode, the particles in
  NEAR mode, ins/_kernels.py), not copies.
- :func:`pf_mechanize`: the mechanization alone (timed in benchmarks/bench_pf.py);
  :func:`pf_propagate`: the unfused reference :func:`pf_step` is tested against.
- :func:`pf_member_navs`: the particles of a measurement epoch as full states.

Each kernel with a parallel loop is one body (``prange``) compiled twice by
:func:`mixnav._jit.serial_and_parallel`: ``name`` (parallel) and ``name_serial``; the
threading contract is filters/_pf_kernels.py's (bitwise the same on any thread count).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._jit import serial_and_parallel
from ._batch_kernels import merge_block_into
from ._batch_kernels import nav_difference as _nav_difference
from ._batch_kernels import propagate_members
from ._error_kernels import L_BA, L_BG, L_CLK, L_SA, L_SG
from ._error_kernels import apply_feedback as _apply_feedback
from ._kernels import NEAR, RECORD, TRIG_POINTS, mechanize_core

# The shared maps, compiled again to be inlined into the per-particle loops (the same
# source, so bitwise the same arithmetic; ~10 % faster than a call per particle, which
# passes and reference-counts every array view). Not cached on their own: only the
# kernels that inline them are (after editing the originals, clear __pycache__). The
# mechanization is the strapdown's ``mechanize_core`` (inlined by its own flag): the
# nominal in RECORD mode, the particles in NEAR mode (ins/_kernels.py).
apply_feedback = njit(inline="always")(_apply_feedback.py_func)
nav_difference = njit(inline="always")(_nav_difference.py_func)

#: per-particle scratch row: dth (0:3), dv (3:6), dvn (6:9), clock (9:11)
SCRATCH = 11


@njit(cache=True, inline="always")
def _mechanize_one(nav, prev, sensor, scr, gth, gdv, gdt, S, trig, mode):
    """One state over the first ``S`` merged sub-intervals (as ``mechanize_members``);
    ``trig`` (>= S, TRIG_POINTS, 3) the reference's latitudes with their sin and cos per
    sub-interval, written (``mode`` RECORD: the nominal) or read (NEAR: the particles).

    Inlined on purpose: called instead, the mechanization of 5000 particles was 30-50 %
    slower (one sub-interval serial 2.7 -> 3.7 ms, two threads 0.84 -> 1.33 ms), though the
    two ``pf_step`` twins then compiled in 35 s instead of 75 s."""
    dth, dv, dvn = scr[0:3], scr[3:6], scr[6:9]
    for k in range(S):
        h = gdt[k]
        for i in range(3):
            dth[i] = (gth[k, i] - sensor[i] * h) / (1.0 + sensor[6 + i])
            dv[i] = (gdv[k, i] - sensor[3 + i] * h) / (1.0 + sensor[9 + i])
        mechanize_core(nav, dth, dv, prev[0:3], prev[3:6], h, dvn, trig[k], mode)
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


def _pf_step(nav0, prev0, sensor0, D, SQT, Z, dtheta, dvel, dt, substeps, layout, tau, T,
             navs, prevs, sensors, scr, gth, gdv, gdt, fdec, Dn):
    """Propagate the particles ``D`` (N, n) about ``nav0`` over one IMU block, fused
    per particle, parallel over particles (``prange``).

    ``nav0`` (10,), ``prev0`` (6,), ``sensor0`` (12,): the nominal before the step;
    ``dtheta``, ``dvel`` (K, 3), ``dt`` (K,) the raw increments, merged into at most
    ``substeps`` sub-intervals (0: every increment); ``layout`` the INS layout array;
    ``tau`` (4,) the sensor Gauss-Markov times [s]; ``T`` the step [s]. ``SQT`` (n, n)
    the transpose of a square root of ``Qd``; ``Z`` (N, n) standard normals drawn by the
    caller. Scratch (allocated here only the (S, 4, 3) record of the nominal's latitudes'
    sin and cos): ``navs`` (N+1, 10), ``prevs`` (N+1, 6),
    ``sensors`` (N+1, 12), ``scr`` (N+1, 11), ``gth``, ``gdv`` (>= S, 3), ``gdt``
    (>= S,), ``fdec`` (4,). Row N of the scratch is the reference (the nominal
    itself). ``Dn`` (N, n) receives the propagated deviations plus noise.
    """
    N = D.shape[0]
    S = merge_block_into(dtheta, dvel, dt, substeps, gth, gdv, gdt)
    _decay(tau, T, fdec)
    trig = np.empty((S, TRIG_POINTS, 3))
    _start_member(N, nav0, prev0, sensor0, D, layout, navs, prevs, sensors, scr)
    _mechanize_one(navs[N], prevs[N], sensors[N], scr[N], gth, gdv, gdt, S, trig, RECORD)
    for j in prange(N):
        _start_member(np.int64(j), nav0, prev0, sensor0, D, layout, navs, prevs, sensors, scr)
        _mechanize_one(navs[j], prevs[j], sensors[j], scr[j], gth, gdv, gdt, S, trig, NEAR)
        _finish_member(j, D, navs, layout, fdec, T, SQT, Z, Dn)


pf_step_serial, pf_step = serial_and_parallel(_pf_step, "pf_step")


def _pf_mechanize(navs, prevs, sensors, scr, gth, gdv, gdt, S):
    """Every row of ``navs`` mechanized over ``S`` merged sub-intervals (in place, parallel
    over rows), the last row as the reference (RECORD, first) and the others as particles
    about it (NEAR), as in :func:`pf_step`: one "IMU step" of the array, timed in
    benchmarks/bench_pf.py."""
    N = navs.shape[0] - 1
    trig = np.empty((S, TRIG_POINTS, 3))
    _mechanize_one(navs[N], prevs[N], sensors[N], scr[N], gth, gdv, gdt, S, trig, RECORD)
    for j in prange(N):
        _mechanize_one(navs[j], prevs[j], sensors[j], scr[j], gth, gdv, gdt, S, trig, NEAR)


pf_mechanize_serial, pf_mechanize = serial_and_parallel(_pf_mechanize, "pf_mechanize")


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


def _pf_member_navs(nav, D, layout, navs, sensors, scr):
    """The particles ``D`` (N, n) about ``nav`` as full navigation states ``navs``
    (>= N, 10) (the engine's feedback map on a copy of ``nav``); ``sensors`` (>= N, 12)
    and ``scr`` (>= N, 11) receive the sensor and clock parts (scratch, not used).
    Parallel over particles."""
    for j in prange(D.shape[0]):
        _member_nav(np.int64(j), nav, D, layout, navs, sensors, scr)


pf_member_navs_serial, pf_member_navs = serial_and_parallel(_pf_member_navs, "pf_member_navs")


class ParticleKernels:
    """The strapdown kernels the particle estimator calls, serial or parallel (the same
    arithmetic); ``scratch``: the width of the per-particle scratch rows (:data:`SCRATCH`)."""

    scratch = SCRATCH

    def __init__(self, parallel: bool):
        self.parallel = bool(parallel)
        pick = 1 if self.parallel else 0
        self.step = (pf_step_serial, pf_step)[pick]
        self.member_navs = (pf_member_navs_serial, pf_member_navs)[pick]


SERIAL = ParticleKernels(False)
PARALLEL = ParticleKernels(True)
