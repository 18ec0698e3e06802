"""Pseudoranges of several systems with a receiver clock per system, for any motion model.

Innovation of satellite ``j`` of system ``g`` (antenna ``r_a``, receiver clock
bias ``b`` [m] of the reference system, inter-system offset ``o_g`` [m], zero
for the reference system)::

    z_j = rho_j - (|R3(OMEGA_E tau_j) s_j - r_a| + b + o_g),   tau_j = |s_j - r_a| / c
    H_j = [-u_n^T on the position block, 1 on the clock bias, 1 on o_g]

(``u_n`` the unit line of sight antenna -> satellite in NED; the satellite
position ``s_j`` is given at the transmit time in the ECEF frame of that
time and turned into the reception-time frame by the Earth's rotation
during the travel time, one fixed-point step: the next changes the range by
well under a millimetre.) The inter-system offsets are the layout's auxiliary
block ``system_offset`` (one state per system after the first of
``systems``); rows of a system not in ``systems`` are dropped when the model
is built and counted (``skipped_rows``).

Ensemble estimators (UKF, DD2, PF, GMPF) get ``h`` on a batch of members
(:meth:`PseudorangeGnss.predict_batch`): each member's own antenna, clock bias and
inter-system offsets, the same travel time and Earth rotation per member as the
rows above, so at the nominal ``y - Y[0]`` is the rows' ``z``.

Noise: ``variance = "given"`` uses the source's variance times ``scale``;
``"elevation"`` uses ``scale (sigma_a^2 + sigma_b^2 / sin^2 el)``.

The model reads only the position, clock and offset blocks, so it serves the
strapdown INS (no lever arm: the antenna is taken at the navigation point),
the dead-reckoning and the constant-velocity models alike. Channels: one per
satellite, :func:`~mixnav.measurements.kinds.channel_id` of the kind, system and satellite.
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from ..geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from ..gnss.geometry import C_LIGHT, earth_rotation_correction
from ..gnss.pseudoranges import PseudorangeEpochs
from ._pseudorange_kernel import pseudorange_predict_batch
from .base import MeasurementModel, Rows
from .kinds import PSEUDORANGE, channel_id


class PseudorangeGnss(MeasurementModel):
    """Pseudorange rows of every used satellite of an epoch (module docstring).

    Parameters
    ----------
    epochs : PseudorangeEpochs
    layout : StateLayout
        With a ``position`` block, the ``clock`` block and, for more than one
        system, an auxiliary ``system_offset`` block of ``len(systems) - 1`` states.
    systems : sequence of int
        System codes used, the clock's reference system first (default: GPS,
        then GLONASS).
    variance : "given" or "elevation"
    scale : float
        Factor on the variance (> 0).
    sigma_a, sigma_b : float
        [m], the elevation model's terms.
    elevation_mask : float
        [rad]; rows below it are not used (rows with unknown elevation are).
    min_satellites : int
        Epochs with fewer used rows give no update.
    """

    kinds = ("pseudorange",)
    #: predict_batch takes each member's auxiliary states (the inter-system offsets)
    batch_aux = True

    def __init__(self, epochs: PseudorangeEpochs, layout, systems=(1, 4), variance: str = "given",
                 scale: float = 1.0, sigma_a: float = 3.0, sigma_b: float = 3.0, elevation_mask: float = 0.0,
                 min_satellites: int = 1):
        if not isinstance(epochs, PseudorangeEpochs):
            raise ArgumentError(f"expected PseudorangeEpochs, got {type(epochs).__name__}", argument="epochs")
        if layout.clk < 0:
            raise ArgumentError("pseudoranges need the receiver clock block in the layout", argument="layout")
        systems = tuple(int(s) for s in systems)
        if not systems or len(set(systems)) != len(systems):
            raise ArgumentError(f"give distinct system codes, got {systems}", argument="systems")
        n_off = len(systems) - 1
        if n_off:
            if not layout.has("system_offset") or layout.block("system_offset").size != n_off:
                raise ArgumentError(f"{len(systems)} systems need an auxiliary block 'system_offset' of {n_off} "
                                    "states in the layout", argument="layout")
        if variance not in ("given", "elevation"):
            raise ArgumentError(f"must be 'given' or 'elevation', got {variance!r}", argument="variance")
        if not scale > 0:
            raise ArgumentError(f"must be positive, got {scale}", argument="scale")
        self.epochs = epochs
        self.layout = layout
        self.systems = systems
        self.min_satellites = int(min_satellites)
        sys_index = np.full(len(epochs.system), -1, dtype=np.int64)
        for k, s in enumerate(systems):
            sys_index[epochs.system == s] = k
        el = epochs.elevation
        use = (sys_index >= 0) & ~(np.isfinite(el) & (el < elevation_mask))
        self.skipped_rows = {"unknown_system": int((sys_index < 0).sum()),
                             "below_mask": int(((sys_index >= 0) & ~use).sum())}
        self._use = use
        self._sys = sys_index
        if variance == "given":
            self._var = scale * epochs.variance
        else:
            s_el = np.sin(np.where(np.isfinite(el), el, np.pi / 2))
            self._var = scale * (sigma_a ** 2 + sigma_b ** 2 / np.maximum(s_el, 0.05) ** 2)
        self._channels = channel_id(PSEUDORANGE, epochs.sat_id, epochs.system)
        self._i_off = layout.slice("system_offset").start if n_off else -1

    @property
    def times(self) -> np.ndarray:
        return self.epochs.time

    def used_rows(self, i: int) -> np.ndarray:
        """Indices (into the epochs' flat rows) of epoch ``i``'s used rows."""
        sl = self.epochs.rows_of(i)
        idx = np.arange(sl.start, sl.stop)
        return idx[self._use[sl]]

    def predicted(self, i: int, nav: np.ndarray, clock, aux=None):
        """``(rows, predicted pseudoranges (m,), u_n (m, 3))`` at the nominal ``nav``."""
        idx = self.used_rows(i)
        r_a = lla_to_ecef(nav[7:10])
        s = self.epochs.sat_ecef[idx]
        tau = np.linalg.norm(s - r_a, axis=1) / C_LIGHT
        d = earth_rotation_correction(s, tau) - r_a
        rng = np.linalg.norm(d, axis=1)
        u_n = (d / rng[:, None]) @ dcm_ecef_to_ned(nav[7], nav[8]).T
        pred = rng + clock[0]
        if self._i_off >= 0:
            k = self._sys[idx]
            off = np.concatenate([[0.0], np.asarray(aux["system_offset"], dtype=float)]) if aux else np.zeros(
                len(self.systems))
            pred = pred + off[k]
        return idx, pred, u_n

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, memory=None, aux=None) -> Rows | None:
        idx = self.used_rows(i)
        if len(idx) < max(self.min_satellites, 1):
            return None
        idx, pred, u_n = self.predicted(i, nav, clock, aux)
        lay = self.layout
        m = len(idx)
        H = np.zeros((m, lay.n))
        H[:, lay.pos] = -u_n
        H[:, lay.clk] = 1.0
        if self._i_off >= 0:
            k = self._sys[idx]
            rows = np.nonzero(k > 0)[0]
            H[rows, self._i_off + k[rows] - 1] = 1.0
        z = self.epochs.pseudorange[idx] - pred
        return Rows(z, H, self._var[idx].copy(), np.full(m, PSEUDORANGE, dtype=np.int64), self._channels[idx])

    def predict_batch(self, i: int, navs: np.ndarray, w_b: np.ndarray, clocks=None, aux=None):
        """``h`` at a batch of full states, for the ensemble estimators: ``(y, Y, R)``.

        ``y`` (m,) the measured pseudoranges of the epoch's used rows [m] (the order of
        :meth:`rows`), ``Y`` (N, m) their predictions at the states ``navs`` (N, 10)
        (only the position ``navs[:, 7:10]`` is read: antenna at the navigation point),
        each with its receiver clock ``clocks`` (2,) or (N, 2) (bias [m]; the drift is not
        used: no Doppler rows) and its offsets ``aux["system_offset"]`` (n_off,) or
        (N, n_off) [m] (default zero); ``R`` (m,) the variances. ``w_b`` is not used.
        None with fewer than ``min_satellites`` used rows.
        """
        idx = self.used_rows(i)
        if len(idx) < max(self.min_satellites, 1):
            return None
        navs = np.atleast_2d(np.asarray(navs, dtype=float))
        N = len(navs)
        bias = np.zeros(N) if clocks is None else np.broadcast_to(np.asarray(clocks, dtype=float), (N, 2))[:, 0]
        off = np.zeros((N, len(self.systems)))                           # column 0: the reference system
        if self._i_off >= 0 and aux is not None and "system_offset" in aux:
            off[:, 1:] = np.broadcast_to(np.asarray(aux["system_offset"], dtype=float), (N, len(self.systems) - 1))
        Y = np.empty((N, len(idx)))
        pseudorange_predict_batch(np.ascontiguousarray(navs[:, 7:10]), self.epochs.sat_ecef[idx],
                                  np.ascontiguousarray(bias), off, self._sys[idx], Y)   # one compiled call
        return self.epochs.pseudorange[idx].copy(), Y, self._var[idx].copy()

    def warm_up(self, nav: np.ndarray, aux: dict | None = None) -> None:
        """Compile (or load) the batch prediction too, outside the timed loop."""
        super().warm_up(nav, aux)
        for i in range(len(self.times)):
            if self.predict_batch(i, np.array(nav, dtype=float)[None], np.zeros(3)) is not None:
                break

    def row_kinds(self, i: int, m: int) -> np.ndarray:
        return np.full(m, PSEUDORANGE, dtype=np.int64)

    def row_channels(self, i: int, m: int) -> np.ndarray:
        return self._channels[self.used_rows(i)]

    def row_info(self, i: int) -> dict:
        """Elevation [rad], C/N0 [dB-Hz], system and satellite of epoch ``i``'s used rows
        (for noise models that weigh by them)."""
        idx = self.used_rows(i)
        e = self.epochs
        return {"elevation": e.elevation[idx], "cn0": e.cn0[idx], "system": e.system[idx], "sat_id": e.sat_id[idx]}
