"""The generic odometer CSV layout: wheel speed or travelled distance per sample.

Comma-separated, one header line naming the columns, each ``name[unit]``
(units as in :mod:`mixnav.io.generic_csv`: anything :mod:`mixnav.units`
reads), in any order. Times are seconds on the IMU time axis. Exactly one of
three ways to give the motion::

    time[s], speed[m/s]                 # forward speed at each time
    time[s], distance[m]                # cumulative travelled distance
    time[s], distance_increment[m]      # distance since the previous line

plus optionally ``sigma[m/s]``: the 1-sigma noise of each speed sample (else
the reader's ``sigma`` argument). A column may be written without its
bracket (``time,speed``) when the reader's ``units`` argument names its unit
(``units={"speed": "km/h"}``); a unit both in the header and in ``units``
must agree.

Distances become speeds over each sample interval: the line ``k`` closes the
interval ``(t[k-1], t[k]]`` and gives the mean speed
``(d[k] - d[k-1]) / (t[k] - t[k-1])`` (cumulative form) or
``increment[k] / (t[k] - t[k-1])`` (increment form; the first line's
increment has no interval and is ignored). The mean speed over an interval
is the speed at its midpoint to second order (error ``a' dt^2 / 24`` for a
speed whose acceleration changes at ``a'``), so these samples are stamped at
the interval midpoints ``(t[k-1] + t[k]) / 2``: N lines give N - 1 samples.
A ``sigma`` column then belongs to the interval its line closes.

Validation (each a :class:`~mixnav.errors.DataError` naming the file and the
1-based line): unknown or duplicated columns, a unit of the wrong dimension,
text or NaN in a number column, an empty file, times going backwards or
repeating, a negative speed (or a decreasing distance) unless ``signed``, a
speed above :data:`mixnav.data.MAX_VEHICLE_SPEED` (a unit error: km/h
declared as m/s), a non-positive sigma, and a time gap longer than
``max_gap`` (warned with the line, or an error, as ``gap_action`` says; the
IMU readers' policy).
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .. import units as u
from ..data import MAX_VEHICLE_SPEED, OdometerData
from ..errors import ArgumentError, DataError
from .registry import ReadOptions, register_reader
from .tables import check_gap_action, check_times, header_fields, read_numeric

_COL = re.compile(r"^\s*([A-Za-z_]+)\s*(?:\[(.*)\])?\s*$")

_DIMS = {"time": u.TIME, "speed": u.VELOCITY, "distance": u.LENGTH, "distance_increment": u.LENGTH,
         "sigma": u.VELOCITY}
#: The three layouts (motion columns); ``time`` is always required, ``sigma`` optional.
_MOTION = ("speed", "distance", "distance_increment")


def _real(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _check_arguments(sigma, max_gap, gap_action, units):
    if sigma is not None and not (_real(sigma) and math.isfinite(sigma) and sigma > 0):
        raise ArgumentError(f"must be a finite positive speed sigma [m/s], got {sigma!r}", "sigma")
    if max_gap is not None and not (_real(max_gap) and max_gap > 0):
        raise ArgumentError(f"must be a positive time [s] or None, got {max_gap!r}", "max_gap")
    check_gap_action(gap_action)
    for name, unit in (units or {}).items():
        if name not in _DIMS:
            raise ArgumentError(f"unknown column {name!r}; columns are {', '.join(_DIMS)}", f"units.{name}")
        try:
            u.parse_quantity(f"1 {unit}", _DIMS[name])
        except u.UnitError as exc:
            raise ArgumentError(str(exc), f"units.{name}") from None


def _header(path: Path, units: Mapping[str, str]):
    """Column names and their factors to SI, from the header and ``units``."""
    names, factors = [], []
    for col in header_fields(path, "odometer"):
        m = _COL.match(col)
        if not m:
            raise DataError(f"header column {col.strip()!r} is not 'name[unit]'", file=str(path), line=1)
        name, unit = m.group(1), m.group(2)
        if name not in _DIMS:
            raise DataError(f"unknown column {name!r}; an odometer file has time, one of "
                            f"{', '.join(_MOTION)}, and optionally sigma (docs/data_formats.md)",
                            file=str(path), line=1)
        if unit is None or not unit.strip():
            if name not in units:
                raise DataError(f"column {name!r} has no unit: write {name}[unit] in the header or pass "
                                f"units={{{name!r}: ...}}", file=str(path), line=1)
            unit = units[name]
        try:
            f = u.parse_quantity(f"1 {unit}", _DIMS[name])
        except u.UnitError as exc:
            raise DataError(f"column {name!r}: {exc}", file=str(path), line=1) from None
        if name in units and not math.isclose(u.parse_quantity(f"1 {units[name]}", _DIMS[name]), f,
                                              rel_tol=1e-12):
            raise DataError(f"column {name!r} is in {unit!r} in the header but units says {units[name]!r}",
                            file=str(path), line=1)
        names.append(name)
        factors.append(f)
    if len(set(names)) != len(names):
        raise DataError("a column appears twice in the header", file=str(path), line=1)
    motion = [n for n in names if n in _MOTION]
    if "time" not in names or len(motion) != 1:
        raise DataError(f"columns {names}: need time and exactly one of {', '.join(_MOTION)} "
                        "(plus an optional sigma)", file=str(path), line=1)
    return names, np.array(factors), motion[0]


def read_odometer_csv(path, *, sigma: float | None = None, units: Mapping[str, str] | None = None,
                      signed: bool = False, max_gap: float | None = None,
                      gap_action: str = "warn") -> OdometerData:
    """Read an odometer CSV (layout in the module docstring and docs/data_formats.md).

    Parameters
    ----------
    path : path-like
    sigma : float, optional
        1-sigma noise of every speed sample [m/s], for files without a
        ``sigma`` column; required then (a file with the column ignores it).
    units : mapping of str to str, optional
        Units of columns whose header has no ``[unit]``, e.g.
        ``{"speed": "km/h"}``; a unit given in both places must agree.
    signed : bool
        Speeds may be negative (reversing). Unsigned data with a negative
        speed or a decreasing distance is an error.
    max_gap : float, optional
        Longest accepted interval between consecutive lines [s]; None: no limit.
    gap_action : {"warn", "fail"}
        A longer interval warns (naming the line that ends it; the data is
        returned with the gap, counted in ``OdometerData.gaps``) or raises, as
        the IMU readers do.

    Returns
    -------
    OdometerData
        ``time`` (M,) [s], ``speed`` (M,) [m/s], ``sigma`` (M,) [m/s]:
        one sample per line for ``speed``, one per interval (midpoint time)
        for the distance forms; ``gaps``: the gaps accepted with a warning.

    Raises
    ------
    ArgumentError
        An impossible argument (non-positive ``sigma`` or ``max_gap``, unknown
        ``gap_action``, a unit of the wrong dimension in ``units``).
    DataError
        Anything wrong in the file, naming the file and the line.
    """
    units = dict(units or {})
    _check_arguments(sigma, max_gap, gap_action, units)
    path = Path(path)
    names, fac, motion = _header(path, units)
    if "sigma" not in names and sigma is None:
        raise ArgumentError("the file has no sigma column: give the speed noise [m/s]", "sigma")
    tab = read_numeric(path, len(names), delimiter=",", skip_lines=1, what="odometer")
    c = {n: tab.values[:, i] * fac[i] for i, n in enumerate(names)}
    t, lines, src = c["time"], tab.lines, str(path)
    gaps = check_times(t, lines, src, max_gap=max_gap, gap_action=gap_action, what="odometer").gaps
    sig = c["sigma"] if "sigma" in c else np.full(len(t), float(sigma))
    if motion == "speed":
        time, speed, sl = t, c["speed"], lines
    else:
        if len(t) < 2:
            raise DataError("a distance needs at least two lines (one interval)", file=src, line=int(lines[0]))
        step = np.diff(c["distance"]) if motion == "distance" else c["distance_increment"][1:]
        if not signed and np.any(step < 0):
            k = int(np.argmax(step < 0)) + 1
            what = "distance decreases" if motion == "distance" else "distance increment is negative"
            raise DataError(f"{what} ({step[k - 1]:.6g} m) but the odometer is not signed; "
                            "pass signed=True for reversing data", file=src, line=int(lines[k]))
        time, speed, sig, sl = 0.5 * (t[1:] + t[:-1]), step / np.diff(t), sig[1:], lines[1:]
    _check_samples(speed, sig, sl, src, signed, motion)
    return OdometerData(time=np.asarray(time, float), speed=np.asarray(speed, float),
                        sigma=np.asarray(sig, float), signed=bool(signed), source=src, gaps=gaps)


def _check_samples(speed, sig, lines, src, signed, motion):
    """Sign, size and sigma of every sample, naming the line it came from."""
    if not signed and np.any(speed < 0):
        k = int(np.argmax(speed < 0))
        raise DataError(f"speed is negative ({speed[k]:.6g} m/s) but the odometer is not signed; "
                        "pass signed=True for reversing data", file=src, line=int(lines[k]))
    big = np.abs(speed) > MAX_VEHICLE_SPEED
    if big.any():
        k = int(np.argmax(big))
        how = "" if motion == "speed" else f" from the {motion.replace('_', ' ')} over the interval"
        raise DataError(f"speed {speed[k]:.6g} m/s{how} is above {MAX_VEHICLE_SPEED:g} m/s: "
                        "probably a wrong unit (km/h or mm/s declared as m/s, or mm as m?)",
                        file=src, line=int(lines[k]))
    bad = ~(sig > 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise DataError(f"sigma must be positive, got {sig[k]:.6g} m/s", file=src, line=int(lines[k]))


@register_reader("odometer", "csv")
def _read(path: Path, options: ReadOptions) -> OdometerData:
    """The registered odometer reader (``[aiding.odometer]``'s ``sigma``, ``max_gap``, ``gap_action``)."""
    max_gap = options.get("max_gap")
    return read_odometer_csv(path, sigma=options.get("sigma"), max_gap=None if max_gap is None else float(max_gap),
                             gap_action=options.get("gap_action", "warn"))
