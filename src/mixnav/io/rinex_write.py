"""RINEX 3.04 writers: observation files (first-frequency code, optionally the carrier phase
with its loss-of-lock indicator, and Doppler) and navigation files, GPS alone or mixed (GPS,
Galileo, BeiDou, QZSS Keplerian records; GLONASS slots and channels in the observation header).

What a receiver converted by RTKLIB's ``convbin`` would give, written from arrays: the
simulator's export (:mod:`mixnav.experiment.export`) writes its pseudoranges, Doppler and
constellation with these, and the readers (:mod:`mixnav.io.rinex_obs`,
:class:`mixnav.gnss.ephemeris.BroadcastEphemeris`, georinex) read them back.

Formats (RINEX 3.04, IGS/RTCM): observations ``F14.3`` plus two blank flag columns
(pseudorange to the millimetre, carrier to the milli-cycle: 0.2 mm, Doppler to the mHz:
0.2 mm/s; the carrier's loss-of-lock indicator in its first flag column), epoch records
``> yyyy mm dd hh mm ss.sssssss  f nnn`` in GPS time; navigation records in ``D19.12``
(13 significant digits: a circular orbit's position to about 0.1 mm). Files are
written atomically (:mod:`mixnav.io.atomic`). Values that do not fit the format are
refused (:class:`ArgumentError` naming the argument), never written truncated.

Several systems: each system's observation types are its first-frequency civil code and
Doppler, the signals the SPP models (:data:`OBS_CODES`: BeiDou B1I is ``C2I`` from RINEX
3.03 on); a Galileo navigation record says I/NAV with the E1,E5b clock (data sources 517),
a BeiDou record is in BDT (its ``t_oc`` calendar too).
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from .atomic import atomic_write_text

#: GPS time origin (1980-01-06 00:00:00)
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
_WEEK = 604800.0
#: the pseudorange code written per system (its Doppler: ``D`` in place of ``C``)
OBS_CODES = {"G": "C1C", "R": "C1C", "E": "C1C", "C": "C2I", "J": "C1C"}
#: satellite numbers RINEX 3 allows per system
PRN_RANGE = {"G": (1, 32), "R": (1, 27), "E": (1, 36), "C": (1, 63), "J": (1, 10)}
_ORDER = "GRECJ"
_NAMES = {"G": "G: GPS", "R": "R: GLONASS", "E": "E: Galileo", "C": "C: BeiDou", "J": "J: QZSS", "M": "M: Mixed"}


def _label(body: str, label: str) -> str:
    return f"{body:<60.60}{label}"


def _calendar(week, tow) -> np.ndarray:
    """GPS week and seconds of week -> datetime64[ns] (GPS time, no leap seconds)."""
    ns = np.round((np.asarray(week, float) * _WEEK) * 1e9).astype(np.int64) + \
        np.round(np.asarray(tow, float) * 1e9).astype(np.int64)
    return _GPS_EPOCH + ns.astype("timedelta64[ns]")


def _fields(t: np.datetime64):
    """(year, month, day, hour, minute, seconds with fraction) of a datetime64[ns]."""
    s = str(np.datetime64(t, "ns"))          # 'YYYY-MM-DDThh:mm:ss.fffffffff'
    date, clock = s.split("T")
    y, mo, d = (int(x) for x in date.split("-"))
    hh, mm, ss = clock.split(":")
    return y, mo, d, int(hh), int(mm), float(ss)


def _d19(x: float) -> str:
    """``D19.12`` (written with E, which every reader takes)."""
    if not np.isfinite(x):
        raise ArgumentError(f"a navigation value is not finite ({x})", argument="records")
    return f"{x:19.12E}"


def _header_run(program: str) -> str:
    return _label(f"{program[:20]:<20}{'mixnav':<20}{'20000101 000000 GPS':<20}", "PGM / RUN BY / DATE")


def write_rinex_nav(path, records: dict, iono_alpha=None, iono_beta=None, program: str = "mixnav") -> None:
    """Write GPS broadcast ephemeris records as a RINEX 3.04 navigation file.

    Parameters
    ----------
    path : str or PathLike
    records : dict of str -> ndarray (r,)
        As :class:`mixnav.gnss.ephemeris.BroadcastEphemeris` holds them (``prn``, ``week``,
        ``toe``, ``toc_week``, ``toc``, ``af0``..``af2``, the Keplerian elements [rad, rad/s,
        m^(1/2)], ``health``, ``tgd`` [s]); e.g.
        :meth:`mixnav.gnss.constellation.NominalConstellation.broadcast_records`.
        ``toc`` must be a whole second (RINEX writes it as a calendar time to the second).
    iono_alpha, iono_beta : ndarray (4,) or None
        Klobuchar coefficients for the ``IONOSPHERIC CORR`` lines (GPSA, GPSB); both or none.
    """
    write_rinex_nav_multi(path, {"G": records}, iono_alpha, iono_beta, program)


def write_rinex_nav_multi(path, records: dict, iono_alpha=None, iono_beta=None, program: str = "mixnav",
                          glonass: dict | None = None, leap_seconds: int | None = None) -> None:
    """Write Keplerian broadcast records of one or more systems as a RINEX 3.04 navigation
    file (mixed when more than one).

    Parameters
    ----------
    records : dict of str -> dict
        System letter (``G``, ``E``, ``C``, ``J``) -> records as :func:`write_rinex_nav`
        takes them, in the system's own time (BeiDou: BDT weeks and seconds; e.g.
        ``broadcast_records(..., time_system="C")``); ``tgd`` is Galileo's BGD E5b/E1 and
        BeiDou's TGD1.
    iono_alpha, iono_beta : ndarray (4,) or None
        GPS Klobuchar coefficients (GPSA, GPSB); both or none.
    glonass : dict of str -> ndarray or None
        GLONASS records (RINEX 3.04 table A10): ``prn`` (r,), ``t_gps`` (r,) the reference
        time t_b in GPS seconds since 1980-01-06 (written as UTC, ``t_gps - leap_seconds``,
        whole seconds), ``pos``, ``vel``, ``acc`` (r, 3) ECEF [m, m/s, m/s^2] (written in
        km), ``minus_tau_n`` [s], ``gamma_n``, ``channel`` (frequency number k).
    leap_seconds : int or None
        GPST - UTC [s] (the ``LEAP SECONDS`` header line); needed with ``glonass``.
    """
    if (iono_alpha is None) != (iono_beta is None):
        raise ArgumentError("give both Klobuchar coefficient sets or neither", argument="iono_alpha")
    if glonass is not None and leap_seconds is None:
        raise ArgumentError("GLONASS records are written in UTC: give leap_seconds", argument="leap_seconds")
    bad = [x for x in records if x not in ("G", "E", "C", "J")]
    if bad or (not records and glonass is None):
        raise ArgumentError(f"Keplerian records of G, E, C or J, got {bad or 'none'} (GLONASS records are state "
                            "vectors)", argument="records")
    letters = [x for x in _ORDER if x in records]
    body = []
    n = 0
    for letter in letters:
        r = {k: np.atleast_1d(np.asarray(v)) for k, v in records[letter].items()}
        n += len(r["prn"])
        toc = np.asarray(r["toc"], float)
        if np.any(np.abs(toc - np.round(toc)) > 1e-9):
            raise ArgumentError("toc must be whole seconds (RINEX gives the clock epoch to the second)",
                                argument="records")
        lo, hi = PRN_RANGE[letter]
        if np.any((r["prn"] < lo) | (r["prn"] > hi)):
            raise ArgumentError(f"{_NAMES[letter][3:]} PRNs are {lo}..{hi}", argument="records")
        # BDT calendar: BDT week w starts at GPS week w + 1356 less 14 s, written as its own calendar
        week_cal = r["toc_week"] + (1356 if letter == "C" else 0)
        times = _calendar(week_cal, np.round(toc))
        body += [(t, letter, int(p), _kepler_lines(letter, r, k, t)) for k, (t, p) in enumerate(zip(times, r["prn"]))]
    if glonass is not None:
        letters.append("R")
        body += _glonass_lines(glonass, int(leap_seconds))
        n += len(glonass["prn"])
    if n == 0:
        raise ArgumentError("no record to write", argument="records")
    sys_label = _NAMES[letters[0]] if len(letters) == 1 else _NAMES["M"]
    lines = [_label(f"{3.04:9.2f}{'':11}{'N: GNSS NAV DATA':<20}{sys_label:<20}", "RINEX VERSION / TYPE"),
             _header_run(program)]
    if leap_seconds is not None:
        lines.append(_label(f"{int(leap_seconds):6d}", "LEAP SECONDS"))
    if iono_alpha is not None:
        for tag, coef in (("GPSA", iono_alpha), ("GPSB", iono_beta)):
            c = np.asarray(coef, float).reshape(4)
            lines.append(_label(f"{tag:<4} " + "".join(f"{x:12.4E}" for x in c), "IONOSPHERIC CORR"))
    lines.append(_label("", "END OF HEADER"))
    if len(letters) == 1:      # one system: by time, then PRN (the order the GPS writer always had)
        body.sort(key=lambda b: (b[0], b[2]))
    else:
        body.sort(key=lambda b: (_ORDER.index(b[1]), b[0], b[2]))
    for b in body:
        lines += b[3]
    atomic_write_text(path, "\n".join(lines) + "\n")


def _glonass_lines(g: dict, leap: int) -> list:
    """``(time, "R", slot, lines)`` of each GLONASS record (RINEX 3.04 table A10: epoch in UTC,
    -tau_n, +gamma_n, message frame time; X, Xdot, Xacc, health; Y..., channel; Z..., age)."""
    prn = np.asarray(g["prn"], np.int64)
    lo, hi = PRN_RANGE["R"]
    if np.any((prn < lo) | (prn > hi)):
        raise ArgumentError(f"GLONASS slots are {lo}..{hi}", argument="glonass")
    t_utc = np.asarray(g["t_gps"], float) - leap
    if np.any(np.abs(t_utc - np.round(t_utc)) > 1e-9):
        raise ArgumentError("GLONASS t_b must be whole seconds", argument="glonass")
    times = _calendar(np.zeros(len(prn)), np.round(t_utc))
    km = 1e-3
    out = []
    for k, t in enumerate(times):
        y, mo, d, hh, mm, ss = _fields(t)
        head = (f"R{int(prn[k]):02d} {y:04d} {mo:02d} {d:02d} {hh:02d} {mm:02d} {int(round(ss)):02d}"
                + _d19(float(g["minus_tau_n"][k])) + _d19(float(g["gamma_n"][k]))
                + _d19(float(np.round(t_utc[k]) % 86400.0)))
        rows = [(km * g["pos"][k][a], km * g["vel"][k][a], km * g["acc"][k][a], extra)
                for a, extra in enumerate((0.0, float(g["channel"][k]), 0.0))]
        out.append((t, "R", int(prn[k]), [head] + ["    " + "".join(_d19(float(x)) for x in row) for row in rows]))
    return out


def _kepler_lines(letter: str, r: dict, k: int, t_cal) -> list:
    """The 8 lines of record ``k`` of ``r`` (RINEX 3.04 tables A6 GPS, A8 Galileo, A14 BeiDou)."""
    y, mo, d, hh, mm, ss = _fields(t_cal)
    g = lambda name: float(r[name][k])  # noqa: E731
    iode = float(int(round(g("toe"))) // 16 % 256)   # a plausible issue-of-data, the same per record
    out = [f"{letter}{int(r['prn'][k]):02d} {y:04d} {mo:02d} {d:02d} {hh:02d} {mm:02d} {int(round(ss)):02d}"
           + _d19(g("af0")) + _d19(g("af1")) + _d19(g("af2"))]
    t_tx = g("toe") - 7200.0 if g("toe") >= 7200.0 else 0.0
    rows = [(iode, g("crs"), g("delta_n"), g("m0")),
            (g("cuc"), g("e"), g("cus"), g("sqrt_a")),
            (g("toe"), g("cic"), g("omega0"), g("cis")),
            (g("i0"), g("crc"), g("omega"), g("omega_dot"))]
    if letter == "E":          # data sources: I/NAV E1-B (bit 0), E5b (bit 2), E1,E5b clock (bit 9)
        rows += [(g("idot"), 517.0, g("week"), 0.0), (3.12, g("health"), g("tgd"), g("tgd")), (t_tx, 0.0)]
    elif letter == "C":        # spare, BDT week; accuracy, SatH1, TGD1, TGD2; transmission time, AODC
        rows += [(g("idot"), 0.0, g("week"), 0.0), (2.0, g("health"), g("tgd"), 0.0), (t_tx, iode)]
    else:
        rows += [(g("idot"), 1.0, g("week"), 0.0), (2.0, g("health"), g("tgd"), iode), (t_tx, 4.0)]
    pad = " " * 4
    out += [pad + "".join(_d19(x) for x in row) for row in rows]
    return out


def write_rinex_obs(path, week, tow, epoch, prn, pseudorange, doppler=None, approx_position=(0.0, 0.0, 0.0),
                    marker: str = "MIXNAV", program: str = "mixnav", interval: float | None = None,
                    system=None, glonass_channels=None, carrier=None, lli=None) -> None:
    """Write GPS L1 C/A pseudoranges (``C1C``) and, when given, carrier phases (``L1C``) and
    Doppler (``D1C``) as a RINEX 3.04 observation file, epoch times in GPS time; with
    ``system``, the satellites of several systems, each with its :data:`OBS_CODES` code (and
    the carrier and Doppler of that signal: a mixed file).

    Parameters
    ----------
    path : str or PathLike
    week : ndarray of int (k,); tow : ndarray (k,)
        Epoch times: GPS week and seconds of week [s], strictly increasing.
    epoch : ndarray of int (m,)
        Epoch index (0..k-1) of each observation.
    prn : ndarray of int (m,)
        Satellite number within its system (GPS 1..32; :data:`PRN_RANGE`).
    pseudorange : ndarray (m,)
        [m] (written to the millimetre; NaN: blank).
    doppler : ndarray (m,) or None
        [Hz] (written to the mHz; NaN: blank); None: no ``D1C`` column.
    carrier : ndarray (m,) or None
        Carrier phase of the same signal [cycles] (written to the milli-cycle; NaN: blank);
        None: no ``L1C`` (or the system's ``L`` code).
    lli : ndarray of int (m,) or None
        The carrier's loss-of-lock indicator (0-7: bit 0 lost lock, bit 1 half-cycle
        ambiguity; 0 written blank); needs ``carrier``.
    approx_position : (3,)
        ECEF [m] for the ``APPROX POSITION XYZ`` line.
    marker : str
    interval : float or None
        [s], the ``INTERVAL`` line (omitted when None).
    system : array_like of str (m,) or None
        RINEX system letter of each observation (G, R, E, C, J); None: GPS.
    glonass_channels : dict of int -> int or None
        GLONASS slot -> frequency channel, written as ``GLONASS SLOT / FRQ #`` lines (the
        slots observed; needed when ``system`` has R).
    """
    week = np.atleast_1d(np.asarray(week))
    tow = np.atleast_1d(np.asarray(tow, float))
    epoch = np.asarray(epoch, dtype=np.int64)
    prn = np.asarray(prn, dtype=np.int64)
    rho = np.asarray(pseudorange, float)
    k, m = len(tow), len(rho)
    if week.shape != (k,):
        raise ArgumentError(f"week has shape {week.shape}, expected ({k},)", argument="week")
    for name, a in (("epoch", epoch), ("prn", prn)):
        if a.shape != (m,):
            raise ArgumentError(f"{name} has shape {a.shape}, expected ({m},)", argument=name)
    dop = None if doppler is None else np.asarray(doppler, float)
    if dop is not None and dop.shape != (m,):
        raise ArgumentError(f"doppler has shape {dop.shape}, expected ({m},)", argument="doppler")
    cp = None if carrier is None else np.asarray(carrier, float)
    if cp is not None and cp.shape != (m,):
        raise ArgumentError(f"carrier has shape {cp.shape}, expected ({m},)", argument="carrier")
    flag = None if lli is None else np.asarray(lli)
    if flag is not None:
        if cp is None:
            raise ArgumentError("loss-of-lock indicators belong to a carrier: give carrier too", argument="lli")
        if flag.shape != (m,) or not np.issubdtype(flag.dtype, np.integer) or np.any((flag < 0) | (flag > 7)):
            raise ArgumentError(f"must be ({m},) integers 0..7", argument="lli")
    if m and (epoch.min() < 0 or epoch.max() >= k):
        raise ArgumentError(f"epoch indices must lie in 0..{k - 1}", argument="epoch")
    letters = np.full(m, "G") if system is None else np.asarray(system).astype(str)
    if letters.shape != (m,):
        raise ArgumentError(f"system has shape {letters.shape}, expected ({m},)", argument="system")
    present = [x for x in _ORDER if x in set(letters.tolist())] or ["G"]
    unknown = sorted(set(letters.tolist()) - set(_ORDER))
    if unknown:
        raise ArgumentError(f"unknown system letters {unknown} (known: {', '.join(_ORDER)})", argument="system")
    for x in present:
        lo, hi = PRN_RANGE[x]
        sel = letters == x
        if np.any((prn[sel] < lo) | (prn[sel] > hi)):
            raise ArgumentError(f"{_NAMES[x][3:]} PRNs are {lo}..{hi}", argument="prn")
    glo_slots = sorted(set(prn[letters == "R"].tolist()))
    channels = dict(glonass_channels or {})
    if glo_slots and not set(glo_slots) <= set(channels):
        raise ArgumentError(f"GLONASS slots {sorted(set(glo_slots) - set(channels))} have no frequency channel",
                            argument="glonass_channels")
    times = _calendar(week, tow)
    if k > 1 and np.any(np.diff(times) <= np.timedelta64(0, "ns")):
        raise ArgumentError("epoch times must increase strictly", argument="tow")
    for name, a, lim in (("pseudorange", rho, 1e10), ("doppler", dop, 1e10), ("carrier", cp, 1e10)):
        if a is not None and np.any(np.isfinite(a) & (np.abs(a) >= lim)):
            raise ArgumentError(f"a {name} does not fit the F14.3 field", argument=name)
    x, y, z = (float(v) for v in approx_position)
    sys_label = _NAMES[present[0]] if len(present) == 1 else _NAMES["M"]
    lines = [_label(f"{3.04:9.2f}{'':11}{'OBSERVATION DATA':<20}{sys_label:<20}", "RINEX VERSION / TYPE"),
             _header_run(program),
             _label(marker[:60], "MARKER NAME"),
             _label(f"{'simulated':<20}{'mixnav':<40}", "OBSERVER / AGENCY"),
             _label(f"{'0':<20}{'SIMULATED':<20}{'mixnav':<20}", "REC # / TYPE / VERS"),
             _label(f"{'0':<20}{'SIMULATED':<20}", "ANT # / TYPE"),
             _label(f"{x:14.4f}{y:14.4f}{z:14.4f}", "APPROX POSITION XYZ"),
             _label(f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}", "ANTENNA: DELTA H/E/N")]
    for x_ in present:
        types = ([OBS_CODES[x_]] + (["L" + OBS_CODES[x_][1:]] if cp is not None else [])
                 + (["D" + OBS_CODES[x_][1:]] if dop is not None else []))
        lines.append(_label(f"{x_}{len(types):5d}" + "".join(f" {t}" for t in types), "SYS / # / OBS TYPES"))
    if interval is not None:
        lines.append(_label(f"{interval:10.3f}", "INTERVAL"))
    if k:
        y0, mo, d, hh, mm, ss = _fields(times[0])
        lines.append(_label(f"{y0:6d}{mo:6d}{d:6d}{hh:6d}{mm:6d}{ss:13.7f}     GPS", "TIME OF FIRST OBS"))
    if glo_slots:     # RINEX 3.04 A4: I3, then up to 8 of (A1, I2.2, 1X, I2, 1X) a line
        for a in range(0, len(glo_slots), 8):
            part = "".join(f"R{p:02d} {int(channels[p]):2d} " for p in glo_slots[a:a + 8])
            lines.append(_label((f"{len(glo_slots):3d} " if a == 0 else "    ") + part, "GLONASS SLOT / FRQ #"))
    lines.append(_label("", "END OF HEADER"))
    rank = np.array([_ORDER.index(v) for v in letters], dtype=np.int64) if system is not None \
        else np.zeros(m, np.int64)
    order = np.lexsort((prn, rank, epoch))
    bounds = np.searchsorted(epoch[order], np.arange(k + 1))

    def value(v):
        return " " * 16 if not np.isfinite(v) else f"{v:14.3f}  "

    for j in range(k):
        rows = order[bounds[j]:bounds[j + 1]]
        y0, mo, d, hh, mm, ss = _fields(times[j])
        lines.append(f"> {y0:04d} {mo:02d} {d:02d} {hh:02d} {mm:02d}{ss:11.7f}  0{len(rows):3d}")
        for i in rows:
            s = f"{letters[i]}{int(prn[i]):02d}" + value(rho[i])
            if cp is not None:
                s += value(cp[i]) if flag is None or not flag[i] or not np.isfinite(cp[i]) else \
                    f"{cp[i]:14.3f}{int(flag[i]):1d} "
            if dop is not None:
                s += value(dop[i])
            lines.append(s.rstrip())
    atomic_write_text(path, "\n".join(lines) + "\n")
