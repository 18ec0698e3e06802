"""Broadcast ephemeris of every GNSS from RINEX navigation files: one registry per system.

:class:`MultiEphemeris` reads any number of RINEX navigation files -- RINEX 3
mixed (``M``) or single-system files, RINEX 2 GPS (``N``, ``.n``), GLONASS
(``G``, ``.g``), Galileo (``E``, or RTKLIB's ``L``) and QZSS (RTKLIB's ``J``)
files -- with its own reader
(:func:`read_rinex_nav`; georinex 1.16 loses BeiDou records with blank spare
fields) -- and keeps one ephemeris per system letter:

===  ========  =========================  ===================================
sys  model     time scale of the records  group delay for the 1st-frequency user
===  ========  =========================  ===================================
G    Kepler    GPST                       T_GD (L1 C/A)
J    Kepler    QZSST = GPST               T_GD (L1 C/A)
E    Kepler    GST = GPST (GPS weeks)     BGD(E1,E5b) with I/NAV (default),
                                          BGD(E1,E5a) with F/NAV
C    Kepler    BDT = GPST - 14 s          T_GD1 (B1I)
R    RK4       UTC epochs (+ leap s)      none (tau_n is the L1 clock)
===  ========  =========================  ===================================

Every query is in GPS time (``week``, ``tow``); each system converts to its
own scale (:mod:`mixnav.gnss.gnss_time`). The orbit and clock models are in
:mod:`mixnav.gnss.orbits`.

Galileo records (OS SIS ICD 5.1.9.2; RINEX 3 "data sources" word): I/NAV
records (bit 0 E1-B or bit 2 E5b-I, clock for E5b/E1: bit 9) or F/NAV records
(bit 1 E5a-I, clock for E5a/E1: bit 8) are kept, per ``galileo_nav``; the
other kind is dropped (counted in :attr:`MultiEphemeris.dropped`). The E1
single-frequency clock is ``dt(E1) = dt(E1,E5x) - BGD(E1,E5x)`` (OS SIS ICD
5.1.5) with ``x = b`` for I/NAV and ``x = a`` for F/NAV. Health: the E1-B
signal's data validity and health bits (bits 0-2 of the RINEX health word)
must be zero.

Record choice (every system): among a satellite's healthy records (health 0;
BeiDou SatH1 0; GLONASS Bn 0), the one with the reference time nearest the
query, used when within the system's ``max_age`` (:data:`DEFAULT_MAX_AGES`).

GLONASS navigation epochs are UTC; ``GPST = UTC + leap seconds``, the count
read from a navigation file's ``LEAP SECONDS`` header line (a BeiDou file's is
BDT - UTC and is not used), else from the table in
:mod:`mixnav.gnss.gnss_time`. GLONASS frequency channel numbers (-7..+6, or
up to +13 in old files) are exposed by :meth:`MultiEphemeris.glonass_channel`.

Errors: a file that cannot be read or parsed is a :class:`~mixnav.errors.DataError`
naming it; a record missing a parameter names the satellite and epoch; a
system with no navigation data is no error: its satellites come back skipped
("no navigation data for the system"), counted per system.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ArgumentError, DataError
from . import gnss_time
from .ephemeris import DEFAULT_MAX_AGE, BroadcastEphemeris, EphemerisSkips
from .geometry import SECONDS_PER_WEEK, SatelliteStates
from .orbits import BEIDOU, GALILEO, GLONASS_STEP, GPS, QZSS, KeplerConstants, glonass_states, kepler_states

SYSTEM_NAMES = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "C": "BeiDou", "J": "QZSS"}
KEPLER_CONSTANTS = {"G": GPS, "J": QZSS, "E": GALILEO, "C": BEIDOU}
#: Default ``|t - t_ref|`` limit per system [s]: GPS 4 h fit interval / 2 + 15 min;
#: QZSS 2 h fit / 2 (IS-QZSS-PNT); Galileo 4 h (OS SIS ICD nominal validity);
#: BeiDou 2 h (hourly uploads, 1 h curve fit, one upload missed);
#: GLONASS 30 min (t_b every 30 min, one upload missed).
DEFAULT_MAX_AGES = {"G": DEFAULT_MAX_AGE, "J": 3600.0, "E": 4 * 3600.0, "C": 2 * 3600.0, "R": 1800.0}
#: BeiDou satellites on geostationary orbits (BDS-SIS-ICD-B1I; C59-C63 for BDS-3).
BEIDOU_GEO_PRNS = (1, 2, 3, 4, 5, 59, 60, 61, 62, 63)
#: Reason given for the satellites of a system no file gave records for.
NO_SYSTEM_DATA = "no navigation data for the system"

_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
_BDT_EPOCH = np.datetime64("2006-01-01T00:00:00", "ns")
# Galileo data-source bits (RINEX 3.0x, Galileo BROADCAST ORBIT 5)
_INAV_BITS, _FNAV_BITS, _CLOCK_E5A, _CLOCK_E5B = 0b101, 0b010, 1 << 8, 1 << 9
_E1B_HEALTH_BITS = 0b111


#: GPS URA values [m] by index (IS-GPS-200 20.3.3.3.1.1; also QZSS and BeiDou's URA)
URA_TABLE = np.array([2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0,
                      6144.0])
#: GLONASS broadcasts no accuracy in RINEX: a 5 m orbit + clock sigma (RTKLIB's ERREPH_GLO)
GLONASS_EPHEMERIS_SIGMA = 5.0
#: Galileo SISA "no accurate prediction available" sigma [m] (RTKLIB's STD_GAL_NAPA)
SISA_NAPA_SIGMA = 500.0


def ephemeris_variance(system: str, accuracy) -> np.ndarray:
    """Orbit + clock variance [m^2] of broadcast records from their accuracy field [m], the way
    RTKLIB's single point weighs them (written from the ICDs, following RTKLIB's rounding):

    - GPS, QZSS, BeiDou: the URA the field names is the first entry of :data:`URA_TABLE` at or
      above it (the index the receiver decoded); its square; beyond the table or blank, 6144^2;
    - Galileo: SISA [m] to its index (OS SIS ICD 5.1.12: 1 cm steps to 0.49 m, 2 cm to
      0.98 m, 4 cm to 1.96 m, 16 cm to 6 m) and back, squared; negative, beyond 6 m or blank
      (NAPA): :data:`SISA_NAPA_SIGMA`^2;
    - GLONASS: :data:`GLONASS_EPHEMERIS_SIGMA`^2.
    """
    a = np.atleast_1d(np.asarray(accuracy, float))
    if system == "R":
        return np.full(a.shape, GLONASS_EPHEMERIS_SIGMA ** 2)
    if system == "E":
        v = np.where(np.isfinite(a), a, -1.0)
        sig = np.full(a.shape, SISA_NAPA_SIGMA)
        # index steps as the SISA encoding; the value back from the rounded index
        for lo, hi, step, base, first in ((0.0, 0.49, 0.01, 0.0, 0), (0.49, 0.98, 0.02, 0.5, 50),
                                          (0.98, 1.96, 0.04, 1.0, 75), (1.96, 6.0, 0.16, 2.0, 100)):
            m = (v > lo if first else v >= lo) & (v <= hi)
            idx = np.round((v[m] - base) / step)
            sig[m] = base + idx * step
        return sig ** 2
    idx = np.searchsorted(URA_TABLE, np.where(np.isfinite(a), a, np.inf), side="left")
    return np.append(URA_TABLE, 6144.0)[np.minimum(idx, len(URA_TABLE))] ** 2


class KeplerEphemeris(BroadcastEphemeris):
    """Keplerian broadcast records of one system (G, J, E or C): BroadcastEphemeris's
    selection and interface with the system's constants and time scale.

    Parameters
    ----------
    system : str
        ``"G"``, ``"J"``, ``"E"`` or ``"C"``.
    records : dict of str -> ndarray (m,)
        As :class:`~mixnav.gnss.ephemeris.BroadcastEphemeris`'s, in the
        system's time scale (BeiDou: BDT weeks and seconds), ``tgd`` the group
        delay the first-frequency user subtracts.
    const : KeplerConstants or None
        Default: the system's (:data:`KEPLER_CONSTANTS`).
    """

    def __init__(self, system: str, records: dict, source: str = "", const: KeplerConstants | None = None,
                 max_age: float | None = None, iono_alpha=None, iono_beta=None):
        super().__init__(records, source=source, iono_alpha=iono_alpha, iono_beta=iono_beta,
                         max_age=DEFAULT_MAX_AGES[system] if max_age is None else max_age)
        self.system = system
        self.const = KEPLER_CONSTANTS[system] if const is None else const
        self._geo = (np.isin(self.rec["prn"], BEIDOU_GEO_PRNS) if system == "C"
                     else np.zeros(len(self.rec["prn"]), bool))

    def _system_time(self, t_gps):
        return gnss_time.gpst_to_bdt(t_gps) if self.system == "C" else t_gps

    def _compute(self, idx, t, apply_tgd):
        r = {k: v[idx] for k, v in self.rec.items()}
        geo = self._geo[idx]
        return kepler_states(r, t, self.const, apply_group_delay=apply_tgd, geo=geo if geo.any() else None)


class GlonassEphemeris(BroadcastEphemeris):
    """GLONASS broadcast records (position, velocity, luni-solar acceleration at t_b).

    Parameters
    ----------
    records : dict of str -> ndarray
        ``prn``, ``week`` and ``toe`` (GPS week and seconds of week of t_b, in
        GPST), ``pos``, ``vel``, ``acc`` (m, 3) [m, m/s, m/s^2], ``minus_tau_n``
        [s], ``gamma_n``, ``health`` (Bn), ``channel`` (frequency number k,
        NaN when absent).
    step : float
        Largest RK4 step [s].

    The interface is BroadcastEphemeris's (``apply_tgd`` has no effect).
    """

    system = "R"

    def __init__(self, records: dict, source: str = "", max_age: float | None = None,
                 step: float = GLONASS_STEP):
        super().__init__(records, source=source, max_age=DEFAULT_MAX_AGES["R"] if max_age is None else max_age)
        self.step = float(step)

    def _compute(self, idx, t, apply_tgd):
        r = {k: v[idx] for k, v in self.rec.items()}
        r["tb"] = r["week"] * SECONDS_PER_WEEK + r["toe"]
        return glonass_states(r, t, self.step)

    def channels(self) -> dict[int, int]:
        """Frequency channel number k per satellite (from its latest record that gives one)."""
        out: dict[int, int] = {}
        order = np.argsort(self.rec["week"] * SECONDS_PER_WEEK + self.rec["toe"], kind="stable")
        for i in order:
            k = self.rec["channel"][i]
            if np.isfinite(k) and -7 <= k <= 13:
                out[int(self.rec["prn"][i])] = int(k)
        return out


@dataclass
class MultiEphemeris:
    """Broadcast ephemeris of several systems, keyed by RINEX system letter.

    Build it with :meth:`from_rinex`. ``eph[letter]`` is the system's
    :class:`KeplerEphemeris` or :class:`GlonassEphemeris`, which has
    BroadcastEphemeris's interface (``states``, ``states_and_skips``,
    ``prns``) and so works with :func:`mixnav.gnss.spp.satellites_at_transmit`.

    Attributes
    ----------
    systems : dict of str -> ephemeris
        The systems some file gave records for.
    sources : tuple of str
        The files read.
    leap_seconds : float
        GPST - UTC [s] used for GLONASS.
    leap_seconds_source : str
        The header it came from, or ``"table"``.
    dropped : dict of str -> int
        Records not used, per reason (the other Galileo message, systems mixnav
        has no model for such as SBAS ``S`` or NavIC ``I``).
    """

    systems: dict
    sources: tuple = ()
    leap_seconds: float = 18.0
    leap_seconds_source: str = "table"
    dropped: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ reading
    @classmethod
    def from_rinex(cls, paths, leap_seconds: float | None = None, galileo_nav: str = "inav",
                   max_age: dict | None = None, glonass_step: float = GLONASS_STEP) -> "MultiEphemeris":
        """Read RINEX 2/3 navigation files of any systems (mixed or one system a file).

        Parameters
        ----------
        paths : path or sequence of paths
        leap_seconds : float or None
            GPST - UTC [s] for GLONASS; None: from the headers, else the table.
        galileo_nav : {"inav", "fnav"}
            Which Galileo message's records to use (see the module docstring).
        max_age : dict of str -> float or None
            Per-system overrides of :data:`DEFAULT_MAX_AGES` [s].
        glonass_step : float
            Largest GLONASS integration step [s].

        Raises
        ------
        DataError
            A file missing, unreadable, not a navigation file, of an
            unsupported RINEX 2 type, or with an incomplete record; the
            message names the file (and the satellite, epoch and line).
        ArgumentError
            ``galileo_nav`` not one of the two.
        """
        if galileo_nav not in ("inav", "fnav"):
            raise ArgumentError(f"must be 'inav' or 'fnav', not {galileo_nav!r}", "galileo_nav")
        paths = [Path(paths)] if isinstance(paths, (str, Path)) else [Path(p) for p in paths]
        ages = dict(DEFAULT_MAX_AGES, **(max_age or {}))
        parts: dict[str, list] = {}
        dropped: dict[str, int] = {}
        iono: dict[str, np.ndarray] = {}
        header_leaps = []
        loaded = []
        for path in paths:
            head, records = read_rinex_nav(path)
            if head["leap"] is not None and head["system"] != "C":
                header_leaps.append((head["leap"], str(path)))
            loaded.append((path, head, records))
        if leap_seconds is not None:
            leap, leap_src = float(leap_seconds), "argument"
        elif header_leaps:
            leap, leap_src = float(header_leaps[0][0]), header_leaps[0][1]
        else:
            leap, leap_src = None, "table"
        for path, head, records in loaded:
            src = str(path)
            for letter, raw in records.items():
                if letter not in SYSTEM_NAMES:
                    key = f"{letter} records (no model)"
                    dropped[key] = dropped.get(key, 0) + len(raw["prn"])
                    continue
                if letter == "R":
                    rec = _glonass_records(raw, leap)
                else:
                    rec, n_other = _kepler_records(raw, letter, galileo_nav)
                    if n_other:
                        key = "Galileo F/NAV records" if galileo_nav == "inav" else "Galileo I/NAV records"
                        dropped[key] = dropped.get(key, 0) + n_other
                if rec is not None:
                    parts.setdefault(letter, []).append((rec, src))
            for letter, coeffs in head["iono"].items():
                iono.setdefault(letter, coeffs)
        systems = {}
        for letter, recs in parts.items():
            keys = recs[0][0].keys()
            rec = {k: np.concatenate([r[k] for r, _ in recs]) for k in keys}
            source = ", ".join(dict.fromkeys(s for _, s in recs))
            if letter == "R":
                systems[letter] = GlonassEphemeris(rec, source=source, max_age=ages["R"], step=glonass_step)
            else:
                a = iono.get(letter)
                systems[letter] = KeplerEphemeris(letter, rec, source=source, max_age=ages[letter],
                                                  iono_alpha=None if a is None else a[:4],
                                                  iono_beta=None if a is None else a[4:])
        if leap is None:
            leap = _table_leap(systems)
        return cls(systems, tuple(str(p) for p in paths), float(leap), leap_src, dropped)

    # ------------------------------------------------------------------ queries
    def __getitem__(self, system: str):
        return self.systems[system]

    def __contains__(self, system: str) -> bool:
        return system in self.systems

    def states(self, system: str, prn, week, tow, apply_group_delay: bool = True) -> SatelliteStates:
        """Satellite states of one system at GPS time(s); see :meth:`states_and_skips`."""
        return self.states_and_skips(system, prn, week, tow, apply_group_delay)[0]

    def states_and_skips(self, system: str, prn, week, tow,
                         apply_group_delay: bool = True) -> tuple[SatelliteStates, EphemerisSkips]:
        """Position, velocity and clock of satellites of one system at GPS time(s).

        Parameters
        ----------
        system : str
            RINEX letter: ``G``, ``R``, ``E``, ``C`` or ``J``.
        prn : array_like of int (n,) or None
            Satellite numbers; None: every satellite of the system with records.
        week : int or ndarray of int (n,)
            GPS week.
        tow : float or ndarray (n,)
            GPS seconds of week [s] (one per satellite, or one for all).
        apply_group_delay : bool
            Subtract the first-frequency group delay (table in the module docstring).

        Returns
        -------
        states : SatelliteStates
            The satellites with a usable record, in the order asked
            (positions [m] ECEF, velocities [m/s], clock [s], drift [s/s]).
        skips : EphemerisSkips
            The others and why; every satellite of a system without records
            has the reason :data:`NO_SYSTEM_DATA`.
        """
        eph = self.systems.get(system)
        if eph is None:
            if system not in SYSTEM_NAMES:
                raise ArgumentError(f"unknown satellite system {system!r} (known: {', '.join(SYSTEM_NAMES)})",
                                    "system")
            prns = np.atleast_1d(np.asarray([] if prn is None else prn, dtype=int))
            z = np.zeros(0)
            return (SatelliteStates(np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3)), z, z),
                    EphemerisSkips(prns, (NO_SYSTEM_DATA,) * len(prns)))
        return eph.states_and_skips(week, tow, prn, apply_tgd=apply_group_delay)

    def states_of(self, sat_ids, week, tow, apply_group_delay: bool = True):
        """States of satellites named like ``"G05"``, ``"R12"``, ``"E11"``, ``"C08"``.

        Parameters
        ----------
        sat_ids : sequence of str (n,)
        week, tow : GPS time, scalars or (n,) arrays.

        Returns
        -------
        states : SatelliteStates
            The satellites with a usable record, in the order asked.
        systems : ndarray of str (k,)
            Their system letters.
        keep : ndarray of bool (n,)
            Which of the asked satellites they are.
        skips : dict of str -> EphemerisSkips
            Per system, the satellites left out and why.
        """
        ids = [str(s).strip() for s in sat_ids]
        letters = np.array([s[:1] for s in ids])
        try:
            prns = np.array([int(s[1:]) for s in ids], dtype=int)
        except ValueError as exc:
            raise ArgumentError(f"satellite ids must look like 'G05' ({exc})", "sat_ids") from exc
        pos, vel, clk, drift, reason = self.states_by_system(letters, prns, week, tow, apply_group_delay)
        keep = reason == ""
        skips = {letter: EphemerisSkips(prns[(letters == letter) & ~keep],
                                        tuple(reason[(letters == letter) & ~keep].tolist()))
                 for letter in dict.fromkeys(letters.tolist())}
        st = SatelliteStates(prns[keep], pos[keep], vel[keep], clk[keep], drift[keep])
        return st, letters[keep], keep, skips

    def states_by_system(self, letters, prns, week, tow, apply_group_delay: bool = True, chunk: int = 8192):
        """:meth:`states_of` for arrays of system letters and PRNs (n,), any number of rows
        (e.g. every observation of a file at once, each at its own time).

        The record choice is made ``chunk`` rows at a time (its table is rows x records).

        Returns
        -------
        pos, vel : ndarray (n, 3)
        clk, drift : ndarray (n,)
            NaN where no record was used.
        reason : ndarray of str (n,)
            ``""`` where a record was used, else why not (the reasons of
            :meth:`states_and_skips`).
        """
        letters = np.asarray(letters).astype(str)
        prns = np.asarray(prns, dtype=int)
        n = len(letters)
        tow_n = np.broadcast_to(np.asarray(tow, float), (n,))
        week_n = np.broadcast_to(np.asarray(week), (n,))
        pos, vel = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        clk, drift = np.full(n, np.nan), np.full(n, np.nan)
        reason = np.full(n, "", dtype=object)
        for letter in dict.fromkeys(letters.tolist()):
            rows = np.flatnonzero(letters == letter)
            eph = self.systems.get(letter)
            if eph is None:
                self.states_and_skips(letter, prns[rows[:1]], None, None)   # an unknown letter raises
                reason[rows] = NO_SYSTEM_DATA
                continue
            idx = np.empty(len(rows), int)
            t = np.empty(len(rows))
            for c0 in range(0, len(rows), chunk):
                part = rows[c0:c0 + chunk]
                i, tt, sk = eph._select(week_n[part], tow_n[part], prns[part])
                idx[c0:c0 + chunk], t[c0:c0 + chunk] = i, tt
                reason[part[i < 0]] = sk.reason
            ok = idx >= 0
            p, v, c, d = eph._compute(idx[ok], t[ok], apply_group_delay)
            rows = rows[ok]
            pos[rows], vel[rows], clk[rows], drift[rows] = p, v, c, d
        return pos, vel, clk, drift, reason.astype(str)

    def ephemeris_variances(self, letters, prns, week, tow) -> np.ndarray:
        """Orbit + clock variance [m^2] (n,) of the record each observation uses
        (:func:`ephemeris_variance` of its accuracy field; NaN where no record is used),
        the record chosen as :meth:`states_by_system` chooses it."""
        letters = np.asarray(letters).astype(str)
        prns = np.asarray(prns, dtype=int)
        n = len(letters)
        tow_n = np.broadcast_to(np.asarray(tow, float), (n,))
        week_n = np.broadcast_to(np.asarray(week), (n,))
        out = np.full(n, np.nan)
        for letter in dict.fromkeys(letters.tolist()):
            eph = self.systems.get(letter)
            if eph is None:
                continue
            rows = np.flatnonzero(letters == letter)
            for c0 in range(0, len(rows), 8192):
                part = rows[c0:c0 + 8192]
                idx = eph._select(week_n[part], tow_n[part], prns[part])[0]
                ok = idx >= 0
                acc = eph.rec["ura"][idx[ok]] if "ura" in eph.rec else np.full(int(ok.sum()), np.nan)
                out[part[ok]] = ephemeris_variance(letter, acc)
        return out

    def skip_counts(self, skips: dict) -> dict[str, dict[str, int]]:
        """Per system name, the satellites left out per reason (from :meth:`states_of`'s ``skips``)."""
        return {SYSTEM_NAMES.get(k, k): v.counts() for k, v in skips.items() if len(v)}

    def glonass_channel(self, prn) -> np.ndarray:
        """GLONASS frequency channel numbers k of the given satellites.

        Raises
        ------
        DataError
            Naming the satellites (``R12``) no navigation record gives a
            channel number for, and the files read.
        """
        prns = np.atleast_1d(np.asarray(prn, int))
        table = self["R"].channels() if "R" in self.systems else {}
        missing = [f"R{p:02d}" for p in prns if int(p) not in table]
        if missing:
            raise DataError(f"no GLONASS frequency channel number for {', '.join(missing)} "
                            "in the navigation data", file=", ".join(self.sources) or None)
        return np.array([table[int(p)] for p in prns], int)

    def summary(self) -> dict[str, int]:
        """Records per system name (0 for a system no file gave records for)."""
        return {name: (len(self.systems[k]) if k in self.systems else 0) for k, name in SYSTEM_NAMES.items()}


def read_rinex_nav(path) -> tuple[dict, dict]:
    """Parse a RINEX 2 or 3 navigation file into raw per-system arrays.

    Written for mixnav (fixed-format columns of RINEX 2.11 / 3.05, tables
    A3-A17 of the 3.05 document) instead of georinex, whose 1.16 reader turns
    every BeiDou record with a blank spare field (as HKSC's files have) into
    NaN. Blank fields read as NaN; ``D`` exponents are accepted.

    Returns
    -------
    header : dict
        ``version``, ``type``, ``system`` (letter; ``M`` mixed), ``leap``
        (int or None), ``iono`` (letter -> ndarray (8,) Klobuchar alpha, beta).
    records : dict of str -> dict
        Per system letter: ``prn`` (int (m,)), ``epoch`` (datetime64[ns] (m,),
        in the system's time as written), ``values`` (m, k) in the order of
        the broadcast orbit lines, ``line`` (int (m,), first line of each
        record).

    Raises
    ------
    DataError
        Naming the file and line of an unreadable record or header.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError("RINEX navigation file not found", file=str(path))
    try:
        text = path.read_bytes().decode("ascii", "replace")
    except OSError as exc:
        raise DataError(f"cannot read: {exc}", file=str(path)) from exc
    lines = text.splitlines()
    head = _parse_header(lines, str(path))
    v3 = head["version"] >= 3
    starts = []
    for num in range(head["end"], len(lines)):
        ln = lines[num]
        if not ln.strip():
            continue
        # RINEX 2 Galileo / QZSS files (RTKLIB's 'E', 'L', 'J') write RINEX 3 style records
        if ln[:1].isalpha() or (not v3 and ln[:2].strip().isdigit()):
            starts.append(num)
    starts.append(len(lines))
    per: dict[str, dict[str, list]] = {}
    for a, b in zip(starts[:-1], starts[1:]):
        ln = lines[a]
        v3rec = ln[:1].isalpha()
        try:
            if v3rec:
                letter, prn = ln[0].upper(), int(ln[1:3])
                y, mo, d, h, mi = (int(ln[k:k + w]) for k, w in ((4, 4), (9, 2), (12, 2), (15, 2), (18, 2)))
                sec = float(ln[21:23])
                first = 23
            else:
                letter, prn = head["system"], int(ln[0:2])
                y, mo, d, h, mi = (int(ln[k:k + 2]) for k in (3, 6, 9, 12, 15))
                y += 2000 if y < 80 else 1900
                sec = float(ln[17:22])
                first = 22
            cont = 4 if v3rec else 3
            vals = [_field(ln[first + 19 * k:first + 19 * (k + 1)]) for k in range(3)]
            for c in range(a + 1, b):
                lc = lines[c]
                vals.extend(_field(lc[cont + 19 * k:cont + 19 * (k + 1)]) for k in range(4))
            epoch = (np.datetime64(f"{y:04d}-{mo:02d}-{d:02d}T{h:02d}:{mi:02d}", "ns")
                     + np.timedelta64(int(round(sec * 1e9)), "ns"))
        except ValueError as exc:
            raise DataError(f"unreadable navigation record {ln[:3].strip()!r} ({exc})", file=str(path),
                            line=a + 1) from None
        rec = per.setdefault(letter, {"prn": [], "epoch": [], "values": [], "line": []})
        rec["prn"].append(prn)
        rec["epoch"].append(epoch)
        rec["values"].append(vals)
        rec["line"].append(a + 1)
    records = {}
    for letter, rec in per.items():
        width = max(len(v) for v in rec["values"])
        values = np.full((len(rec["values"]), width), np.nan)
        for i, v in enumerate(rec["values"]):
            values[i, :len(v)] = v
        records[letter] = {"prn": np.array(rec["prn"], int), "epoch": np.array(rec["epoch"]),
                           "values": values, "line": np.array(rec["line"], int), "source": str(path)}
    return head, records


def _field(s: str) -> float:
    s = s.strip()
    return float(s.replace("D", "E").replace("d", "e")) if s else np.nan


def _parse_header(lines: list, source: str) -> dict:
    """Version, file type, system letter, LEAP SECONDS and Klobuchar coefficients of a navigation header."""
    if not lines or "RINEX VERSION / TYPE" not in lines[0]:
        raise DataError("not a RINEX file: the first line is not a 'RINEX VERSION / TYPE' header "
                        f"(it reads {lines[0][:60]!r})" if lines else "empty file", file=source, line=1)
    first = lines[0]
    try:
        version = float(first[:9])
    except ValueError:
        raise DataError(f"unreadable RINEX version {first[:9]!r}", file=source, line=1) from None
    ftype = first[20:21].upper()
    if version >= 4:
        raise DataError(f"RINEX {version} navigation files are not supported (RINEX 2 and 3 are)",
                        file=source, line=1)
    if version >= 3:
        if ftype != "N":
            raise DataError(f"not a navigation file: RINEX file type {first[20:40].strip()!r} "
                            "(expected 'N')", file=source, line=1)
        system = first[40:41].upper().strip() or "G"
    else:
        system = {"N": "G", "G": "R", "E": "E", "L": "E", "J": "J"}.get(ftype)
        if system is None:
            raise DataError(f"unsupported RINEX 2 navigation file type {first[20:40].strip()!r} "
                            "(N: GPS, G: GLONASS, E or L: Galileo, J: QZSS)", file=source, line=1)
    leap, end, klob = None, None, {}
    for num, ln in enumerate(lines, start=1):
        label = ln[60:].strip()
        try:
            if label == "END OF HEADER":
                end = num
                break
            if label == "LEAP SECONDS":
                leap = int(ln[:6])
            elif label == "IONOSPHERIC CORR" and ln[:4] in ("GPSA", "GPSB", "QZSA", "QZSB", "BDSA", "BDSB"):
                klob[ln[:4]] = [_field(ln[5 + 12 * k:5 + 12 * (k + 1)]) for k in range(4)]
            elif label in ("ION ALPHA", "ION BETA"):
                klob["GPSA" if label == "ION ALPHA" else "GPSB"] = [_field(ln[2 + 12 * k:2 + 12 * (k + 1)])
                                                                   for k in range(4)]
        except ValueError:
            raise DataError(f"unreadable header line {label!r}", file=source, line=num) from None
    if end is None:
        raise DataError("no END OF HEADER line", file=source)
    iono = {}
    for letter, key in (("G", "GPS"), ("J", "QZS"), ("C", "BDS")):
        if key + "A" in klob and key + "B" in klob:
            c = np.array(klob[key + "A"] + klob[key + "B"], float)
            if np.all(np.isfinite(c)):
                iono[letter] = c
    return {"version": version, "type": ftype, "system": system, "leap": leap, "end": end, "iono": iono}


# flat value index of each parameter (RINEX broadcast orbit lines, 4 values a line after the 3 of the first)
_KEPLER_INDEX = {"af0": 0, "af1": 1, "af2": 2, "crs": 4, "delta_n": 5, "m0": 6, "cuc": 7, "e": 8,
                 "cus": 9, "sqrt_a": 10, "toe": 11, "cic": 12, "omega0": 13, "cis": 14, "i0": 15,
                 "crc": 16, "omega": 17, "omega_dot": 18, "idot": 19, "week": 21, "health": 24}
_URA_INDEX = 23
_KEPLER_EXTRA = {"G": {"tgd": 25}, "J": {"tgd": 25}, "C": {"tgd": 25},
                 "E": {"data_source": 20, "bgd_e5a": 25, "bgd_e5b": 26}}
_GLONASS_INDEX = {"minus_tau_n": 0, "gamma_n": 1, "x": 3, "vx": 4, "ax": 5, "health": 6,
                  "y": 7, "vy": 8, "ay": 9, "z": 11, "vz": 12, "az": 13}
_GLONASS_CHANNEL = 10


def _take(raw: dict, index: dict, letter: str) -> dict:
    """The named parameters of every record; a record lacking one is a DataError naming it."""
    vals = raw["values"]
    cols = np.array(list(index.values()))
    if vals.shape[1] <= cols.max():
        got = np.full((len(vals), cols.max() + 1), np.nan)
        got[:, :vals.shape[1]] = vals
        vals = got
    sub = vals[:, cols]
    bad = ~np.isfinite(sub)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise DataError(f"incomplete ephemeris record for {letter}{raw['prn'][i]:02d} at "
                        f"{str(raw['epoch'][i])[:19]}: {list(index)[j]} missing "
                        f"({int(bad.any(axis=1).sum())} such records; is the file truncated?)",
                        file=raw["source"], line=int(raw["line"][i]))
    out = {k: sub[:, n] for n, k in enumerate(index)}
    out["prn"] = raw["prn"]
    return out


def _check(raw: dict, letter: str, ok: np.ndarray, what: str) -> None:
    """A record whose values cannot be an orbit (a damaged file) is a DataError naming it."""
    if not ok.all():
        i = int(np.argmin(ok))
        raise DataError(f"impossible ephemeris record for {letter}{raw['prn'][i]:02d} at "
                        f"{str(raw['epoch'][i])[:19]}: {what}", file=raw["source"], line=int(raw["line"][i]))


def _kepler_records(raw: dict, letter: str, galileo_nav: str):
    """Records of one Keplerian system, times in its own scale; (None, 0) if none."""
    rec = _take(raw, {**_KEPLER_INDEX, **_KEPLER_EXTRA[letter]}, letter)
    vals = raw["values"]
    # SV accuracy (GPS, QZSS, BeiDou URA) or SISA (Galileo) [m]; a blank field reads NaN
    rec["ura"] = vals[:, _URA_INDEX] if vals.shape[1] > _URA_INDEX else np.full(len(vals), np.nan)
    _check(raw, letter, (rec["e"] >= 0) & (rec["e"] < 1) & (rec["sqrt_a"] > 0),
           "eccentricity outside [0, 1) or sqrt(A) <= 0")
    origin = _BDT_EPOCH if letter == "C" else _GPS_EPOCH
    toc_s = (raw["epoch"] - origin) / np.timedelta64(1, "s")
    rec["toc_week"] = np.floor(toc_s / SECONDS_PER_WEEK)
    rec["toc"] = toc_s - rec["toc_week"] * SECONDS_PER_WEEK
    n_other = 0
    if letter == "E":
        src = rec["data_source"].astype(np.int64)
        if galileo_nav == "inav":
            keep = ((src & _INAV_BITS) != 0) & ((src & _CLOCK_E5B) != 0)
            rec["tgd"] = rec["bgd_e5b"]
        else:
            keep = ((src & _FNAV_BITS) != 0) & ((src & _CLOCK_E5A) != 0)
            rec["tgd"] = rec["bgd_e5a"]
        rec["health_word"] = rec["health"]
        rec["health"] = (rec["health_word"].astype(np.int64) & _E1B_HEALTH_BITS).astype(float)
        n_other = int((~keep).sum())
        rec = {k: v[keep] for k, v in rec.items()}
        if not keep.any():
            return None, n_other
    return rec, n_other


def _glonass_records(raw: dict, leap):
    """GLONASS records with t_b in GPST (GPS week and seconds of week)."""
    rec = _take(raw, _GLONASS_INDEX, "R")
    radius = 1000.0 * np.sqrt(rec["x"] ** 2 + rec["y"] ** 2 + rec["z"] ** 2)
    _check(raw, "R", (radius > 1e7) & (radius < 1e8), "position not 10 000 - 100 000 km from the geocentre")
    vals = raw["values"]
    channel = vals[:, _GLONASS_CHANNEL] if vals.shape[1] > _GLONASS_CHANNEL else np.full(len(vals), np.nan)
    km = 1000.0                                   # RINEX gives km, km/s, km/s^2
    epoch_utc = (raw["epoch"] - _GPS_EPOCH) / np.timedelta64(1, "s")
    lp = gnss_time.leap_seconds(epoch_utc) if leap is None else leap
    tb = gnss_time.utc_to_gpst(epoch_utc, lp)
    week, tow = gnss_time.gpst_week_tow(tb)
    return {"prn": rec["prn"], "week": week.astype(float), "toe": tow,
            "pos": km * np.stack([rec["x"], rec["y"], rec["z"]], -1),
            "vel": km * np.stack([rec["vx"], rec["vy"], rec["vz"]], -1),
            "acc": km * np.stack([rec["ax"], rec["ay"], rec["az"]], -1),
            "minus_tau_n": rec["minus_tau_n"], "gamma_n": rec["gamma_n"],
            "health": rec["health"], "channel": channel}


def _table_leap(systems: dict) -> float:
    """Leap seconds from the table at the first GLONASS record (18 when there is none)."""
    eph = systems.get("R")
    if eph is None:
        return float(gnss_time.leap_seconds(np.array([1.3e9]))[0])
    t = eph.rec["week"][0] * SECONDS_PER_WEEK + eph.rec["toe"][0]
    return float(gnss_time.leap_seconds(t)[()])
