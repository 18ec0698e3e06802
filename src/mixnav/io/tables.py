"""Validated reading of numeric text tables, with errors that name file and line.

Every reader in :mod:`mixnav.io` goes through :func:`read_numeric` so that a
malformed file fails the same way everywhere: missing or extra columns, text
in a number column, NaN, all reported with the 1-based line number of the
file. pandas' C parser does the fast path; only when it fails (or finds NaN)
is the file scanned line by line to locate the problem.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import ArgumentError, DataError

#: What a time gap beyond ``max_gap`` does: warn (counted) or raise.
GAP_ACTIONS = ("warn", "fail")


@dataclass(frozen=True)
class Table:
    """Rows of a numeric table and the file line each came from."""

    values: np.ndarray   # (n, ncols) float64
    lines: np.ndarray    # (n,) 1-based line numbers in the file
    path: str


def _is_float(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def header_fields(path: Path, what: str) -> list[str]:
    """The comma-separated fields of a file's header line (a ``DataError`` naming the file
    when it does not exist or its first line is empty)."""
    if not path.is_file():
        raise DataError(f"{what} file does not exist", file=str(path))
    with open(path, encoding="utf-8", errors="replace") as fh:
        head = fh.readline()
    if not head.strip():
        raise DataError(f"{what} file is empty (no header line)", file=str(path), line=1)
    return head.strip().split(",")


def read_numeric(path, ncols: int | tuple[int, ...], *, delimiter: str | None = None,
                 comment: str | None = None, skip_lines: int = 0, drop_edges: bool = False,
                 converters=None, what: str = "data") -> Table:
    """Read a table of numbers.

    Parameters
    ----------
    path : path-like
    ncols : int or tuple of int
        Allowed numbers of columns (e.g. ``(7, 13)`` for optional velocity).
    delimiter : str or None
        ``None`` splits on whitespace.
    comment : str or None
        Lines starting with it are skipped (as are blank lines).
    skip_lines : int
        Header lines to skip before the data.
    drop_edges : bool
        Drop the first and the last data line (loggers that may cut them).
    converters : callable, optional
        ``converters(tokens) -> list[float]`` for lines whose first tokens are
        not plain numbers (e.g. calendar dates); the line is parsed in Python.
    what : str
        What the file holds, for messages.

    Raises
    ------
    DataError
        Empty file (with ``skip_lines``: no data line after the header, naming
        its last line), wrong column count, non-numeric or non-finite value,
        each naming the file and the line.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{what} file does not exist", file=str(path))
    text = path.read_text(encoding="utf-8", errors="replace")
    allowed = (ncols,) if isinstance(ncols, int) else tuple(ncols)
    raw = text.splitlines()
    keep_lines, keep_rows = [], []
    for i, line in enumerate(raw[skip_lines:], start=skip_lines + 1):
        s = line.strip()
        if not s or (comment and s.startswith(comment)):
            continue
        keep_lines.append(i)
        keep_rows.append(s)
    if skip_lines and not keep_rows and len(raw) >= skip_lines:
        raise DataError(f"{what} file is empty: no data line after the header", file=str(path),
                        line=skip_lines)
    if drop_edges:
        keep_lines, keep_rows = keep_lines[1:-1], keep_rows[1:-1]
    if not keep_rows:
        raise DataError(f"{what} file is empty (no data lines)", file=str(path))
    lines = np.asarray(keep_lines)
    if converters is None:
        try:
            sep = r"\s+" if delimiter is None else delimiter
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                df = pd.read_csv(io.StringIO("\n".join(keep_rows)), sep=sep, header=None,
                                 dtype=np.float64, engine="c", skipinitialspace=True)
            values = df.to_numpy()
            if values.shape[1] in allowed and np.isfinite(values).all():
                return Table(values, lines, str(path))
        except (ValueError, pd.errors.ParserError):
            pass
    # Slow path: parse (or locate the problem) line by line.
    rows = []
    for ln, s in zip(lines, keep_rows):
        toks = s.split(delimiter) if delimiter else s.split()
        toks = [t.strip() for t in toks]
        if converters is not None:
            try:
                vals = converters(toks)
            except (ValueError, IndexError) as exc:
                raise DataError(f"cannot read this {what} line ({exc}): {s[:80]!r}", file=str(path),
                                line=int(ln)) from None
        else:
            if len(toks) not in allowed:
                raise DataError(f"expected {' or '.join(map(str, allowed))} columns, found {len(toks)}",
                                file=str(path), line=int(ln))
            bad = [t for t in toks if not _is_float(t)]
            if bad:
                raise DataError(f"not a number: {bad[0]!r}", file=str(path), line=int(ln))
            vals = [float(t) for t in toks]
        if len(vals) not in allowed:
            raise DataError(f"expected {' or '.join(map(str, allowed))} columns, found {len(vals)}",
                            file=str(path), line=int(ln))
        if not all(np.isfinite(vals)):
            raise DataError("non-finite value (NaN or inf)", file=str(path), line=int(ln))
        rows.append(vals)
    widths = {len(r) for r in rows}
    if len(widths) > 1:
        first = next(i for i, r in enumerate(rows) if len(r) != len(rows[0]))
        raise DataError(f"column count changes from {len(rows[0])} to {len(rows[first])}",
                        file=str(path), line=int(lines[first]))
    return Table(np.array(rows, dtype=float), lines, str(path))


def check_gap_action(gap_action) -> None:
    """An :class:`ArgumentError` naming ``gap_action`` unless it is one of :data:`GAP_ACTIONS`."""
    if not (isinstance(gap_action, str) and gap_action in GAP_ACTIONS):
        raise ArgumentError(f"must be {' or '.join(repr(a) for a in GAP_ACTIONS)}, got {gap_action!r}",
                            "gap_action")


@dataclass
class TimeCheck:
    """What :func:`check_times` found (gaps are counted when only warned)."""

    gaps: int = 0
    largest_gap: float = 0.0


def check_times(t: np.ndarray, lines: np.ndarray, path: str, max_gap: float | None = None,
                gap_action: str = "warn", what: str = "data") -> TimeCheck:
    """Times must increase strictly; gaps beyond ``max_gap`` warn (counted) or fail.

    Raises
    ------
    ArgumentError
        ``gap_action`` is not one of :data:`GAP_ACTIONS` ("warn", "fail").
    DataError
        Time going backwards or repeating (naming the line), or a gap when
        ``gap_action == "fail"``.
    """
    check_gap_action(gap_action)
    d = np.diff(t)
    bad = np.nonzero(d <= 0)[0]
    if bad.size:
        k = int(bad[0]) + 1
        kind = "repeats" if d[bad[0]] == 0 else "goes backwards"
        raise DataError(f"{what} time {kind} ({float(t[k - 1])!r} then {float(t[k])!r})", file=path,
                        line=int(lines[k]))
    out = TimeCheck()
    if max_gap is not None and d.size:
        gaps = np.nonzero(d > max_gap)[0]
        out.gaps = int(gaps.size)
        out.largest_gap = float(d.max())
        if gaps.size:
            k = int(gaps[0]) + 1
            msg = (f"{gaps.size} gap(s) longer than {max_gap:g} s in the {what}; the first, "
                   f"{d[gaps[0]]:.3f} s, ends here")
            if gap_action == "fail":
                raise DataError(msg, file=path, line=int(lines[k]))
            warnings.warn(f"{path}, line {int(lines[k])}: {msg}", stacklevel=3)
    return out


#: fastest plausible GNSS velocity of a vehicle [m/s] (docs/validation.md)
MAX_SPEED = 1000.0


def check_fix_values(lla: np.ndarray, sd: np.ndarray, lines: np.ndarray, path: str,
                     vel: np.ndarray | None = None) -> None:
    """Plausible GNSS fixes (docs/validation.md), a DataError naming the first bad line:
    latitude within +-90 deg, longitude within +-360 deg, height within
    :data:`mixnav.data.HEIGHT_RANGE`, sigmas finite and at most :data:`mixnav.data.MAX_SIGMA`,
    speed at most :data:`MAX_SPEED`. ``lla`` [rad, rad, m], ``sd`` [m] (k, 3), ``vel`` [m/s]."""
    from ..data import HEIGHT_RANGE, MAX_SIGMA
    checks = [(np.abs(lla[:, 0]) > np.pi / 2, "latitude outside [-90, 90] deg"),
              (np.abs(lla[:, 1]) > 2 * np.pi, "longitude outside [-360, 360] deg"),
              ((lla[:, 2] < HEIGHT_RANGE[0]) | (lla[:, 2] > HEIGHT_RANGE[1]),
               f"height outside {HEIGHT_RANGE[0]:g}..{HEIGHT_RANGE[1]:g} m"),
              (~np.all(np.isfinite(sd) & (sd <= MAX_SIGMA), axis=1), f"a standard deviation beyond {MAX_SIGMA:g} m")]
    if vel is not None:
        checks.append((~(np.linalg.norm(vel, axis=1) <= MAX_SPEED), f"a speed beyond {MAX_SPEED:g} m/s"))
    for bad, what in checks:
        if bad.any():
            k = int(np.argmax(bad))
            raise DataError(f"{what} ({int(bad.sum())} line(s))", file=path, line=int(lines[k]))
