"""GPS pseudoranges from a RINEX observation file (2.x or 3.x), read with georinex.

Any receiver whose data RTKLIB's ``convbin`` (or the maker's tool) converts to RINEX
can then be processed by single-point positioning like a phone log
(:mod:`mixnav.experiment.spp_process`, ``raw_gnss.format = "rinex-obs"``).

The L1 C/A pseudorange is taken: ``C1C`` (RINEX 3) or ``C1`` (RINEX 2), with the L1
Doppler of the same record when the file has it (``D1C`` / ``D1``: the range rate of the
tightly coupled INS, :mod:`mixnav.experiment.rinex_ins`). Epoch times are
those the epoch records give, to the ns (georinex truncates them to microseconds, and
RINEX 2 to milliseconds when its file-size guess fails: 4 m of satellite motion), in GPS
time (a header declaring another time system is refused), as GPS week and seconds of week.

georinex reads the values. Before it, the file's header and epoch records are
walked here (:func:`_listing`), for two reasons: georinex passes over what it does not
know (a satellite system letter outside its list, a record where an epoch should be:
it stops there in RINEX 3, skips the line in RINEX 2), and nothing it passes over may
vanish uncounted. So every satellite record of every observation epoch is counted per
system letter; the ones that are not GPS are reported in ``rejected`` as
``"not GPS: <letter>"``, GPS records without a usable pseudorange as
``"no C1 pseudorange"`` (``"no C1C pseudorange"``), and epochs without any GPS
pseudorange in ``epochs_all_rejected`` (the SPP's epoch status ``all measurements
rejected``). A damaged header or epoch record is a :class:`DataError` naming the file
and line. Only GPS is used: GLONASS and the others need their own broadcast ephemerides
and clocks (not built).
"""

from __future__ import annotations

import io
from collections import Counter
from dataclasses import dataclass
from math import ceil
from pathlib import Path

import numpy as np

from ..data import RawPseudoranges
from ..errors import DataError
from .registry import ReadOptions, register_reader

#: GPS time origin (1980-01-06 00:00:00) as numpy datetime64
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
_WEEK = 604800.0


#: the one raw-GNSS type (fields: mixnav.data.RawPseudoranges); RINEX gives doppler, code, version
#: and event_records
RinexPseudoranges = RawPseudoranges


@dataclass
class _Listing:
    """What the header and epoch records of a RINEX observation file list."""

    version: float
    code: str                  # C1C or C1
    records: Counter           # satellite records of observation epochs, per system letter
    times: np.ndarray          # (epochs,) datetime64[ns]: observation epochs (flag 0 or 1), as written
    lines: np.ndarray          # (epochs,) their line numbers (1-based)
    gps: np.ndarray            # (epochs,) GPS satellite records of each observation epoch
    events: Counter            # records of other flags (events, cycle slips), per flag
    observations_only: str | None = None   # the text without those records (None: there are none)

    @property
    def epochs(self) -> int:
        return len(self.times)


def _int(text: str, what: str, path: Path, lineno: int) -> int:
    try:
        return int(text)
    except ValueError:
        raise DataError(f"{what} {text.strip()!r} is not an integer", file=str(path), line=lineno) from None


def _epoch_time(ln: str, version: float, path: Path, lineno: int) -> np.datetime64:
    """The epoch record's time to the ns (georinex keeps microseconds, or milliseconds in RINEX 2
    when it cannot guess the file's size: 1 ms is 4 m of satellite motion)."""
    try:
        if version >= 3:
            y, rest, sec = int(ln[2:6]), ln[7:18], float(ln[18:29])
        else:
            y, rest, sec = int(ln[1:3]), ln[4:15], float(ln[15:26])
            y += 2000 if y < 80 else 1900      # RINEX 2's two-digit year
        mo, d, hh, mm = (int(x) for x in rest.split())
        if not (0.0 <= sec < 61.0):
            raise ValueError(sec)
        t = np.datetime64(f"{y:04d}-{mo:02d}-{d:02d}T{hh:02d}:{mm:02d}", "ns")
        return t + np.timedelta64(int(round(sec * 1e9)), "ns")
    except ValueError:
        raise DataError(f"epoch time {ln[:29].strip()!r} is not a date and time", file=str(path),
                        line=lineno) from None


def _names(ln: str, n: int, path: Path, lineno: int) -> list:
    """System letters of the ``n`` satellites a RINEX 2 epoch line (or its continuation) lists."""
    names = [ln[32 + 3 * i:35 + 3 * i] for i in range(n)]
    if any(len(s) < 3 or not s[1:].strip().isdigit() for s in names):
        raise DataError(f"the epoch record's satellite list does not hold {n} satellite names (letter and "
                        "2 digits)", file=str(path), line=lineno)
    return [s[0] for s in names]


def _count(text: str, path: Path, lineno: int) -> int:
    n = _int(text, "number of satellites", path, lineno)
    if n < 0:
        raise DataError(f"number of satellites {n} is negative", file=str(path), line=lineno)
    return n


def _listing(path: Path) -> _Listing:
    """Walk the header and the epoch records (not the values) of ``path``.

    Raises DataError (file and line) for a file that is not a RINEX 2/3 observation file,
    one without the L1 C/A pseudorange type for GPS in its header, or a line that is not
    an epoch record where one must be.
    """
    from georinex.rio import opener   # reads gzip / bzip2 / Hatanaka as georinex does
    try:
        with opener(path) as fh:
            lines = fh.read().splitlines()
    except Exception as exc:  # noqa: BLE001 - a damaged compressed file raises many kinds
        raise DataError(f"cannot be read as text ({type(exc).__name__}: {exc})", file=str(path)) from None
    first = next((k for k, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise DataError("the file is empty", file=str(path))
    head = lines[first]
    try:
        version = float(head[:9])
    except ValueError:
        version = 0.0
    if "RINEX VERSION / TYPE" not in head[60:] or int(version) not in (2, 3) or head[20:21] != "O":
        raise DataError("not a RINEX 2 or 3 observation file (the first line is not "
                        "'RINEX VERSION / TYPE' with version 2.x/3.x and type O)", file=str(path), line=first + 1)
    types: dict[str, list[str]] = {}
    type_line: dict[str, int] = {}
    n_types: dict[str, int] = {}
    k = first + 1
    sys = ""
    while True:
        if k >= len(lines):
            raise DataError("the header has no END OF HEADER line", file=str(path), line=k)
        ln = lines[k]
        label, body = ln[60:].strip(), ln[:60]
        k += 1
        if label == "END OF HEADER":
            break
        if label == "TIME OF FIRST OBS" and body[48:51].strip() not in ("", "GPS", "GAL"):
            # GAL is GPS time; GLO / UTC would need the leap seconds, BDT is 14 s off
            raise DataError(f"epoch times in {body[48:51].strip()} time: only GPS (or GAL) time is read",
                            file=str(path), line=k)
        if version < 3 and label == "# / TYPES OF OBSERV":
            if body[:6].strip():       # a continuation line leaves the count blank
                sys = " "
                n_types[sys] = _int(body[:6], "number of observation types", path, k)
                type_line.setdefault(sys, k)
            types.setdefault(" ", []).extend(body[6:].split())
        elif version >= 3 and label == "SYS / # / OBS TYPES":
            if body[:1].strip():
                sys = body[:1]
                n_types[sys] = _int(body[3:6], "number of observation types", path, k)
                type_line.setdefault(sys, k)
            if not sys:
                raise DataError("SYS / # / OBS TYPES continuation without a system letter", file=str(path), line=k)
            types.setdefault(sys, []).extend(body[6:].split())
    if version < 3:
        code, key, label = "C1", " ", "# / TYPES OF OBSERV"
    else:
        code, key, label = "C1C", "G", "SYS / # / OBS TYPES"
    if key not in types:
        if version < 3:
            raise DataError(f"the header has no {label} line", file=str(path))
        raise DataError(f"no GPS observation types: the header's {label} lines list the systems "
                        f"{', '.join(sorted(types)) or 'none'} (G with C1C is needed)", file=str(path),
                        line=min(type_line.values(), default=None))
    if code not in types[key]:
        raise DataError(f"no L1 C/A pseudorange: the header's {label} lists {' '.join(types[key]) or 'nothing'} "
                        f"for {'every system' if version < 3 else 'GPS'} ({code} is needed)",
                        file=str(path), line=type_line.get(key))
    for sy, listed in types.items():
        if n_types.get(sy) != len(listed):
            raise DataError(f"the header's {label} line declares {n_types.get(sy, 'no number of')} observation "
                            f"types{'' if version < 3 else ' for ' + sy} but lists {len(listed)}", file=str(path),
                            line=type_line.get(sy))
    per_sat = ceil(len(types[key]) / 5)  # RINEX 2: lines per satellite record (5 values a line)
    records: Counter = Counter()
    events: Counter = Counter()
    drop = np.zeros(len(lines), dtype=bool)   # lines of records that are not observations
    times, at, gps = [], [], []
    while k < len(lines):
        ln = lines[k]
        k += 1
        start = k
        if not ln.strip():
            continue
        if version >= 3:
            if not ln.startswith(">"):
                raise DataError("an epoch record ('> yyyy mm dd ...') was expected", file=str(path), line=k)
            flag = _int(ln[31:32] or "0", "epoch flag", path, k)
            n = _count(ln[32:35], path, k)
            sats = [s[:1] for s in lines[k:k + n]] if flag in (0, 1) else []
            if " " in sats or "" in sats:
                j = k + 1 + [s[:1].strip() for s in lines[k:k + n]].index("")
                raise DataError("a satellite record (system letter and number) was expected", file=str(path),
                                line=j)
            k += n
        else:
            if len(ln) < 32 or not ln[26:29].strip().isdigit():
                raise DataError("an epoch record (' yy mm dd hh mm ss.sssssss  f nnn') was expected",
                                file=str(path), line=k)
            flag = _int(ln[28:29], "epoch flag", path, k)
            n = _count(ln[29:32], path, k)
            if flag in (0, 1, 6):        # satellite list (12 a line), then per_sat lines each
                sats = _names(ln, min(n, 12), path, k)
                for _ in range(ceil(n / 12) - 1):
                    cont = lines[k] if k < len(lines) else ""
                    k += 1
                    sats += _names(cont, min(n - len(sats), 12), path, k)
                k += n * per_sat
                if flag == 6:            # cycle-slip records: not observations
                    sats = []
            else:                        # events: n header records follow
                sats = []
                k += n
        if k > len(lines):
            raise DataError(f"the file ends inside an epoch record of {n} satellites", file=str(path), line=len(lines))
        if flag in (0, 1):
            at.append(start)
            times.append(_epoch_time(lines[start - 1], version, path, start))
            # a blank system letter is GPS (RINEX 2)
            letters = ["G" if s == " " else s for s in sats]
            records.update(letters)
            gps.append(letters.count("G"))
        else:
            events[f"flag {flag}"] += 1
            drop[start - 1:k] = True
    t = np.array(times, dtype="datetime64[ns]")
    if len(t) > 1 and np.any(np.diff(t) <= np.timedelta64(0, "ns")):
        j = int(np.nonzero(np.diff(t) <= np.timedelta64(0, "ns"))[0][0]) + 1
        raise DataError(f"epoch times do not increase ({t[j]} after {t[j - 1]})", file=str(path), line=at[j])
    # georinex reads a cycle-slip record (flag 6, same layout as observations) as a second
    # epoch at the same time and fails: it is given the file without the records that
    # are not observations
    kept = "\n".join(ln for ln, d in zip(lines, drop) if not d) + "\n" if events else None
    return _Listing(version=version, code=code, records=records, times=t, lines=np.array(at, dtype=np.int64),
                    gps=np.array(gps, dtype=np.int64), events=events, observations_only=kept)


def _full_times(truncated: np.ndarray, listing: _Listing, path: Path) -> np.ndarray:
    """The epoch records' own times (to the ns) of georinex's epochs (truncated to us or ms):
    each is the first record at or after it, at most 1 ms later (1.1 ms: its float truncation
    can take a unit more, .999 -> .998999), in increasing order."""
    j = np.searchsorted(listing.times, truncated, side="left")
    inside = j < len(listing.times)
    late = listing.times[np.minimum(j, len(listing.times) - 1)] - truncated
    good = inside & (late >= np.timedelta64(0, "ns")) & (late < np.timedelta64(1100, "us"))
    if len(j) > 1:
        good[1:] &= np.diff(j) > 0
    if not good.all():
        bad = int(np.nonzero(~good)[0][0])
        raise DataError(f"georinex read an epoch at {truncated[bad]} that no epoch record of the file "
                        "gives (a damaged record?)", file=str(path))
    return listing.times[j]


def read_rinex_obs(path) -> RinexPseudoranges:
    """Read the GPS L1 C/A pseudoranges of a RINEX 2.x/3.x observation file.

    Raises
    ------
    DataError
        A file that is not a RINEX 2/3 observation file or georinex cannot read, one without
        ``C1C``/``C1`` for GPS in its header (naming the header line), with epoch times not in
        GPS time, or without any GPS pseudorange value, a damaged epoch record or times that
        do not increase (naming the line), a satellite name that is not a GPS PRN (naming
        the file).
    """
    import warnings

    import georinex as gr
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", file=str(path))
    listing = _listing(path)
    code = listing.code
    n_gps = listing.records.get("G", 0)
    if n_gps == 0:
        others = ", ".join(f"{s}: {n}" for s, n in sorted(listing.records.items())) or "none"
        raise DataError(f"no GPS satellite in the file's {listing.epochs} observation epochs "
                        f"(satellite records per system: {others})", file=str(path))
    try:
        with warnings.catch_warnings():   # georinex's per-epoch xarray concat warns of a future default
            warnings.simplefilter("ignore", FutureWarning)
            source = path if listing.observations_only is None else io.StringIO(listing.observations_only)
            ds = gr.load(source, use={"G"}, fast=False)   # fast: a size guess that can fail
    except Exception as exc:  # noqa: BLE001 - georinex raises many kinds for a damaged file
        raise DataError(f"not a readable RINEX observation file ({type(exc).__name__}: {exc})",
                        file=str(path)) from None
    if code not in getattr(ds, "data_vars", {}):
        raise DataError(f"no GPS {code} pseudorange in the file: the {code} column is blank at all {n_gps} "
                        "GPS satellite records", file=str(path))
    svs = [str(s) for s in ds.sv.values]
    values = np.asarray(ds[code].values, dtype=float)          # (time, sv)
    times = _full_times(np.asarray(ds.time.values).astype("datetime64[ns]"), listing, path)
    gps = np.array([s.startswith("G") for s in svs], dtype=bool)
    values = values[:, gps]
    bad = [s for s, g in zip(svs, gps) if g and not (len(s) == 3 and s[1:].isdigit() and 1 <= int(s[1:]) <= 32)]
    if bad:
        raise DataError(f"satellite name {bad[0]!r} is not a GPS PRN (G01-G32)", file=str(path))
    prns = np.array([int(s[1:]) for s, g in zip(svs, gps) if g], dtype=np.int64)
    ok = np.isfinite(values) & (values > 0)
    if not ok.any():
        raise DataError(f"no GPS {code} pseudorange in the file: the {code} column is blank or not positive at "
                        f"all {n_gps} GPS satellite records", file=str(path))
    rejected = {f"not GPS: {s}": n for s, n in sorted(listing.records.items()) if s != "G"}
    # an observation epoch with GPS records that georinex did not return (it silently lost
    # the epoch after a flag-5 record before those were removed): said and counted, not lost
    unread = (listing.gps > 0) & ~np.isin(listing.times, times)
    lost = int(listing.gps[unread].sum())
    if lost:
        first = int(listing.lines[np.flatnonzero(unread)[0]])
        warnings.warn(f"{path}: georinex did not read {int(unread.sum())} observation epochs with GPS records "
                      f"(the first at line {first}); their {lost} GPS records are counted as 'epoch not read'",
                      stacklevel=2)
        rejected["epoch not read"] = lost
    missing = n_gps - lost - int(ok.sum())   # blank (or zero) C1: georinex's NaN, or a record it dropped
    if missing > 0:
        rejected[f"no {code} pseudorange"] = missing
    # in integer ns: seconds since 1980 as a float would keep only 0.24 us
    since = (times - _GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64)
    week_ns = int(_WEEK) * 1_000_000_000
    week = since // week_ns
    tow = (since - week * week_ns) / 1e9
    keep = ok.any(axis=1)                       # epochs with at least one GPS pseudorange
    idx = np.cumsum(keep) - 1
    t_i, s_i = np.nonzero(ok)
    dcode = "D1C" if listing.version >= 3 else "D1"
    doppler = None
    if dcode in ds.data_vars:
        doppler = np.asarray(ds[dcode].values, dtype=float)[:, gps][t_i, s_i]
    return RinexPseudoranges(week=week[keep], tow=tow[keep], epoch=idx[t_i].astype(np.int64), prn=prns[s_i],
                             pseudorange=values[t_i, s_i], code=code, rejected=rejected,
                             epochs_all_rejected=max(listing.epochs - int(keep.sum()), 0),
                             version=listing.version, source=str(path), doppler=doppler,
                             event_records=dict(sorted(listing.events.items())))


@register_reader("raw-gnss", "rinex-obs")
def _read(path: Path, options: ReadOptions) -> RawPseudoranges:
    """The registered reader (no options)."""
    return read_rinex_obs(path)
