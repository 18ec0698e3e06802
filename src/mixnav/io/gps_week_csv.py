"""A reference trajectory as comma-separated GPS week, time of week and WGS-84 position
(``[reference] format = "gps-week-csv"``; docs/data_formats.md).

One line per sample, five comma-separated numbers::

    gps_week,gps_tow_s,lat_deg,lon_deg,height_m
    2304,381600.0,22.30378112,114.17964523,3.2
    2304,381600.2,22.30378131,114.17964510,3.2

- ``gps_week``: GPS week (whole number, counted from 1980-01-06, not modulo 1024);
  ``gps_tow_s``: GPS seconds of that week, ``0 <= tow < 604800``; the time is GPS time
  (no leap seconds), the scale of RINEX observation epochs.
- ``lat_deg``, ``lon_deg``: WGS-84 geodetic latitude and longitude [deg];
  ``height_m``: ellipsoidal height [m] (not above mean sea level).
- The header line is optional: a first data line whose first field is not a number must
  be exactly the five names above (a header with other names is an error: a file whose
  columns are in another order would otherwise be read wrongly without a word).
- Lines starting with ``#`` and blank lines are skipped.
- Times must increase strictly (a week roll-over is fine: week and tow are combined).

Every failure is a :class:`~mixnav.errors.DataError` naming the file and the 1-based line:
a wrong number of fields, a field that is not a finite number, a week that is not a whole
number in 0..9999, a time of week outside [0, 604800), a latitude outside +-90 deg, a
longitude outside +-360 deg or a height outside -1..100 km (the fix readers' rule,
:func:`mixnav.io.tables.check_fix_values`), time not increasing.

The trajectory's ``time`` is GPS seconds since 1980-01-06 (one float: 0.24 us steps,
far below any scoring need); ``extra`` keeps the exact ``gps_week`` and ``gps_tow_s``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data import Trajectory
from ..errors import DataError
from .atomic import atomic_write_text
from .registry import ReadOptions, register_reader
from .tables import check_fix_values, check_times, read_numeric

#: the header's names, in order (the same names as the solution tables' columns)
COLUMNS = ("gps_week", "gps_tow_s", "lat_deg", "lon_deg", "height_m")
SECONDS_PER_WEEK = 604800.0


def _header_lines(path: Path) -> int:
    """0 without a header, else the 1-based line number of the header (checked)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for n, line in enumerate(fh, start=1):
                s = line.strip()
                if not s or s.startswith("#"):
                    continue
                first = s.split(",")[0].strip()
                try:
                    float(first)
                    return 0
                except ValueError:
                    names = tuple(t.strip() for t in s.split(","))
                    if names != COLUMNS:
                        raise DataError(f"the header {s[:80]!r} is not {','.join(COLUMNS)} (the header is optional; "
                                        "when given it must name these five columns in this order)",
                                        file=str(path), line=n) from None
                    return n
    except FileNotFoundError:
        raise DataError("reference file does not exist", file=str(path)) from None
    return 0


def read_gps_week_csv(path) -> Trajectory:
    """Read a GPS week / time-of-week / latitude / longitude / height reference (module
    docstring). Returns a Trajectory (``time``: GPS seconds since 1980, ``lla`` in rad,
    rad, m; no velocity or attitude) with ``extra = {"gps_week", "gps_tow_s"}``."""
    path = Path(path)
    if not path.is_file():
        raise DataError("reference file does not exist", file=str(path))
    head = _header_lines(path)
    tab = read_numeric(path, len(COLUMNS), delimiter=",", comment="#", skip_lines=head, what="reference")
    week, tow, lat, lon, h = tab.values.T
    bad = np.nonzero((week != np.round(week)) | (week < 0) | (week > 9999))[0]
    if bad.size:
        raise DataError(f"GPS week {week[bad[0]]!r} is not a whole number in 0..9999", file=str(path),
                        line=int(tab.lines[bad[0]]))
    bad = np.nonzero((tow < 0) | (tow >= SECONDS_PER_WEEK))[0]
    if bad.size:
        raise DataError(f"time of week {tow[bad[0]]!r} s is outside 0..604800 s", file=str(path),
                        line=int(tab.lines[bad[0]]))
    lla = np.column_stack([np.radians(lat), np.radians(lon), h])
    check_fix_values(lla, np.zeros((len(lla), 3)), tab.lines, str(path))   # the fix readers' position rule
    week = week.astype(np.int64)
    t = week * SECONDS_PER_WEEK + tow
    check_times(t, tab.lines, str(path), what="reference")
    return Trajectory(time=t, lla=lla, v_n=None, q_nb=None, extra={"gps_week": week, "gps_tow_s": tow})


def write_gps_week_csv(path, week, tow, lla, header: bool = True) -> None:
    """Write a reference in this format (``lla``: (n, 3) rad, rad, m): latitude and longitude
    to 1e-12 deg (0.1 um), height to 1 um, time of week to 1 ns."""
    lines = [",".join(COLUMNS)] if header else []
    lines += [f"{int(w)},{s:.9f},{np.degrees(p[0]):.12f},{np.degrees(p[1]):.12f},{p[2]:.6f}"
              for w, s, p in zip(week, tow, lla)]
    atomic_write_text(Path(path), "\n".join(lines) + "\n")


@register_reader("reference", "gps-week-csv")
def _read_reference(path: Path, options: ReadOptions) -> Trajectory:
    """The registered reference reader (no options)."""
    return read_gps_week_csv(path)
