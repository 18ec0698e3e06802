"""GNSS time scales and their conversions to GPS time.

mixnav keeps every time as GPS time (GPST); a satellite system's own time is
only used inside its orbit and clock formulas. Times here are continuous
seconds since the GPS epoch, 1980-01-06 00:00:00 GPST (``week * 604800 +
tow``), or ``(week, tow)`` pairs.

- GST (Galileo) and QZSST (QZSS) are steered to GPST; RINEX writes their
  weeks in GPS numbering. The offsets (a few ns, broadcast as GGTO) are left
  to the receiver's inter-system clock terms.
- BDT (BeiDou, BDS-SIS-ICD-B1I 5.1 / 5.2.4.x): started 2006-01-01 00:00:00
  UTC, 14 s behind GPST, no leap seconds since: ``BDT = GPST - 14 s``,
  ``BDT week = GPS week - 1356``.
- GLONASST (GLONASS ICD 5.1, 3.3.3): ``GLONASST = UTC(SU) + 3 h``; it follows
  UTC's leap seconds, so ``GPST = GLONASST - 3 h + leap seconds`` with
  ``leap seconds = GPST - UTC`` (18 s since 2017-01-01). RINEX writes GLONASS
  navigation epochs in UTC.

The leap second count comes from a file header when one gives it
(:func:`leap_seconds` otherwise, from the table below, valid until the next
leap second is announced; none has been since 2017).
"""

from __future__ import annotations

import numpy as np

from .geometry import SECONDS_PER_WEEK

#: BDT is behind GPST by this many seconds [s].
BDT_OFFSET_S = 14.0
#: GPS week of BDT week 0.
BDT_WEEK_OFFSET = 1356
#: GLONASST - UTC(SU) [s].
GLONASST_UTC_OFFSET_S = 3 * 3600.0

_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "s")

#: UTC date from which GPST - UTC is the given count (IERS Bulletin C).
LEAP_SECOND_TABLE = (
    ("1981-07-01", 1), ("1982-07-01", 2), ("1983-07-01", 3), ("1985-07-01", 4),
    ("1988-01-01", 5), ("1990-01-01", 6), ("1991-01-01", 7), ("1992-07-01", 8),
    ("1993-07-01", 9), ("1994-07-01", 10), ("1996-01-01", 11), ("1997-07-01", 12),
    ("1999-01-01", 13), ("2006-01-01", 14), ("2009-01-01", 15), ("2012-07-01", 16),
    ("2015-07-01", 17), ("2017-01-01", 18),
)


def leap_seconds(t_utc) -> np.ndarray:
    """GPST - UTC [s] at UTC seconds since the GPS epoch, from :data:`LEAP_SECOND_TABLE`.

    Parameters
    ----------
    t_utc : float or ndarray (n,)
        UTC counted in seconds from 1980-01-06 00:00:00 UTC.

    Returns
    -------
    ndarray of float, the shape of ``t_utc``.
    """
    starts = np.array([(np.datetime64(d, "s") - _GPS_EPOCH) / np.timedelta64(1, "s")
                       for d, _ in LEAP_SECOND_TABLE])
    counts = np.array([0.0] + [float(n) for _, n in LEAP_SECOND_TABLE])
    return counts[np.searchsorted(starts, np.asarray(t_utc, float), side="right")]


def gpst_seconds(week, tow) -> np.ndarray:
    """Continuous GPS seconds [s] from GPS week and seconds of week."""
    return np.asarray(week, float) * SECONDS_PER_WEEK + np.asarray(tow, float)


def gpst_week_tow(t_gps) -> tuple[np.ndarray, np.ndarray]:
    """(GPS week (int), seconds of week [s]) of continuous GPS seconds."""
    t = np.asarray(t_gps, float)
    week = np.floor(t / SECONDS_PER_WEEK)
    return week.astype(int), t - week * SECONDS_PER_WEEK


def gpst_to_bdt(t_gps) -> np.ndarray:
    """BDT [s, continuous from the BDT epoch 2006-01-01] of continuous GPS seconds."""
    return np.asarray(t_gps, float) - BDT_WEEK_OFFSET * SECONDS_PER_WEEK - BDT_OFFSET_S


def bdt_to_gpst(t_bdt) -> np.ndarray:
    """Continuous GPS seconds of BDT [s, continuous from the BDT epoch]."""
    return np.asarray(t_bdt, float) + BDT_WEEK_OFFSET * SECONDS_PER_WEEK + BDT_OFFSET_S


def gps_week_tow_to_bdt(week, tow) -> tuple[np.ndarray, np.ndarray]:
    """(BDT week, BDT seconds of week) of a GPS (week, tow)."""
    tow_b = np.asarray(tow, float) - BDT_OFFSET_S
    week_b = np.asarray(week, int) - BDT_WEEK_OFFSET
    wrap = tow_b < 0.0                       # the first 14 s of a GPS week are in the previous BDT week
    return week_b - wrap, tow_b + wrap * SECONDS_PER_WEEK


def utc_to_gpst(t_utc, leap) -> np.ndarray:
    """GPS seconds of UTC seconds (same origin) given ``leap = GPST - UTC`` [s]."""
    return np.asarray(t_utc, float) + leap


def gpst_to_utc(t_gps, leap) -> np.ndarray:
    """UTC seconds (counted from the GPS epoch) of GPS seconds given ``leap = GPST - UTC`` [s]."""
    return np.asarray(t_gps, float) - leap


def glonasst_to_gpst(t_glo, leap) -> np.ndarray:
    """GPS seconds of GLONASS time [s, counted like GPS seconds]: ``GLONASST - 3 h + leap``."""
    return np.asarray(t_glo, float) - GLONASST_UTC_OFFSET_S + leap


def gpst_to_glonasst(t_gps, leap) -> np.ndarray:
    """GLONASS time [s] of GPS seconds: ``GPST + 3 h - leap``."""
    return np.asarray(t_gps, float) + GLONASST_UTC_OFFSET_S - leap
