"""Measurement differencing for AR(1) coloured measurement noise (paper P2 eqs. 13-20).

The noise of channel ``c`` (one satellite's pseudorange, one satellite's
range rate, one axis of a fix) is coloured::

    e_k = psi e_{k-1} + zeta_k,      zeta_k white (a Gaussian mixture)    # P2 eq. (7)

so the differenced measurement of two successive epochs has white noise::

    z*_k = z_k - psi z_{k-1} = H_k x_k - psi H_{k-1} x_{k-1} + zeta_k       # P2 eqs. (13)-(18)

P2 writes it as an update of the state at ``k-1`` followed by a prediction
(eq. 16, ``A* = A_{k+1} Phi - Psi A_k``). Here the state at ``k-1`` is carried
as a stochastic clone instead (the engine's mechanism, see
:mod:`mixnav.filters.ekf`): after each epoch's update the engine appends
``x_c = J x_{k-1}`` (``J`` selects the columns the measurement uses), and the
differenced row has ``H* = [H_k | -psi H_{k-1} J^T]``. For a linear-Gaussian
model the two are the same posterior (both are the exact conditional of the
current state on all measurements); the clone keeps the closed-loop feedback
of the INS untouched, and it is what lets one wrapper serve every
measurement model. With ``psi = 0`` the clone columns of ``H*`` are zero and
the update is the undifferenced one (the M6 = M3 invariant).

``z_{k-1}`` is the previous epoch's innovation *recomputed after its update*
(:meth:`remember`, with the corrected INS state), so it refers to the same
nominal state as the clone. Rows of a channel that was not measured at the
previous epoch (the first epoch, a rising satellite, after a gap longer than
1.5 epochs) are used undifferenced, with the stationary variance of the AR(1)
process, ``r / (1 - psi^2)`` (``r`` the model's variance, which is that of
``zeta``); their row kind is offset by :data:`STATIONARY` so a mixture filter
can give them their own standardised mixture (same weights and variance
scales, means times ``sqrt((1 + psi) / (1 - psi))``: the stationary mean
``mu / (1 - psi)`` in units of the stationary sigma). That
drops the correlation of a returning channel with its value before the gap
(slightly conservative, never inconsistent for gaps of many correlation times).
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError, NumericalError
from ..ins.error_model import StateLayout
from .base import MeasurementModel, Rows
from .kinds import MAX_KINDS, channel_id, kind_code
from .loose import LooseGnss
from .tight import TightGnss

#: Offset added to the row kind of an undifferenced (stationary-noise) row: its
#: stationary twin (:func:`mixnav.measurements.kinds.stationary`).
STATIONARY = MAX_KINDS


def clone_columns(model, layout: StateLayout) -> np.ndarray:
    """Error-state columns the model's Jacobian can use (the clone ``J`` selects them)."""
    lever = np.any(np.asarray(getattr(model, "lever", np.zeros(3))) != 0.0)
    cols = list(range(layout.pos.start, layout.pos.stop))
    if isinstance(model, TightGnss):
        rate = model.use_range_rate
        cols += [layout.clk] + ([layout.clk + 1] if rate else [])
    elif isinstance(model, LooseGnss):
        rate = model.use_velocity
    else:
        return np.arange(layout.n)
    if rate:
        cols += list(range(layout.vel.start, layout.vel.stop))
    if lever:
        cols += list(range(layout.att.start, layout.att.stop))
        if rate:
            cols += list(range(layout.bg.start, layout.bg.stop))
    return np.array(sorted(cols), dtype=np.int64)


class DifferencedMeasurement(MeasurementModel):
    """Wrap a measurement model so that its rows are differenced against the
    previous epoch (P2 eqs. 13-20), with a stochastic clone of the previous state.

    Parameters
    ----------
    inner : measurement model
        Needs ``times``, ``measure``, ``row_kinds`` and ``row_channels``
        (:class:`~mixnav.measurements.tight.TightGnss`,
        :class:`~mixnav.measurements.loose.LooseGnss`). It must not clone itself.
    layout : StateLayout
    psi : dict
        Observable kind name -> AR(1) coefficient per epoch, ``|psi| < 1``;
        kinds not listed are white (``psi = 0``).
    psi_channels : dict, optional
        Per-channel coefficients that replace the kind's: ``(kind name, id)``
        -> psi, ``id`` the satellite PRN (tight) or the axis 0-2 (loose).
    """

    remembers = True

    def __init__(self, inner, layout: StateLayout, psi: dict, psi_channels: dict | None = None):
        if getattr(inner, "clone_size", 0) or getattr(inner, "remembers", False):
            raise ArgumentError("measurement differencing cannot wrap a model that remembers its previous "
                                "epoch (e.g. tdcp-ekf): use tight-ekf or loose-ekf", argument="inner")
        if isinstance(inner, TightGnss) and len(inner.systems) > 1:
            # the remembered epoch's rows would need the inter-system offsets too (not passed yet)
            raise ArgumentError("measurement differencing (the coloured-noise bank) takes one satellite system so "
                                f"far; this tight model has {len(inner.systems)}: read GPS alone (systems = "
                                "[\"G\"]) for it", argument="inner")
        if not hasattr(inner, "row_channels"):
            raise ArgumentError(f"{type(inner).__name__} does not name the channel of its rows, "
                                "which differencing needs", argument="inner")
        self.inner = inner
        self.layout = layout
        self.kinds = tuple(inner.kinds)
        self.psi_by_code = np.zeros(MAX_KINDS)
        for name, v in psi.items():
            code = kind_code(name, argument=f"psi.{name}")
            if not (np.isfinite(v) and abs(v) < 1.0):
                raise ArgumentError(f"AR(1) coefficient must satisfy |psi| < 1 (stationary), got {v}",
                                    argument=f"psi.{name}")
            self.psi_by_code[code] = float(v)
        self.psi_channels = {}
        for (name, cid), v in (psi_channels or {}).items():
            arg = f"psi_channels.{name}:{cid}"
            code = kind_code(name, argument=arg)
            if not (np.isfinite(v) and abs(v) < 1.0):
                raise ArgumentError(f"AR(1) coefficient must satisfy |psi| < 1 (stationary), got {v}", argument=arg)
            self.psi_channels[channel_id(code, int(cid))] = float(v)
        self.cols = clone_columns(inner, layout)
        self.clone_size = len(self.cols)
        t = np.asarray(inner.times, dtype=float)
        dt = np.diff(t)
        self.max_gap = 1.5 * (float(np.median(dt)) if len(dt) else np.inf)

    @property
    def times(self) -> np.ndarray:
        return self.inner.times

    # --- the clone -------------------------------------------------------------------------
    def clone_rows(self, nav: np.ndarray) -> np.ndarray:
        """``J`` (c, n): the columns of the error state the measurement uses."""
        J = np.zeros((self.clone_size, self.layout.n))
        J[np.arange(self.clone_size), self.cols] = 1.0
        return J

    def remember(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock):
        """The innovations of epoch ``i`` recomputed with the updated state (the clone's
        nominal): ``(i, channels, z, H on the clone columns)``, or None."""
        rows = self.inner.rows(i, nav, w_b, clock)
        if rows is None:
            return None
        z, H = rows.z, np.asarray(rows.H)
        Hc = H[:, self.cols]
        if np.count_nonzero(H) != np.count_nonzero(Hc):  # a bug in clone_columns, not bad input
            raise NumericalError("the measurement Jacobian uses columns outside the clone")
        return (int(i), self.inner.row_channels(i, len(z)), np.array(z, dtype=float), Hc)

    def correct_memory(self, memory, dx_c: np.ndarray):
        """The clone's nominal moved by ``dx_c``: the remembered innovations follow it."""
        if memory is None:
            return None
        i, ch, z, Hc = memory
        return (i, ch, z - Hc @ dx_c, Hc)

    # --- the measurement ---------------------------------------------------------------------
    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock, memory=None, aux=None) -> Rows | None:
        """``(z*, H*, r)``: ``H*`` has ``n + c`` columns (the clone last), or ``n`` when
        no row is differenced; rows of channels measured at the previous epoch are
        differenced (kind ``k``, noise ``zeta``), the others are not (kind
        ``k + STATIONARY``, the stationary noise of the AR(1) process)."""
        inner = self.inner.rows(i, nav, w_b, clock, aux=aux)
        if inner is None:
            return None
        z, H, r = inner.z, inner.H, inner.R
        m, n = len(z), self.layout.n
        kinds = np.asarray(inner.kinds, dtype=np.int64)
        ch = self.inner.row_channels(i, m)
        psi_row = self.psi_by_code[kinds]
        if self.psi_channels:
            psi_row = psi_row.copy()
            for q, c in enumerate(ch):
                psi_row[q] = self.psi_channels.get(int(c), psi_row[q])
        Ha = np.zeros((m, n + self.clone_size))
        Ha[:, :n] = H
        za = np.array(z, dtype=float)
        stationary = np.ones(m, dtype=bool)
        prev = memory
        t = self.inner.times
        if prev is not None and prev[0] < i and t[i] - t[prev[0]] <= self.max_gap:
            _, ch_p, z_p, Hc_p = prev
            _, a, b = np.intersect1d(ch, ch_p, assume_unique=True, return_indices=True)
            psi = psi_row[a]
            za[a] -= psi * z_p[b]                                       # P2 eq. (15)
            Ha[a, n:] = -psi[:, None] * Hc_p[b]                         # P2 eq. (16), clone form
            stationary[a] = False
        if stationary.all():  # no clone in use (the engine may not carry one yet)
            Ha = Ha[:, :n]
        ra = np.array(r, dtype=float)
        ps = psi_row[stationary]
        ra[stationary] /= 1.0 - ps * ps                                 # stationary variance of e
        return Rows(za, Ha, ra, kinds + STATIONARY * stationary, ch)
