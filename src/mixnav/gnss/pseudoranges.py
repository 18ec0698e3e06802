"""Pseudorange epochs of any number of systems, held flat (one row per measurement).

The processed form the pseudorange measurement model
(:class:`mixnav.measurements.pseudorange.PseudorangeGnss`) reads, derived from a reader's
:class:`mixnav.data.RawPseudoranges`: corrected ones (a smartLoc log: satellite clock and
atmosphere removed, satellite position at the transmit time in the ECEF frame of that time)
grouped by :meth:`PseudorangeEpochs.from_raw`, broadcast ones once the broadcast corrections
are applied (:func:`mixnav.gnss.spp.corrected_pseudoranges`). No reader returns it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError

#: system codes (smartLoc's, a bit per system) -> RINEX letter
SYSTEM_LETTERS = {1: "G", 2: "S", 4: "R", 8: "E", 16: "J", 32: "C"}


@dataclass(frozen=True)
class PseudorangeEpochs:
    """Pseudoranges of ``E`` epochs, ``M`` rows in all, rows of epoch ``e`` in
    ``start[e]:start[e + 1]``.

    Attributes
    ----------
    time : ndarray (E,)
        Receive times [s], strictly increasing.
    start : ndarray of int (E + 1,)
    pseudorange : ndarray (M,)
        [m], satellite clock (and atmosphere, where the source removed it) removed.
    variance : ndarray (M,)
        The source's variance [m^2] (> 0).
    sat_ecef : ndarray (M, 3)
        Satellite position at the transmit time, ECEF of that time [m] (the model
        turns it into the reception-time frame).
    sat_id : ndarray of int (M,)
    system : ndarray of int (M,)
        System code (:data:`SYSTEM_LETTERS`).
    elevation : ndarray (M,)
        [rad] (NaN where unknown).
    cn0 : ndarray (M,)
        [dB-Hz] (NaN where unknown).
    source : str or None
    sat_vel : ndarray (M, 3) or None
        Satellite velocity at the transmit time, ECEF of that time [m/s] (where Doppler is given).
    range_rate : ndarray (M,) or None
        Range rate from the Doppler [m/s], satellite clock drift removed (NaN where the
        receiver gave none); None: no Doppler at all.
    """

    time: np.ndarray
    start: np.ndarray
    pseudorange: np.ndarray
    variance: np.ndarray
    sat_ecef: np.ndarray
    sat_id: np.ndarray
    system: np.ndarray
    elevation: np.ndarray
    cn0: np.ndarray
    source: str | None = None
    sat_vel: np.ndarray | None = None
    range_rate: np.ndarray | None = None

    def __post_init__(self):
        M = len(self.pseudorange)
        E = len(self.time)
        where = self.source or "pseudoranges"
        if self.start.shape != (E + 1,) or self.start[0] != 0 or self.start[-1] != M or (np.diff(self.start) < 0).any():
            raise ArgumentError(f"{where}: start must run from 0 to {M} without decreasing", argument="start")
        for name in ("variance", "sat_id", "system", "elevation", "cn0"):
            if getattr(self, name).shape != (M,):
                raise ArgumentError(f"{where}: {name} has shape {getattr(self, name).shape}, expected ({M},)",
                                    argument=name)
        if (self.sat_vel is None) != (self.range_rate is None):
            raise ArgumentError(f"{where}: sat_vel and range_rate go together", argument="range_rate")
        if self.range_rate is not None and (self.range_rate.shape != (M,) or self.sat_vel.shape != (M, 3)):
            raise ArgumentError(f"{where}: range_rate must be ({M},) and sat_vel ({M}, 3)", argument="range_rate")
        if self.sat_ecef.shape != (M, 3):
            raise ArgumentError(f"{where}: sat_ecef must be ({M}, 3)", argument="sat_ecef")
        if E > 1 and (np.diff(self.time) <= 0).any():
            raise ArgumentError(f"{where}: epoch times must increase strictly", argument="time")
        if not (np.isfinite(self.pseudorange).all() and np.isfinite(self.sat_ecef).all()):
            raise ArgumentError(f"{where}: non-finite pseudorange or satellite position", argument="pseudorange")
        if not (self.variance > 0).all():
            raise ArgumentError(f"{where}: variances must be positive", argument="variance")

    @classmethod
    def from_rows(cls, time, pseudorange, variance, sat_ecef, sat_id, system, elevation=None, cn0=None,
                  source=None, sat_vel=None, range_rate=None) -> "PseudorangeEpochs":
        """Group rows sharing a time (rows need not be sorted; a stable sort keeps their order)."""
        t = np.asarray(time, dtype=float)
        order = np.argsort(t, kind="stable")
        t = t[order]
        times, first = np.unique(t, return_index=True)
        start = np.append(first, len(t)).astype(np.int64)
        nan = np.full(len(t), np.nan)
        pick = lambda a: nan.copy() if a is None else np.asarray(a, dtype=float)[order]  # noqa: E731
        return cls(time=times, start=start, pseudorange=np.asarray(pseudorange, dtype=float)[order],
                   variance=np.asarray(variance, dtype=float)[order],
                   sat_ecef=np.asarray(sat_ecef, dtype=float)[order],
                   sat_id=np.asarray(sat_id, dtype=np.int64)[order], system=np.asarray(system, dtype=np.int64)[order],
                   elevation=pick(elevation), cn0=pick(cn0), source=source,
                   sat_vel=None if sat_vel is None else np.asarray(sat_vel, dtype=float)[order],
                   range_rate=None if range_rate is None else np.asarray(range_rate, dtype=float)[order])

    @classmethod
    def from_raw(cls, raw) -> "PseudorangeEpochs":
        """The corrected pseudoranges of a reader's :class:`~mixnav.data.RawPseudoranges`
        (``corrected = True``: satellite positions and variances given) grouped by epoch, file
        order kept inside an epoch; times are the epochs' ``tow`` (a smartLoc log's seconds).
        Broadcast pseudoranges are an ArgumentError: their satellite states and corrections
        come from a navigation file (:func:`mixnav.gnss.spp.corrected_pseudoranges`)."""
        if not raw.corrected:
            raise ArgumentError(f"{raw.source or 'pseudoranges'}: broadcast pseudoranges have no satellite "
                                "positions yet: apply the navigation file's corrections "
                                "(mixnav.gnss.spp.corrected_pseudoranges)", argument="raw")
        codes = {letter: code for code, letter in SYSTEM_LETTERS.items()}
        system = np.array([codes[s] for s in raw.systems()], dtype=np.int64)
        epoch = np.asarray(raw.epoch, dtype=np.int64)
        return cls.from_rows(np.asarray(raw.tow, dtype=float)[epoch], raw.pseudorange, raw.variance, raw.sat_ecef,
                             raw.prn, system, raw.elevation, raw.cn0, source=raw.source)

    def __len__(self) -> int:
        return len(self.time)

    def rows_of(self, e: int) -> slice:
        return slice(int(self.start[e]), int(self.start[e + 1]))

    def counts(self) -> np.ndarray:
        """Rows per epoch (E,)."""
        return np.diff(self.start)
