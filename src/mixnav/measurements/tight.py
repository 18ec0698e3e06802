"""Tightly coupled pseudorange and pseudorange-rate (Doppler) in the error-state EKF.

Innovations, true minus predicted, for each valid satellite ``j`` of the
epoch (antenna ``r_a = r + C_en^T C_nb l``, unit line of sight ``u`` from the
antenna to the satellite, receiver clock bias ``b`` [m] and drift ``d`` [m/s])::

    z_rho_j = rho_j - (|r_s - r_a| + b)
    z_rr_j  = rr_j  - (u . (v_s - v_a) + d)

Jacobians (``dx = x_true - x_est``, ``C_true = exp(phi x) C_est``, position
error in NED metres, ``u_n`` the line of sight in NED, ``l_n = C_nb l``,
``w`` the compensated body rate)::

    H_rho = [ u_n^T [l_n x],                0,       -u_n^T, 0,               0, 1, 0 ]
    H_rr  = [ u_n^T [(C_nb (w x l)) x],    -u_n^T,   0,     -u_n^T C_nb [l x], 0, 0, 1 ]

The dependence of the range rate on position through ``u`` (relative size
|v_s - v_a| / range, about 1e-4 per metre) is left out of H, as is
customary, and so is the factor ``1 - d(tau)/dt`` on the satellite velocity
(a few mm/s against Doppler noise of centimetres per second).
Needs a layout with the clock block (17 states or more).

Several systems (``obs.system`` given): one receiver clock, that of the first of
``systems`` (the reference), and one inter-system offset ``o_g`` [m] per further
system, the layout's auxiliary block ``system_offset`` (:func:`tight_layout`)::

    z_rho_j = rho_j - (|r_s - r_a| + b + o_g),      H_rho gets 1 in o_g's column

``o_g`` holds the difference of the receiver's hardware delays between the
signals and what is left of the systems' time offsets after the broadcast
corrections (GPST-GST, GPST-BDT, GPST-GLONASST are removed by the broadcast
clocks to a few ns): a random walk (:data:`OFFSET_WALK`). Its rate is left out
of the range rates (one drift for all systems: the time scales' relative
drift is below 1e-13 s/s, 0.03 mm/s). Satellites of a system not in
``systems`` are left out (counted: ``skipped_slots``).
"""

from __future__ import annotations

import numpy as np

from ..attitude import quat_to_dcm, skew
from ..errors import ArgumentError
from ..geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from ..gnss.observables import GnssObservations
from ..ins.error_model import StateBlock, StateLayout
from .base import MeasurementModel, Rows
from .kinds import PSEUDORANGE, RANGE_RATE, channel_id
from ._tight_kernel import tight_predict_batch, tight_zhr

#: System codes (:data:`mixnav.gnss.pseudoranges.SYSTEM_LETTERS`) in the order the reference
#: clock is chosen: GPS, GLONASS, Galileo, BeiDou, QZSS (the SPP's ``G R E C J``).
SYSTEM_CODE_ORDER = (1, 4, 8, 32, 16)
#: Initial 1-sigma of an inter-system offset [m]: the SPP's median offsets on
#: urbannav-tst-static are -4.6..+9.4 m (benchmarks/results/urbannav_spp.md), so 100 m (the
#: constant-velocity and dead-reckoning models' default too) leaves them to the data; a start
#: from an SPP fix gives the starting value.
OFFSET_SIGMA0 = 100.0
#: Random-walk density of an inter-system offset [m/sqrt(s)]: 0.01 m/sqrt(s) lets it move
#: 0.6 m (1 sigma) in an hour, a nearly constant bias; the value the constant-velocity and
#: dead-reckoning models use (mixnav.motion), not fitted to a recording (none with an IMU
#: and several systems is in the data).
OFFSET_WALK = 0.01


def observation_systems(obs: GnssObservations) -> tuple[int, ...]:
    """The system codes with a valid slot in ``obs``, in :data:`SYSTEM_CODE_ORDER` (the
    first is the reference clock's); ``(1,)`` (GPS) when ``obs.system`` is None."""
    if obs.system is None:
        return (1,)
    present = set(np.unique(obs.system[obs.valid]).tolist())
    return tuple(c for c in SYSTEM_CODE_ORDER if c in present) + tuple(sorted(present - set(SYSTEM_CODE_ORDER)))


def system_offset_block(n: int, sigma0: float = OFFSET_SIGMA0, walk: float = OFFSET_WALK) -> StateBlock:
    """The auxiliary block of ``n`` inter-system offsets [m] (random walks, ``walk``
    [m/sqrt(s)], initial sigma ``sigma0`` [m])."""
    return StateBlock("system_offset", int(n), "random_walk", "aux", float(sigma0), float(walk),
                      tuple(f"isb_{i}" for i in range(int(n))))


def tight_layout(layout: StateLayout, systems, sigma0: float = OFFSET_SIGMA0, walk: float = OFFSET_WALK):
    """``layout`` with a ``system_offset`` block for ``len(systems) - 1`` offsets (``layout``
    itself for one system, or when it has the block already)."""
    n_off = len(tuple(systems)) - 1
    if n_off < 1 or layout.has("system_offset"):
        return layout
    return StateLayout(f"{layout.name}+system_offset", list(layout.blocks[5:]) + [system_offset_block(n_off, sigma0,
                                                                                                       walk)])



class TightGnss(MeasurementModel):
    """Pseudoranges (and range rates) of every valid satellite of an epoch.

    Parameters
    ----------
    obs : GnssObservations
        Its ``sigma_pr`` / ``sigma_rr`` are the rows' sigmas, or per satellite its
        ``pr_variance`` when given.
    lever_arm : ndarray (3,)
        Antenna in the body frame relative to the IMU [m].
    layout : StateLayout
        Must have the clock block.
    use_range_rate : bool
        Also use the Doppler range rates.
    min_satellites : int
        Epochs with fewer valid satellites give no update (the filter keeps
        predicting); 1 uses whatever there is, which is the point of tight
        coupling.
    systems : sequence of int or None
        System codes used, the reference clock's first (module docstring); None:
        those of ``obs`` (:func:`observation_systems`). More than one needs the
        layout's ``system_offset`` block of ``len(systems) - 1`` states.
    """

    #: predict_batch takes each member's auxiliary states (the inter-system offsets)
    batch_aux = True

    def __init__(self, obs: GnssObservations, lever_arm, layout: StateLayout,
                 use_range_rate: bool = True, min_satellites: int = 1, systems=None):
        if layout.clk < 0:
            raise ArgumentError(f"tight coupling needs the receiver clock states: use states = 17, "
                              f"not {layout.n}", argument="layout")
        systems = observation_systems(obs) if systems is None else tuple(int(s) for s in systems)
        if not systems or len(set(systems)) != len(systems):
            raise ArgumentError(f"give distinct system codes, got {systems}", argument="systems")
        n_off = len(systems) - 1
        if n_off and (not layout.has("system_offset") or layout.block("system_offset").size != n_off):
            raise ArgumentError(f"{len(systems)} systems need an auxiliary block 'system_offset' of {n_off} states "
                                "in the layout (mixnav.measurements.tight.tight_layout)", argument="layout")
        self.obs = obs
        self.lever = np.asarray(lever_arm, dtype=float).reshape(3)
        self.layout = layout
        self.use_range_rate = bool(use_range_rate)
        self.min_satellites = int(min_satellites)
        self.systems = systems
        if obs.system is None:
            # every slot GPS: the slots of a model of GPS, else none
            self._sys = np.zeros(obs.valid.shape, dtype=np.int64) if 1 in systems else \
                np.full(obs.valid.shape, -1, dtype=np.int64)
            if 1 in systems:
                self._sys[:] = systems.index(1)
        else:
            self._sys = np.full(obs.valid.shape, -1, dtype=np.int64)
            for g, code in enumerate(systems):
                self._sys[obs.system == code] = g
        # the slots the model uses: obs.valid itself when every valid slot is of a used system
        unused = obs.valid & (self._sys < 0)
        self.skipped_slots = int(unused.sum())
        self._valid = obs.valid & ~unused if self.skipped_slots else obs.valid
        self._sys = np.ascontiguousarray(np.maximum(self._sys, 0))
        self._i_off = layout.slice("system_offset").start if n_off else -1
        self._zero_offsets = np.zeros(len(systems))
        # the system part of the channel ids: 0 for one system (the ids as before systems
        # existed), else the slot's system code
        self._channel_system = np.zeros(obs.valid.shape, dtype=np.int64) if (obs.system is None or not n_off) \
            else np.asarray(obs.system, dtype=np.int64)
        self._n_valid = self._valid.sum(axis=1)
        self._kind_rows = {}  # rows per satellite count -> kind codes (built once per count)
        self._channels = {}   # (epoch, rows) -> channel ids (a pure function of the epoch: built once)

    kinds = ("pseudorange", "range_rate")

    def _offsets(self, aux) -> np.ndarray:
        """``[0, o_1, ...]`` [m] from the auxiliary estimates ``aux`` (zero without them)."""
        if self._i_off < 0 or not aux or "system_offset" not in aux:
            return self._zero_offsets
        return np.concatenate([[0.0], np.asarray(aux["system_offset"], dtype=float)])

    def _kinds_of(self, m: int) -> np.ndarray:
        k = self._kind_rows.get(m)
        if k is None:
            n_pr = m // 2 if self.use_range_rate else m
            k = self._kind_rows[m] = np.array([PSEUDORANGE] * n_pr + [RANGE_RATE] * (m - n_pr), dtype=np.int64)
        return k

    @property
    def times(self) -> np.ndarray:
        return self.obs.time

    def predict(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, aux=None) -> tuple:
        """Predicted (pseudorange (n,), range rate (n,), u_n (n, 3), l_n, C_nb) of epoch ``i``."""
        o = self.obs
        sel = self._valid[i]
        C_nb = quat_to_dcm(nav[0:4])
        C_ne = dcm_ecef_to_ned(nav[7], nav[8])
        l_n = C_nb @ self.lever
        r_a = lla_to_ecef(nav[7:10]) + C_ne.T @ l_n
        v_a_n = nav[4:7] + C_nb @ np.cross(w_b, self.lever)
        d = o.sat_pos[i, sel] - r_a
        rng = np.linalg.norm(d, axis=1)
        u_e = d / rng[:, None]
        u_n = u_e @ C_ne.T
        rr = np.einsum("ij,ij->i", u_e, o.sat_vel[i, sel]) - u_n @ v_a_n
        return rng + clock[0] + self._offsets(aux)[self._sys[i, sel]], rr + clock[1], u_n, l_n, C_nb

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, memory=None, aux=None) -> Rows | None:
        """The rows of epoch ``i`` (pseudoranges [m], then range rates [m/s] of the
        same satellites), or None with too few satellites.

        One compiled call (:func:`mixnav.measurements._tight_kernel.tight_zhr`);
        :meth:`measure_numpy` is the same model in numpy (the tests' oracle).
        """
        o, lay = self.obs, self.layout
        if self._n_valid[i] < self.min_satellites or self._n_valid[i] == 0:
            return None
        z, H, r = tight_zhr(nav, self.lever, w_b, np.asarray(clock, dtype=float), o.sat_pos[i],
                            o.sat_vel[i], o.pseudorange[i], o.range_rate[i], self._valid[i],
                            o.sigma_pr, o.sigma_rr, self.use_range_rate, lay.n, lay.bg.start, lay.clk,
                            self._sys[i], self._offsets(aux), self._i_off)
        m = len(z)
        if o.pr_variance is not None:     # per-satellite variances (recorded data), in slot order
            r[:self._n_valid[i]] = o.pr_variance[i, self._valid[i]]
        return Rows(z, H, r, self._kinds_of(m), self.row_channels(i, m))

    def predict_batch(self, i: int, navs: np.ndarray, w_b: np.ndarray, clocks=None, aux=None):
        """``h`` at a batch of full states, for the ensemble estimators (UKF): ``(y, Y, R)``
        with ``y`` (m,) the measured pseudoranges then range rates of the valid
        satellites (the order of :meth:`rows`), ``Y`` (N, m) their predictions at the
        states ``navs`` (N, 10) with body rates ``w_b`` (3,) or (N, 3) and receiver
        clocks ``clocks`` (2,) or (N, 2) (bias [m], drift [m/s]; default zero), ``R`` (m,)
        the variances; None with too few satellites. Several systems: each state's
        inter-system offsets ``aux["system_offset"]`` (S-1,) or (N, S-1) [m] (default zero).
        One compiled call. At the nominal, ``y - Y[0]`` is :meth:`rows`' ``z``."""
        o = self.obs
        if self._n_valid[i] < self.min_satellites or self._n_valid[i] == 0:
            return None
        navs = np.ascontiguousarray(np.atleast_2d(np.asarray(navs, dtype=float)))
        N = len(navs)
        # copies, writable: a broadcast view is read-only (and for N = 1 already contiguous), and
        # a read-only array is another type to numba, so the kernel would compile twice
        w = np.array(np.broadcast_to(np.asarray(w_b, dtype=float), (N, 3)), order="C")
        c = np.zeros(2) if clocks is None else np.asarray(clocks, dtype=float)
        c = np.array(np.broadcast_to(c, (N, 2)), order="C")
        off = np.zeros((N, len(self.systems)))                           # column 0: the reference system
        if self._i_off >= 0 and aux is not None and "system_offset" in aux:
            off[:, 1:] = np.broadcast_to(np.asarray(aux["system_offset"], dtype=float), (N, len(self.systems) - 1))
        sel = self._valid[i]
        ns = int(self._n_valid[i])
        m = 2 * ns if self.use_range_rate else ns
        Y = np.empty((N, m))
        tight_predict_batch(navs, self.lever, w, c, o.sat_pos[i], o.sat_vel[i], sel, self.use_range_rate,
                            self._sys[i], off, Y)
        y = np.empty(m)
        r = np.empty(m)
        y[:ns] = o.pseudorange[i, sel]
        r[:ns] = o.sigma_pr ** 2 if o.pr_variance is None else o.pr_variance[i, sel]
        if self.use_range_rate:
            y[ns:] = o.range_rate[i, sel]
            r[ns:] = o.sigma_rr ** 2
        return y, Y, r

    def warm_up(self, nav: np.ndarray, aux: dict | None = None) -> None:
        """Compile (or load) the rows kernel and the batch prediction."""
        super().warm_up(nav, aux)
        for i in range(len(self.times)):
            if self.predict_batch(i, np.array(nav, dtype=float)[None], np.zeros(3), aux=aux) is not None:
                break

    def row_kinds(self, i: int, m: int) -> np.ndarray:
        """Pseudorange rows, then (with ``use_range_rate``) as many range-rate rows."""
        return self._kinds_of(m)

    def row_channels(self, i: int, m: int) -> np.ndarray:
        """A channel id per row, the same for the same satellite and observable at
        every epoch: :func:`~mixnav.measurements.kinds.channel_id` of kind, PRN and (several
        systems) system code (rows in the order of :meth:`row_kinds`)."""
        ch = self._channels.get((i, m))
        if ch is None:
            sel = self._valid[i]
            prn, sys = self.obs.prn[i, sel], self._channel_system[i, sel]
            rep = m // len(prn)
            ch = self._channels[(i, m)] = channel_id(self._kinds_of(m), np.concatenate([prn] * rep),
                                                     np.concatenate([sys] * rep))
        return ch

    def measure_numpy(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, aux=None):
        """:meth:`measure` in plain numpy."""
        o, lay = self.obs, self.layout
        sel = self._valid[i]
        n = int(sel.sum())
        if n < self.min_satellites:
            return None
        pr, rr, u_n, l_n, C_nb = self.predict(i, nav, w_b, clock, aux)
        use_rr = self.use_range_rate
        m = 2 * n if use_rr else n
        H = np.zeros((m, lay.n))
        z = np.empty(m)
        r = np.empty(m)
        z[:n] = o.pseudorange[i, sel] - pr
        H[:n, lay.att] = u_n @ skew(l_n)
        H[:n, lay.pos] = -u_n
        H[:n, lay.clk] = 1.0
        if self._i_off >= 0:
            g = self._sys[i, sel]
            H[np.nonzero(g > 0)[0], self._i_off + g[g > 0] - 1] = 1.0
        r[:n] = o.sigma_pr ** 2 if o.pr_variance is None else o.pr_variance[i, sel]
        if use_rr:
            z[n:] = o.range_rate[i, sel] - rr
            H[n:, lay.att] = u_n @ skew(C_nb @ np.cross(w_b, self.lever))
            H[n:, lay.vel] = -u_n
            H[n:, lay.bg] = -u_n @ (C_nb @ skew(self.lever))
            H[n:, lay.clk + 1] = 1.0
            r[n:] = o.sigma_rr ** 2
        return z, H, r
