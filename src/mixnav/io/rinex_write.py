"""RINEX 3.04 writers: a GPS observation file (C1C, optionally L1C with its loss-of-lock
indicator and D1C) and a GPS navigation file.

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
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from .atomic import atomic_write_text

#: GPS time origin (1980-01-06 00:00:00)
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
_WEEK = 604800.0


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
    if (iono_alpha is None) != (iono_beta is None):
        raise ArgumentError("give both Klobuchar coefficient sets or neither", argument="iono_alpha")
    r = {k: np.atleast_1d(np.asarray(v)) for k, v in records.items()}
    n = len(r["prn"])
    toc = np.asarray(r["toc"], float)
    if np.any(np.abs(toc - np.round(toc)) > 1e-9):
        raise ArgumentError("toc must be whole seconds (RINEX gives the clock epoch to the second)",
                            argument="records")
    if np.any((r["prn"] < 1) | (r["prn"] > 32)):
        raise ArgumentError("GPS PRNs are 1..32", argument="records")
    lines = [_label(f"{3.04:9.2f}{'':11}{'N: GNSS NAV DATA':<20}{'G: GPS':<20}", "RINEX VERSION / TYPE"),
             _header_run(program)]
    if iono_alpha is not None:
        for tag, coef in (("GPSA", iono_alpha), ("GPSB", iono_beta)):
            c = np.asarray(coef, float).reshape(4)
            lines.append(_label(f"{tag:<4} " + "".join(f"{x:12.4E}" for x in c), "IONOSPHERIC CORR"))
    lines.append(_label("", "END OF HEADER"))
    times = _calendar(r["toc_week"], np.round(toc))
    order = np.lexsort((r["prn"], times))
    pad = " " * 4
    for k in order:
        y, mo, d, hh, mm, ss = _fields(times[k])
        g = lambda name: float(r[name][k])  # noqa: E731
        iode = float(int(round(g("toe"))) // 16 % 256)   # a plausible issue-of-data, the same per record
        lines.append(f"G{int(r['prn'][k]):02d} {y:04d} {mo:02d} {d:02d} {hh:02d} {mm:02d} {int(round(ss)):02d}"
                     + _d19(g("af0")) + _d19(g("af1")) + _d19(g("af2")))
        for row in ((iode, g("crs"), g("delta_n"), g("m0")),
                    (g("cuc"), g("e"), g("cus"), g("sqrt_a")),
                    (g("toe"), g("cic"), g("omega0"), g("cis")),
                    (g("i0"), g("crc"), g("omega"), g("omega_dot")),
                    (g("idot"), 1.0, g("week"), 0.0),
                    (2.0, g("health"), g("tgd"), iode),
                    (g("toe") - 7200.0 if g("toe") >= 7200.0 else 0.0, 4.0)):
            lines.append(pad + "".join(_d19(x) for x in row))
    if n == 0:
        raise ArgumentError("no record to write", argument="records")
    atomic_write_text(path, "\n".join(lines) + "\n")


def write_rinex_obs(path, week, tow, epoch, prn, pseudorange, doppler=None, approx_position=(0.0, 0.0, 0.0),
                    marker: str = "MIXNAV", program: str = "mixnav", interval: float | None = None,
                    carrier=None, lli=None) -> None:
    """Write GPS L1 C/A pseudoranges (``C1C``) and, when given, carrier phases (``L1C``) and
    Doppler (``D1C``) as a RINEX 3.04 observation file, epoch times in GPS time.

    Parameters
    ----------
    path : str or PathLike
    week : ndarray of int (k,); tow : ndarray (k,)
        Epoch times: GPS week and seconds of week [s], strictly increasing.
    epoch : ndarray of int (m,)
        Epoch index (0..k-1) of each observation.
    prn : ndarray of int (m,)
        GPS satellite (1..32).
    pseudorange : ndarray (m,)
        [m] (written to the millimetre; NaN: blank).
    doppler : ndarray (m,) or None
        [Hz] (written to the mHz; NaN: blank); None: no ``D1C`` column.
    carrier : ndarray (m,) or None
        L1 carrier phase [cycles] (written to the milli-cycle; NaN: blank); None: no ``L1C``.
    lli : ndarray of int (m,) or None
        The carrier's loss-of-lock indicator (0-7: bit 0 lost lock, bit 1 half-cycle
        ambiguity; 0 written blank); needs ``carrier``.
    approx_position : (3,)
        ECEF [m] for the ``APPROX POSITION XYZ`` line.
    marker : str
    interval : float or None
        [s], the ``INTERVAL`` line (omitted when None).
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
    if np.any((prn < 1) | (prn > 32)):
        raise ArgumentError("GPS PRNs are 1..32", argument="prn")
    times = _calendar(week, tow)
    if k > 1 and np.any(np.diff(times) <= np.timedelta64(0, "ns")):
        raise ArgumentError("epoch times must increase strictly", argument="tow")
    for name, a, lim in (("pseudorange", rho, 1e10), ("doppler", dop, 1e10), ("carrier", cp, 1e10)):
        if a is not None and np.any(np.isfinite(a) & (np.abs(a) >= lim)):
            raise ArgumentError(f"a {name} does not fit the F14.3 field", argument=name)
    types = ["C1C"] + (["L1C"] if cp is not None else []) + (["D1C"] if dop is not None else [])
    x, y, z = (float(v) for v in approx_position)
    lines = [_label(f"{3.04:9.2f}{'':11}{'OBSERVATION DATA':<20}{'G: GPS':<20}", "RINEX VERSION / TYPE"),
             _header_run(program),
             _label(marker[:60], "MARKER NAME"),
             _label(f"{'simulated':<20}{'mixnav':<40}", "OBSERVER / AGENCY"),
             _label(f"{'0':<20}{'SIMULATED':<20}{'mixnav':<20}", "REC # / TYPE / VERS"),
             _label(f"{'0':<20}{'SIMULATED':<20}", "ANT # / TYPE"),
             _label(f"{x:14.4f}{y:14.4f}{z:14.4f}", "APPROX POSITION XYZ"),
             _label(f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}", "ANTENNA: DELTA H/E/N"),
             _label(f"G{len(types):5d}" + "".join(f" {t}" for t in types), "SYS / # / OBS TYPES")]
    if interval is not None:
        lines.append(_label(f"{interval:10.3f}", "INTERVAL"))
    if k:
        y0, mo, d, hh, mm, ss = _fields(times[0])
        lines.append(_label(f"{y0:6d}{mo:6d}{d:6d}{hh:6d}{mm:6d}{ss:13.7f}     GPS", "TIME OF FIRST OBS"))
    lines.append(_label("", "END OF HEADER"))
    order = np.lexsort((prn, epoch))
    bounds = np.searchsorted(epoch[order], np.arange(k + 1))

    def value(v):
        return " " * 16 if not np.isfinite(v) else f"{v:14.3f}  "

    for j in range(k):
        rows = order[bounds[j]:bounds[j + 1]]
        y0, mo, d, hh, mm, ss = _fields(times[j])
        lines.append(f"> {y0:04d} {mo:02d} {d:02d} {hh:02d} {mm:02d}{ss:11.7f}  0{len(rows):3d}")
        for i in rows:
            s = f"G{int(prn[i]):02d}" + value(rho[i])
            if cp is not None:
                s += value(cp[i]) if flag is None or not flag[i] or not np.isfinite(cp[i]) else \
                    f"{cp[i]:14.3f}{int(flag[i]):1d} "
            if dop is not None:
                s += value(dop[i])
            lines.append(s.rstrip())
    atomic_write_text(path, "\n".join(lines) + "\n")
