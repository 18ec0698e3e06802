"""Pseudoranges + time-differenced carrier phase (TDCP) for any motion model with a position,
clock and (several systems) inter-system offset blocks: the GNSS-only filters' TDCP.

What :mod:`mixnav.measurements.tdcp` does for the INS (P1 eqs. 2-4), without the lever
arm and attitude: the TDCP of satellite ``j`` (system ``g``) between the remembered epoch
``c`` and epoch ``k``, carriers in metres with the pseudorange's corrections
(:func:`mixnav.gnss.cycle_slips.carrier_of_rows`)::

    dphi_j = phi_j(k) - phi_j(c) = rho_j(k) + b(k) + o_g(k) - rho_j(c) - b(c) - o_g(c) + e

    z = dphi_j - (|s_j(k) - r_a| + b + o_g - |s_j(c) - r_a^c| - b^c - o_g^c)
    H = [-u_n^T on the position, 1 on the clock bias, 1 on o_g | u_c^T, -1, -1 on o_g^c]

(``u`` the unit line of sight antenna -> satellite in NED at each epoch, satellites turned
into each reception-time frame by the Earth's rotation as the pseudorange rows do). The
previous antenna position, clock bias and offsets are a stochastic clone held by the engine
(``x_c = J x``, ``J`` picks the position, the clock bias and the offsets), corrected by the
clone part of every update. TDCP noise ``2 sigma_cp^2``, white (successive TDCPs share a
carrier epoch: the filter is slightly conservative about velocity, as the INS model).

A TDCP row is formed for a satellite used at both epochs, with a carrier at both, whose
carrier at ``k`` continues its arc (``continuous``: no loss of lock, gap, Doppler or
geometry-free alarm, :mod:`mixnav.gnss.cycle_slips`), and only between consecutive epochs
of the model at most ``1.5`` median intervals apart.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..errors import ArgumentError
from ..geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from ..gnss.geometry import C_LIGHT, earth_rotation_correction
from ..gnss.pseudoranges import PseudorangeEpochs
from .base import Rows
from .kinds import TDCP, channel_id
from .pseudorange import PseudorangeGnss


class TdcpClone(NamedTuple):
    """What a TDCP epoch remembers of the previous one: ``i`` its epoch, ``r_a`` the antenna
    ECEF estimate [m], ``C_ne`` ECEF -> NED there, ``b`` the clock bias [m], ``offsets``
    the inter-system offsets [m] (n_off,)."""

    i: int
    r_a: np.ndarray
    C_ne: np.ndarray
    b: float
    offsets: np.ndarray


class PseudorangeTdcp(PseudorangeGnss):
    """Pseudorange rows of :class:`PseudorangeGnss`, then TDCP rows (module docstring).

    Parameters
    ----------
    epochs : PseudorangeEpochs
    carrier : ndarray (M,)
        Carrier of each of ``epochs``' rows [m] (NaN: none).
    continuous : ndarray of bool (M,)
        The row's carrier continues its satellite's arc from the previous epoch.
    layout, systems, variance, scale, sigma_a, sigma_b, elevation_mask, min_satellites
        As :class:`PseudorangeGnss`.
    sigma_cp : float
        Carrier 1-sigma [m].
    """

    kinds = ("pseudorange", "tdcp")
    remembers = True
    remembers_aux = True

    def __init__(self, epochs: PseudorangeEpochs, carrier, continuous, layout, systems=(1,), variance="given",
                 scale: float = 1.0, sigma_a: float = 3.0, sigma_b: float = 3.0, elevation_mask: float = 0.0,
                 min_satellites: int = 1, sigma_cp: float = 0.003):
        super().__init__(epochs, layout, systems, variance, scale, sigma_a, sigma_b, elevation_mask, min_satellites)
        M = len(epochs.pseudorange)
        carrier = np.asarray(carrier, float)
        continuous = np.asarray(continuous, bool)
        if carrier.shape != (M,) or continuous.shape != (M,):
            raise ArgumentError(f"carrier and continuous must have shape ({M},) like the epochs' rows",
                                argument="carrier")
        if not sigma_cp > 0:
            raise ArgumentError(f"must be positive, got {sigma_cp}", argument="sigma_cp")
        self.carrier = carrier
        self.sigma_cp = float(sigma_cp)
        self._has_cp = self._use & np.isfinite(carrier)
        self._cont = self._has_cp & continuous
        n_off = len(self.systems) - 1
        self.n_off = n_off
        self.clone_size = 4 + n_off
        dt = np.diff(epochs.time)
        self.max_gap = 1.5 * (float(np.median(dt)) if len(dt) else np.inf)
        self._tdcp_channels = channel_id(TDCP, epochs.sat_id, epochs.system)

    # --- the clone --------------------------------------------------------------------------
    def clone_rows(self, nav: np.ndarray) -> np.ndarray:
        lay = self.layout
        J = np.zeros((self.clone_size, lay.n))
        J[0:3, lay.pos] = np.eye(3)
        J[3, lay.clk] = 1.0
        if self.n_off:
            J[4:, self._i_off:self._i_off + self.n_off] = np.eye(self.n_off)
        return J

    def remember(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, aux=None) -> TdcpClone:
        off = np.zeros(self.n_off)
        if self.n_off and aux is not None:
            off = np.array(aux["system_offset"], dtype=float)
        return TdcpClone(int(i), lla_to_ecef(nav[7:10]), dcm_ecef_to_ned(nav[7], nav[8]), float(clock[0]), off)

    def correct_memory(self, memory: TdcpClone, dx_c: np.ndarray) -> TdcpClone:
        return memory._replace(r_a=memory.r_a + memory.C_ne.T @ dx_c[0:3], b=memory.b + float(dx_c[3]),
                               offsets=memory.offsets + dx_c[4:])

    # --- the rows ---------------------------------------------------------------------------
    def tdcp_pairs(self, i: int, memory: TdcpClone | None):
        """Rows (current, previous) of epoch ``i`` and the remembered epoch forming a TDCP."""
        e = self.epochs
        if memory is None or memory.i != i - 1 or e.time[i] - e.time[memory.i] > self.max_gap:
            return None
        sl, sp = e.rows_of(i), e.rows_of(memory.i)
        cur = np.arange(sl.start, sl.stop)[self._cont[sl]]
        prev = np.arange(sp.start, sp.stop)[self._has_cp[sp]]
        if not len(cur) or not len(prev):
            return None
        key = lambda r: e.system[r].astype(np.int64) * 1000 + e.sat_id[r]  # noqa: E731
        _, a, b = np.intersect1d(key(cur), key(prev), assume_unique=True, return_indices=True)
        return (cur[a], prev[b]) if len(a) else None

    def _ranges(self, rows, r_a, C_ne):
        s = self.epochs.sat_ecef[rows]
        tau = np.linalg.norm(s - r_a, axis=1) / C_LIGHT
        d = earth_rotation_correction(s, tau) - r_a
        rng = np.linalg.norm(d, axis=1)
        return rng, (d / rng[:, None]) @ C_ne.T

    def tdcp_rows(self, i: int, nav: np.ndarray, clock, memory: TdcpClone, aux=None):
        """``(z, H, r, rows)`` of epoch ``i``'s TDCP rows (``H`` with the clone columns), or None."""
        pairs = self.tdcp_pairs(i, memory)
        if pairs is None:
            return None
        cur, prev = pairs
        lay = self.layout
        r_a = lla_to_ecef(nav[7:10])
        rng, u_n = self._ranges(cur, r_a, dcm_ecef_to_ned(nav[7], nav[8]))
        rng_c, u_c = self._ranges(prev, memory.r_a, memory.C_ne)
        pred = rng + float(clock[0]) - rng_c - memory.b
        H = np.zeros((len(cur), lay.n + self.clone_size))
        H[:, lay.pos] = -u_n
        H[:, lay.clk] = 1.0
        H[:, lay.n:lay.n + 3] = u_c
        H[:, lay.n + 3] = -1.0
        if self.n_off:
            k = self._sys[cur]
            off = np.concatenate([[0.0], np.asarray(aux["system_offset"], float)]) if aux else np.zeros(
                len(self.systems))
            off_c = np.concatenate([[0.0], memory.offsets])
            pred = pred + off[k] - off_c[k]
            on = np.nonzero(k > 0)[0]
            H[on, self._i_off + k[on] - 1] = 1.0
            H[on, lay.n + 4 + k[on] - 1] = -1.0
        z = (self.carrier[cur] - self.carrier[prev]) - pred
        return z, H, np.full(len(cur), 2.0 * self.sigma_cp ** 2), cur

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, memory=None, aux=None) -> Rows | None:
        pr = super().rows(i, nav, w_b, clock, aux=aux)
        td = self.tdcp_rows(i, nav, clock, memory, aux)
        if td is None:
            return pr
        z, H, r, cur = td
        kinds = np.full(len(z), TDCP, dtype=np.int64)
        if pr is None:
            return Rows(z, H, r, kinds, self._tdcp_channels[cur])
        H_pr = np.zeros((len(pr.z), H.shape[1]))
        H_pr[:, :self.layout.n] = pr.H
        return Rows(np.concatenate([pr.z, z]), np.vstack([H_pr, H]), np.concatenate([pr.R, r]),
                    np.concatenate([pr.kinds, kinds]), np.concatenate([pr.channels, self._tdcp_channels[cur]]))
