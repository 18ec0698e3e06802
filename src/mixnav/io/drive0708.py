"""Reader of the drive-0708 car recording (IMU CSV + RTKLIB time-tag file).

``imu_*.csv``: one sample a line, ``ax, ay, az`` [g], ``gx, gy, gz``
[deg/s], then a millisecond tick counter since IMU power-up. The first and
last lines may be partial and are always skipped.

``imu_*.csv.tag`` (RTKLIB time tag, little-endian): a 60-byte text header,
``uint32`` tick, ``uint32`` whole seconds (GPS time counted from the Unix
epoch) and ``float64`` fractional seconds of the start, then ``(uint32
tick_ms, uint32 file_pos)`` pairs; the last pair's tick (ms after the start)
gives the end time. The IMU ticks are spread linearly between start and end,
then the logger's latency offset (-0.125 s for this recording) is added.
"""

from __future__ import annotations

import struct
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..data import ImuData
from ..errors import ArgumentError, DataError
from ..units import DEG
from .imu_checks import G0, DataWarning, check_plausible, rates_to_increments
from .registry import ReadOptions, register_reader
from .tables import check_times, read_numeric

_HEADER = 60
_FIXED = 16  # tick, seconds, fraction
#: largest difference between the tag's span and the IMU tick counter's (beyond the tag's lead, its
#: first pair's tick): an absolute part [s] (logging jitter) plus a relative part (the two clocks'
#: drift, 2e-4 = 200 ppm; drive-0708: 141 ms over 549 s, of which the lead 131 ms). A record-aligned truncation of the tag
#: beyond it would stretch every IMU time stamp (0.8 % of drive-0708's tag: 72 m RMSE instead of 5 m).
TAG_SPAN_TOLERANCE_S = 0.1
TAG_SPAN_DRIFT = 2e-4


@dataclass(frozen=True)
class TimeTag:
    start: float      # GPS seconds since 1970-01-01 (no leap seconds)
    end: float
    n_tags: int
    first: float = 0.0   # the first pair's tick [s after start]: when the stream's first bytes came


def read_time_tag(path) -> TimeTag:
    """Read an RTKLIB ``.tag`` file: start and end time of the stream."""
    path = Path(path)
    if not path.is_file():
        raise DataError("time-tag file does not exist", file=str(path))
    b = path.read_bytes()
    if len(b) < _HEADER + _FIXED + 8:
        raise DataError(f"time-tag file is truncated: {len(b)} bytes, a header and one tag need "
                        f"{_HEADER + _FIXED + 8}", file=str(path))
    if not b[:7] == b"TIMETAG":
        raise DataError("not an RTKLIB time-tag file (header does not start with 'TIMETAG')", file=str(path))
    _, sec = struct.unpack_from("<II", b, _HEADER)
    (frac,) = struct.unpack_from("<d", b, _HEADER + 8)
    body = len(b) - _HEADER - _FIXED
    if body % 8:
        raise DataError(f"time-tag file is truncated: {body % 8} stray bytes after the last whole tag "
                        f"(byte {len(b) - body % 8})", file=str(path))
    pairs = np.frombuffer(b, dtype="<u4", offset=_HEADER + _FIXED).reshape(-1, 2)
    if not (0.0 <= frac < 1.0) or np.any(np.diff(pairs[:, 0].astype(np.int64)) < 0):
        raise DataError("time-tag file is corrupt (fraction outside [0, 1) or ticks decreasing)", file=str(path))
    start = float(sec) + float(frac)
    return TimeTag(start=start, end=start + pairs[-1, 0] / 1000.0, n_tags=len(pairs), first=pairs[0, 0] / 1000.0)


def read_drive_imu(csv_path, tag_path=None, time_offset: float = -0.125, max_gap: float | None = 0.05,
                   gap_action: str = "warn", spike_action: str = "fail", tag_start: str = "tag") -> ImuData:
    """IMU increments of the drive-0708 recording, in the IMU's own axes (SI).

    Parameters
    ----------
    csv_path, tag_path : path-like
        The CSV and its ``.tag`` (default: the CSV path plus ``.tag``).
    time_offset : float
        Added to every IMU time [s] (logger latency).
    max_gap, gap_action :
        See :func:`mixnav.io.tables.check_times`.
    spike_action : {"fail", "reject"}
        See :func:`mixnav.io.imu_checks.check_spikes`.
    tag_start : {"tag", "first-bytes"}
        Where the first tick is put: at the tag's start (``"tag"``, the data README's rule), or
        at its first pair's tick, when the stream's first bytes came (``"first-bytes"``). The
        ticks are spread linearly from there to the tag's end.
    """
    if tag_start not in ("tag", "first-bytes"):
        raise ArgumentError(f"must be 'tag' or 'first-bytes', got {tag_start!r}", argument="tag_start")
    csv_path = Path(csv_path)
    tag = read_time_tag(tag_path or Path(str(csv_path) + ".tag"))
    # The first and last lines may be partial: drop them, but use their
    # ticks (when readable) as the span that the tag's start and end cover.
    try:
        tab = read_numeric(csv_path, 7, delimiter=",", drop_edges=True, what="IMU")
    except DataError as exc:   # only the edges may be partial: one inside is a damaged file
        if exc.line is None or not exc.message.startswith("expected 7 columns"):
            raise
        raise DataError(f"a partial line inside the file ({exc.message}); only the first and the last line "
                        "may be partial", file=exc.file, line=exc.line) from None
    numbered = [(i, ln) for i, ln in enumerate(csv_path.read_text(encoding="utf-8", errors="replace")
                                               .splitlines(), start=1) if ln.strip()]
    ticks = tab.values[:, 6]
    step = float(np.median(np.diff(ticks))) if len(ticks) > 1 else 10.0
    # a cut edge line has lost its tick (fewer fields, or digits cut off the last one): it was
    # one sample before/after its neighbour
    first_tick = _tick(numbered[0][1], ticks[0], before=True)
    last_tick = _tick(numbered[-1][1], ticks[-1], before=False)
    partial = [(i, which) for (i, _), tk, which in ((numbered[0], first_tick, "first"), (numbered[-1], last_tick, "last"))
               if tk is None]
    if partial:
        warnings.warn(f"{csv_path}: {' and '.join(f'the {w} line (line {i})' for i, w in partial)} "
                      f"{'is' if len(partial) == 1 else 'are'} partial: skipped as the format says, the tick taken "
                      "one sample from its neighbour's (metrics.json: imu_partial_lines_skipped)",
                      DataWarning, stacklevel=2)
    first_tick = ticks[0] - step if first_tick is None else first_tick
    last_tick = ticks[-1] + step if last_tick is None else last_tick
    check_times(ticks, tab.lines, str(csv_path), what="IMU tick")
    span = last_tick - first_tick
    if span <= 0:
        raise DataError("IMU ticks do not increase from the first to the last line", file=str(csv_path))
    if len(ticks) < 2:
        raise DataError("need at least two IMU samples", file=str(csv_path))
    # time continuity: the tag's span (start to its last pair) and the IMU's own millisecond
    # counter must agree (a truncated or foreign tag would stretch or squeeze every IMU time stamp);
    # the tag may begin up to its first pair's tick before the data (drive-0708: 131 ms)
    tag_file = tag_path or Path(str(csv_path) + ".tag")
    tag_span, tick_span = tag.end - tag.start, span / 1000.0
    allowed = TAG_SPAN_TOLERANCE_S + TAG_SPAN_DRIFT * tick_span
    if not tick_span - allowed <= tag_span <= tick_span + tag.first + allowed:
        raise DataError(f"the time-tag file spans {tag_span:.3f} s (to its last tick) but the IMU's tick counter in "
                        f"{csv_path.name} {tick_span:.3f} s (its first tick to its last): one of the two files is "
                        f"truncated, or the tag belongs to another recording (the tag must span "
                        f"{tick_span - allowed:.3f}..{tick_span + tag.first + allowed:.3f} s: the ticks' span, plus "
                        f"its first pair's lead of {tag.first:.3f} s, within {TAG_SPAN_TOLERANCE_S:g} s + "
                        f"{TAG_SPAN_DRIFT * 1e6:g} ppm)", file=str(tag_file))
    # "first-bytes": the first tick is when the stream's first bytes came (the tag's start plus its
    # first pair's tick), not the tag's start; spreading the ticks from the tag's start instead
    # stretches every IMU time by that lead over the recording (drive-0708: 131 ms over 549 s,
    # 257 ppm, where the chunks' arrival times against the ticks drift by 12 ppm:
    # benchmarks/results/drive0708_time_tags.md)
    lead = tag.first if tag_start == "first-bytes" else 0.0
    t = tag.start + lead + (ticks - first_tick) / span * (tag.end - tag.start - lead) + time_offset
    gaps = check_times(t, tab.lines, str(csv_path), max_gap=max_gap, gap_action=gap_action, what="IMU").gaps
    f = tab.values[:, 0:3] * G0
    w = tab.values[:, 3:6] * DEG
    imu = replace(rates_to_increments(t, w, f, source=str(csv_path)), gaps=gaps, partial_lines=len(partial))
    return check_plausible(imu, "deg/s", "g", tab.lines[1:], spike_action)


def _tick(line: str, neighbour: float, before: bool) -> float | None:
    """The tick of an edge line when the line is whole (7 numbers, the tick before/after its
    neighbour's), else None (a partial line: a cut last line keeps a prefix of its tick)."""
    parts = line.strip().split(",")
    try:
        vals = [float(x) for x in parts]
    except ValueError:
        return None
    if len(vals) != 7 or not ((vals[6] < neighbour) if before else (vals[6] > neighbour)):
        return None
    return vals[6]


@register_reader("imu", "drive-0708")
def _read(path: Path, options: ReadOptions) -> ImuData:
    """The registered reader (``options``: ``[imu]``'s ``tag``, a file of the data folder, ``tag_start``,
    ``max_gap``, ``gap_action``, ``spike_action``); times as the tag gives them (no offset: the
    installation's)."""
    tag = options.get("tag")
    return read_drive_imu(path, options.folder / tag if tag else None, time_offset=0.0,
                          tag_start=options.get("tag_start", "tag"), **options.imu_checks(max_gap=0.05))
