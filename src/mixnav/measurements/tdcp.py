"""Pseudorange + time-differenced carrier phase (TDCP) by stochastic cloning (P1 eqs. 2-4).

TDCP of satellite ``j`` between the previous GNSS epoch ``k-1`` and epoch ``k``
(carrier in metres, the constant ambiguity cancels)::

    dphi_j = phi_j(k) - phi_j(k-1) = |r_s(k) - r_a(k)| - |r_s(k-1) - r_a(k-1)| + b(k) - b(k-1) + e
                                                                    # P1 eq. (3)

It depends on the antenna position and clock bias at *two* epochs. This model
carries the earlier ones as a stochastic clone (see :mod:`mixnav.filters.ekf`):
after the update of each epoch the engine appends to the error state a copy

    x_c = [dr_a (3, NED at the clone's place), db]  = J x,
    J = [[-[l_n x], 0, I, 0, 0, 0, 0], [0, ..., 0, 1, 0]]

with its covariance and cross-covariances, which propagate with the INS
(the clone itself is constant). At the next epoch the innovation and Jacobian
of a TDCP row are::

    z = dphi_j - (|r_s(k) - r_a| + b - |r_s(k-1) - r_a^c| - b^c)
    H = [u_n^T [l_n x], 0, -u_n^T, 0, 0, 1, 0 | u_c^T, -1]

(``u`` the unit line of sight from the antenna to the satellite, in NED at
each epoch; ``r_a^c``, ``b^c`` the cloned estimates, corrected by the clone
part of every update). Pseudorange rows are those of
:class:`mixnav.measurements.tight.TightGnss` (P1 eq. (2)), with zeros on the
clone. The TDCP noise is taken as white with variance ``2 sigma_cp^2``:
successive TDCPs share a carrier epoch and are in truth correlated (-1/2), an
approximation that makes the filter slightly conservative about velocity.

``clone=False`` gives the common shortcut instead: the previous antenna
position and clock are taken as known (the estimates remembered at the
previous epoch, no clone, ``H`` on the current states only). It ignores the
previous epoch's uncertainty, so the filter becomes overconfident: tests and
benchmarks/results/tight.md show what this costs in NEES.

TDCP rows are formed only for satellites tracked, with a carrier, at both epochs
when the epochs are at most ``1.5 / rate`` apart (a longer gap means loss of lock),
and, for recorded carriers, only where the carrier is one arc between the two epochs
(``GnssObservations.carrier_continuous``, from :mod:`mixnav.gnss.cycle_slips`: loss-of-lock
flags, gaps, Doppler and geometry-free checks).

Several systems (``obs.system`` given; the layout's ``system_offset`` block, as
:class:`~mixnav.measurements.tight.TightGnss`): the carrier of a satellite of system ``g``
carries the receiver's inter-system offset ``o_g`` as its pseudorange does, so its time
difference sees the offset's change over the epoch::

    dphi_j = ... + b(k) - b(k-1) + o_g(k) - o_g(k-1) + e

and the clone holds the offsets too, ``x_c = [dr_a, db, do_1 .. do_{S-1}]`` (``4 + S - 1``
states): ``H`` gets ``+1`` in ``o_g``'s column and ``-1`` in its clone column (the shortcut
``clone=False`` takes the remembered offsets as known, as it does the clock). Satellites are
paired across the two epochs by system and number (GPS 5 and Galileo 5 are two satellites).
With GPS alone nothing of this enters (the rows bit for bit those of one system).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..attitude import skew
from ..gnss.observables import GnssObservations
from ..ins.error_model import StateLayout
from ._tight_kernel import antenna_frame, tdcp_rows
from .kinds import PSEUDORANGE, TDCP
from .base import Rows
from .tight import TightGnss


class TdcpMemory(NamedTuple):
    """What a TDCP epoch remembers of the previous one (held by the engine).

    ``i`` its epoch index, ``r_a`` the antenna ECEF estimate [m], ``C_ne`` ECEF -> NED
    there, ``b`` the clock-bias estimate [m], ``offsets`` the inter-system offset estimates
    [m] (S-1,) (empty for one system)."""

    i: int
    r_a: np.ndarray
    C_ne: np.ndarray
    b: float
    offsets: np.ndarray = np.zeros(0)


class TdcpGnss(TightGnss):
    """Pseudoranges and TDCP of every satellite tracked at an epoch.

    Parameters
    ----------
    obs : GnssObservations
    lever_arm : ndarray (3,)
        Antenna in the body frame [m].
    layout : StateLayout
        With the clock block.
    clone : bool
        Stochastic cloning (default) or the known-previous-position shortcut.
    use_pseudorange : bool
        Also use the pseudoranges (TDCP alone does not observe absolute position).
    min_satellites : int
        Fewer valid satellites than this at an epoch: no update.
    systems : sequence of int or None
        As :class:`~mixnav.measurements.tight.TightGnss` (several: the layout's
        ``system_offset`` block, module docstring).
    """

    def __init__(self, obs: GnssObservations, lever_arm, layout: StateLayout, clone: bool = True,
                 use_pseudorange: bool = True, min_satellites: int = 1, systems=None):
        super().__init__(obs, lever_arm, layout, use_range_rate=False, min_satellites=min_satellites,
                         systems=systems)
        self.clone = bool(clone)
        self.n_off = len(self.systems) - 1
        self.clone_size = 4 + self.n_off if self.clone else 0
        # several systems: the engine hands remember() the offsets' estimates
        self.remembers_aux = self.n_off > 0
        # a satellite's key across epochs: its number, and with several systems its system too
        self._sat_key = obs.prn if obs.system is None else \
            np.asarray(obs.system, dtype=np.int64) * 1000 + np.asarray(obs.prn, dtype=np.int64)
        self.use_pseudorange = bool(use_pseudorange)
        dt = np.diff(obs.time)
        self.max_gap = 1.5 * (float(np.median(dt)) if len(dt) else np.inf)
        # slots of the satellites tracked at both epoch i-1 and epoch i, once, up front
        self._pairs = [None] + [self._common_slots(i - 1, i) for i in range(1, len(obs.time))]

    kinds = ("pseudorange", "tdcp")
    remembers = True
    #: inter-system offsets beside the reference clock (0: one system, the clone of 4 states)
    n_off = 0
    remembers_aux = False

    # --- the clone -----------------------------------------------------------------------
    def _antenna(self, nav):
        """Antenna ECEF [m], C_ne and ``C_nb l`` (compiled)."""
        return antenna_frame(nav, self.lever)

    def clone_rows(self, nav: np.ndarray) -> np.ndarray:
        """``J`` (4 + S - 1, n): antenna position error (NED), clock-bias error and (several
        systems) the inter-system offset errors from the error state."""
        lay = self.layout
        _, _, l_n = self._antenna(nav)
        J = np.zeros((4 + self.n_off, lay.n))
        J[0:3, lay.att] = -skew(l_n)
        J[0:3, lay.pos] = np.eye(3)
        J[3, lay.clk] = 1.0
        if self.n_off:
            J[4:, self._i_off:self._i_off + self.n_off] = np.eye(self.n_off)
        return J

    def remember(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, aux=None) -> TdcpMemory:
        """The estimates of epoch ``i`` (after its update) the next TDCP needs (several
        systems: the offsets of ``aux``)."""
        r_a, C_ne, _ = self._antenna(nav)
        if not self.n_off:
            return TdcpMemory(int(i), r_a, C_ne, float(clock[0]))
        return TdcpMemory(int(i), r_a, C_ne, float(clock[0]), self._offsets(aux)[1:].copy())

    def correct_memory(self, memory: TdcpMemory, dx_c: np.ndarray) -> TdcpMemory:
        """The remembered estimates moved by the clone part of a correction."""
        if not self.n_off:
            return memory._replace(r_a=memory.r_a + memory.C_ne.T @ dx_c[0:3], b=memory.b + float(dx_c[3]))
        return memory._replace(r_a=memory.r_a + memory.C_ne.T @ dx_c[0:3], b=memory.b + float(dx_c[3]),
                               offsets=memory.offsets + dx_c[4:4 + self.n_off])

    # --- the measurement -------------------------------------------------------------------
    def _tdcp_pairs(self, i: int, memory):
        """Slots (current, previous) of the satellites tracked at the remembered epoch and ``i``."""
        o = self.obs
        p = None if memory is None else memory.i
        if p is None or p >= i or o.time[i] - o.time[p] > self.max_gap:
            return None
        if p == i - 1:
            return self._pairs[i]
        return self._common_slots(p, i)

    def _common_slots(self, p: int, i: int):
        """Slots of the satellites with a carrier at epochs ``p`` and ``i``; with recorded
        carriers (``obs.carrier_continuous``) only those whose carrier is one arc from ``p``
        to ``i`` (no cycle slip at any epoch after ``p`` up to ``i``). Slots of a system the
        model does not use are left out (``TightGnss.skipped_slots``)."""
        o, valid, key = self.obs, self._valid, self._sat_key
        a = np.nonzero(valid[i] & np.isfinite(o.carrier[i]))[0]
        b = np.nonzero(valid[p] & np.isfinite(o.carrier[p]))[0]
        cont = o.carrier_continuous
        if cont is not None:
            a = a[cont[i, a]]
            for q in range(p + 1, i):     # an epoch in between: the arc must run through it too
                a = a[np.isin(key[i, a], key[q][valid[q] & cont[q]])]
        _, ia, ib = np.intersect1d(key[i, a], key[p, b], assume_unique=True, return_indices=True)
        if not len(ia):
            return None
        return a[ia], b[ib]

    def _kinds_tdcp(self, n_pr: int, m: int) -> np.ndarray:
        k = self._kind_rows.get((n_pr, m))
        if k is None:
            k = self._kind_rows[(n_pr, m)] = np.array([PSEUDORANGE] * n_pr + [TDCP] * (m - n_pr), dtype=np.int64)
        return k

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, memory: TdcpMemory | None = None, aux=None):
        """The rows of epoch ``i``: pseudoranges [m], then TDCP [m]; ``H`` has ``n + 4``
        columns when TDCP rows are present and the model clones, else ``n``.
        ``memory`` is what :meth:`remember` returned at the previous epoch."""
        o, lay = self.obs, self.layout
        n_sat = int(self._n_valid[i])     # the slots of the systems used
        if n_sat < self.min_satellites:
            return None
        pairs = self._tdcp_pairs(i, memory)
        n_pr = n_sat if self.use_pseudorange else 0
        n_td = 0 if pairs is None else len(pairs[0])
        if n_pr + n_td == 0:
            return None
        ncol = lay.n + (self.clone_size if n_td else 0)
        z = np.empty(n_pr + n_td)
        H = np.zeros((n_pr + n_td, ncol))
        r = np.empty(n_pr + n_td)
        r_a, C_ne, l_n = self._antenna(nav)
        if n_pr:  # the pseudorange rows of TightGnss (compiled)
            pr = super().rows(i, nav, w_b, clock, aux=aux)
            z[:n_pr], H[:n_pr, :lay.n], r[:n_pr] = pr.z, pr.H, pr.R
        if n_td:
            cur, prev = pairs
            p = memory.i
            tdcp_rows(z, H, r, n_pr, r_a, C_ne, l_n, float(clock[0]), o.sat_pos[i, cur],
                      o.sat_pos[p, prev], o.carrier[i, cur], o.carrier[p, prev],
                      memory.r_a, memory.C_ne, memory.b, o.sigma_cp, self.clone, lay.n, lay.clk)
            if self.n_off:
                self._offset_terms(z, H, n_pr, cur, i, memory, aux)
        return Rows(z, H, r, self._kinds_tdcp(n_pr, n_pr + n_td))

    def _offset_terms(self, z, H, row0: int, cur, i: int, memory: TdcpMemory, aux) -> None:
        """Several systems: each TDCP row ``row0:`` of a satellite of system ``g > 0`` gets
        ``o_g - o_g^c`` off its innovation, ``+1`` in ``o_g``'s column and, cloning, ``-1`` in
        its clone column ``n + 4 + g - 1`` (module docstring)."""
        g = self._sys[i, cur]
        off = self._offsets(aux)
        off_c = np.concatenate([[0.0], memory.offsets])
        rows = row0 + np.arange(len(cur))
        z[rows] -= off[g] - off_c[g]
        on = g > 0
        H[rows[on], self._i_off + g[on] - 1] = 1.0
        if self.clone:
            H[rows[on], self.layout.n + 4 + g[on] - 1] = -1.0

    def tdcp_rows_numpy(self, i: int, nav: np.ndarray, clock, memory: TdcpMemory, aux=None):
        """The TDCP rows of :meth:`measure` (``z``, ``H``, ``r``) in plain numpy (the tests'
        oracle for the compiled :func:`mixnav.measurements._tight_kernel.tdcp_rows`)."""
        o, lay = self.obs, self.layout
        pairs = self._tdcp_pairs(i, memory)
        r_a, C_ne, l_n = self._antenna(nav)
        n_td = len(pairs[0])
        z = np.empty(n_td)
        H = np.zeros((n_td, lay.n + self.clone_size))
        r = np.empty(n_td)
        if n_td:
            cur, prev = pairs
            d = o.sat_pos[i, cur] - r_a
            rho = np.linalg.norm(d, axis=1)
            u_n = (d / rho[:, None]) @ C_ne.T
            d_c = o.sat_pos[memory.i, prev] - memory.r_a
            rho_c = np.linalg.norm(d_c, axis=1)
            u_c = (d_c / rho_c[:, None]) @ memory.C_ne.T
            rows = slice(0, n_td)
            z[rows] = (o.carrier[i, cur] - o.carrier[memory.i, prev]) - \
                (rho + clock[0] - rho_c - memory.b)
            H[rows, lay.att] = u_n @ skew(l_n)
            H[rows, lay.pos] = -u_n
            H[rows, lay.clk] = 1.0
            if self.clone:
                H[rows, lay.n:lay.n + 3] = u_c
                H[rows, lay.n + 3] = -1.0
            r[rows] = 2.0 * o.sigma_cp ** 2
            if self.n_off:   # written out here again, not through _offset_terms: the oracle
                g = self._sys[i, cur]
                off = self._offsets(aux)
                off_c = np.concatenate([[0.0], memory.offsets])
                z[rows] = z[rows] - (off[g] - off_c[g])
                for q in np.nonzero(g > 0)[0]:
                    H[q, self._i_off + g[q] - 1] = 1.0
                    if self.clone:
                        H[q, lay.n + 4 + g[q] - 1] = -1.0
        return z, H, r
