"""Pseudoranges, carrier phase, Doppler and C/N0 of GPS, GLONASS, Galileo, BeiDou and QZSS
from a RINEX observation file (2.x or 3.x, mixed files), read here into arrays.

Any receiver whose data RTKLIB's ``convbin`` (or the maker's tool) converts to RINEX
can then be processed by single-point positioning like a phone log
(:mod:`mixnav.experiment.spp_process`, ``raw_gnss.format = "rinex-obs"``) or by the
tightly coupled INS (:mod:`mixnav.experiment.rinex_ins`).

What is read
------------
The ``systems`` asked for (RINEX letters, default GPS alone: ``("G",)``, what this reader
always gave) and, per system, one pseudorange signal: the first code of the system's
list in ``signals`` (or of :data:`mixnav.gnss.signals.DEFAULT_SIGNALS`) that the satellite
record has a positive value of: RINEX 3 G ``C1C``; R ``C1C``; E ``C1C`` then ``C1X``;
C ``C2I`` then ``C1I`` (RINEX 3.02 wrote B1I as ``C1I``, 3.03 on as ``C2I``); J ``C1C``;
RINEX 2 ``C1`` (BeiDou ``C2`` then ``C1``), ``P1`` when asked for. With the pseudorange
come the same signal's carrier phase, Doppler and C/N0 (``L1C``, ``D1C``, ``S1C``; RINEX 2
``L1``, ``D1``, ``S1``) and the loss-of-lock indicator of each of the four values.
Measurements are ordered by epoch, then system (G R E C J), then satellite number.
GLONASS frequency channel numbers come from the header's ``GLONASS SLOT / FRQ #``
when it has them (else :meth:`mixnav.data.RawPseudoranges.with_glonass_channels`
attaches the navigation file's).

Epoch times are those the epoch records give, to the ns, in GPS time (a header
declaring another time system is refused), as GPS week and seconds of week.

How
---
The file (gzip, bzip2 or Hatanaka-compressed as georinex opens them) is walked once,
header and epoch records (:func:`_listing`), and every satellite record of the systems
read is cut into its 16-character observation fields (``F14.3``, loss-of-lock
indicator, signal strength), which numpy parses at once (:func:`_fields`): a value
written as RINEX's ``F14.3`` is its integer of thousandths divided by 1000, the same
double as Python's ``float`` of the text; any other number is parsed by ``float``.
georinex, the independent implementation, gives the same value for every system,
signal and epoch (tests/test_rinex_multi.py) and is several hundred times slower
(benchmarks/results/rinex_read.md: 40 s of CPU against 0.12 s on a 3.7 MB mixed file).

Nothing passes over silently: every satellite record of every observation epoch is
counted per system letter; records of systems not read are reported in ``rejected``
(``"not GPS: <letter>"`` when GPS alone is read, else ``"system not read: <letter>"``),
records without a usable (blank or zero) pseudorange as ``"no C1C pseudorange"`` (GPS;
the codes asked for that the header lists, joined by ``/``; another system with its
letter: ``"no E C1C/C1X pseudorange"``),
epochs without any in ``epochs_all_rejected`` (the SPP's epoch status ``all
measurements rejected``); event and cycle-slip records (flags 2-6) are skipped and
counted per flag in ``event_records``. A damaged header, epoch record or observation
field, records whose values do not fit the header's observation types, a satellite
listed twice in an epoch, or a signal asked for that the header does not list is a
:class:`DataError` naming the file and line.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from math import ceil
from pathlib import Path

import numpy as np

from ..data import GNSS_SYSTEMS, LLI_COLUMNS, RawPseudoranges
from ..errors import ArgumentError, DataError
from ..gnss.signals import DEFAULT_SYSTEMS, SYSTEMS, check_signals, check_systems, companions, signals_for
from .registry import ReadOptions, register_reader

#: GPS time origin (1980-01-06 00:00:00) as numpy datetime64
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
_WEEK = 604800.0
#: characters of one observation field (F14.3, loss-of-lock indicator, signal strength)
_FIELD = 16
#: observation fields per line of a RINEX 2 satellite record
_PER_LINE2 = 5

#: the one raw-GNSS type (fields: mixnav.data.RawPseudoranges); RINEX gives doppler, carrier,
#: cn0, lli, system, signal, line, code, version, event_records and glonass_channels
RinexPseudoranges = RawPseudoranges


@dataclass
class _Listing:
    """What the header and epoch records of a RINEX observation file list, and the
    observation fields of the satellite records of the systems read."""

    version: float
    first: int                 # 1-based line of RINEX VERSION / TYPE
    types: dict                # system letter (RINEX 2: " ", every system) -> observation types
    type_line: dict            # its first header line (1-based)
    records: Counter           # satellite records of observation epochs, per system letter
    times: np.ndarray          # (epochs,) datetime64[ns]: observation epochs (flag 0 or 1), as written
    lines: np.ndarray          # (epochs,) their line numbers (1-based)
    events: Counter            # records of other flags (events, cycle slips), per flag
    glonass: dict              # GLONASS slot -> frequency channel (header)
    rec_epoch: np.ndarray      # (R,) epoch index of each satellite record read
    rec_system: np.ndarray     # (R,) its system letter
    rec_prn: np.ndarray        # (R,) its satellite number
    rec_line: np.ndarray       # (R,) 1-based line of its first observation field
    width: int                 # observation fields per record in ``text``
    text: bytes                # R * width * 16 characters: each record's fields, blank-padded

    @property
    def epochs(self) -> int:
        return len(self.times)

    def field_line(self, r: int, t: int) -> int:
        """The 1-based line of record ``r``'s observation field ``t``."""
        return int(self.rec_line[r]) + (t // _PER_LINE2 if self.version < 3 else 0)


def _int(text: str, what: str, path: Path, lineno: int) -> int:
    try:
        return int(text)
    except ValueError:
        raise DataError(f"{what} {text.strip()!r} is not an integer", file=str(path), line=lineno) from None


def _epoch_time(ln: str, version: float, path: Path, lineno: int) -> np.datetime64:
    """The epoch record's time to the ns."""
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
    """The ``n`` satellite names a RINEX 2 epoch line (or its continuation) lists."""
    names = [ln[32 + 3 * i:35 + 3 * i] for i in range(n)]
    if any(len(s) < 3 or not s[1:].strip().isdigit() for s in names):
        raise DataError(f"the epoch record's satellite list does not hold {n} satellite names (letter and "
                        "2 digits)", file=str(path), line=lineno)
    return names


def _count(text: str, path: Path, lineno: int) -> int:
    n = _int(text, "number of satellites", path, lineno)
    if n < 0:
        raise DataError(f"number of satellites {n} is negative", file=str(path), line=lineno)
    return n


def _text_lines(path: Path) -> list:
    from georinex.rio import opener   # reads gzip / bzip2 / Hatanaka as georinex does
    try:
        with opener(path) as fh:
            return fh.read().splitlines()
    except Exception as exc:  # noqa: BLE001 - a damaged compressed file raises many kinds
        raise DataError(f"cannot be read as text ({type(exc).__name__}: {exc})", file=str(path)) from None


def _glonass_slots(body: str, path: Path, lineno: int, out: dict) -> None:
    """Add a ``GLONASS SLOT / FRQ #`` line's slot -> channel pairs (``R01  1``) to ``out``."""
    for i in range(4, 60, 7):
        cell = body[i:i + 7]
        if not cell.strip():
            continue
        name, k = cell[:3], cell[3:7].strip()
        if name[:1] != "R" or not name[1:].strip().isdigit():
            raise DataError(f"GLONASS SLOT / FRQ #: {cell.strip()!r} is not a slot and a channel ('R01  1')",
                            file=str(path), line=lineno)
        k = _int(k, "GLONASS frequency channel", path, lineno)
        if not -7 <= k <= 6:
            raise DataError(f"GLONASS SLOT / FRQ #: channel {k} of {name} is outside -7..6", file=str(path),
                            line=lineno)
        out[int(name[1:])] = k


def _header(lines: list, path: Path):
    """The header of a RINEX 2/3 observation file: (version, its line, index of the first
    line after END OF HEADER, types, type_line, glonass channels)."""
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
    glonass: dict[int, int] = {}
    k = first + 1
    sys = ""
    label3, label2 = "SYS / # / OBS TYPES", "# / TYPES OF OBSERV"
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
        if version < 3 and label == label2:
            if body[:6].strip():       # a continuation line leaves the count blank
                sys = " "
                n_types[sys] = _int(body[:6], "number of observation types", path, k)
                type_line.setdefault(sys, k)
            types.setdefault(" ", []).extend(body[6:].split())
        elif version >= 3 and label == label3:
            if body[:1].strip():
                sys = body[:1]
                n_types[sys] = _int(body[3:6], "number of observation types", path, k)
                type_line.setdefault(sys, k)
            if not sys:
                raise DataError(f"{label3} continuation without a system letter", file=str(path), line=k)
            types.setdefault(sys, []).extend(body[6:].split())
        elif label == "GLONASS SLOT / FRQ #":
            _glonass_slots(body, path, k, glonass)
    for sy, listed in types.items():
        if n_types.get(sy) != len(listed):
            raise DataError(f"the header's {label2 if version < 3 else label3} line declares "
                            f"{n_types.get(sy, 'no number of')} observation types{'' if version < 3 else ' for ' + sy} "
                            f"but lists {len(listed)}", file=str(path), line=type_line.get(sy))
    return version, first + 1, k, types, type_line, glonass


def _listing(lines: list, path: Path, systems: tuple, header: tuple) -> _Listing:
    """Walk the epoch records of the file's ``lines`` after its ``header`` (:func:`_header`),
    and cut the observation fields of the satellite records of ``systems`` (letters).

    Raises DataError (file and line) for a file that is not a RINEX 2/3 observation file, a
    line that is not an epoch record where one must be, a satellite record whose values
    run past the header's observation types, or a satellite number that is not one.
    """
    version, first, k, types, type_line, glonass = header
    rinex3 = version >= 3
    ntypes = {s: len(types.get(s if rinex3 else " ", [])) for s in systems}
    width = max(ntypes.values(), default=0)
    per_sat = ceil(len(types.get(" ", [])) / _PER_LINE2)  # RINEX 2: lines per satellite record
    chars = {s: n * _FIELD for s, n in ntypes.items()}
    pad = width * _FIELD
    records: Counter = Counter()
    events: Counter = Counter()
    times, at = [], []
    r_epoch, r_sys, r_prn, r_line, text = [], [], [], [], []
    read = set(systems)

    def take(letter, name, body, lineno, rec_lines):
        """Keep the satellite record ``name`` of a system read: its fields ``body``."""
        n = chars[letter]
        if len(body) > n and body[n:].strip():
            j = len(body) - len(body[n:].lstrip())
            extra = rec_lines[min(j // (_PER_LINE2 * _FIELD), len(rec_lines) - 1)] if not rinex3 else lineno
            raise DataError(f"satellite {name}: values beyond the header's {ntypes[letter]} observation types "
                            f"(line {type_line.get(letter if rinex3 else ' ')}) for {SYSTEMS[letter]}",
                            file=str(path), line=extra)
        num = name[1:3].strip()
        if not num.isdigit() or not 1 <= int(num) <= (32 if letter == "G" else 99):
            what = "a GPS PRN (G01-G32)" if letter == "G" else "a satellite number (01-99)"
            raise DataError(f"satellite name {name!r} is not {what}", file=str(path), line=lineno)
        r_epoch.append(len(times))
        r_sys.append(letter)
        r_prn.append(int(num))
        r_line.append(rec_lines[0] if rec_lines else lineno)
        text.append(body[:n].ljust(pad))

    while k < len(lines):
        ln = lines[k]
        k += 1
        start = k
        if not ln.strip():
            continue
        if rinex3:
            if not ln.startswith(">"):
                raise DataError("an epoch record ('> yyyy mm dd ...') was expected", file=str(path), line=k)
            flag = _int(ln[31:32] or "0", "epoch flag", path, k)
            n = _count(ln[32:35], path, k)
            if k + n > len(lines):
                raise DataError(f"the file ends inside an epoch record of {n} satellites", file=str(path),
                                line=len(lines))
            if flag in (0, 1):
                for j, rec in enumerate(lines[k:k + n]):
                    letter = rec[:1]
                    if not letter.strip():
                        raise DataError("a satellite record (system letter and number) was expected",
                                        file=str(path), line=k + j + 1)
                    records[letter] += 1
                    if letter in read:
                        take(letter, rec[:3], rec[3:], k + j + 1, None)
            k += n
        else:
            if len(ln) < 32 or not ln[26:29].strip().isdigit():
                raise DataError("an epoch record (' yy mm dd hh mm ss.sssssss  f nnn') was expected",
                                file=str(path), line=k)
            flag = _int(ln[28:29], "epoch flag", path, k)
            n = _count(ln[29:32], path, k)
            if flag in (0, 1, 6):        # satellite list (12 a line), then per_sat lines each
                names = _names(ln, min(n, 12), path, k)
                for _ in range(ceil(n / 12) - 1):
                    cont = lines[k] if k < len(lines) else ""
                    k += 1
                    names += _names(cont, min(n - len(names), 12), path, k)
                if k + n * per_sat > len(lines):
                    raise DataError(f"the file ends inside an epoch record of {n} satellites", file=str(path),
                                    line=len(lines))
                if flag != 6:            # cycle-slip records: not observations
                    for j, name in enumerate(names):
                        letter = "G" if name[0] == " " else name[0]   # a blank system letter is GPS
                        records[letter] += 1
                        if letter in read:
                            a = k + j * per_sat
                            rec = lines[a:a + per_sat]
                            if any(len(x) > _PER_LINE2 * _FIELD and x[_PER_LINE2 * _FIELD:].strip() for x in rec):
                                j2 = next(i for i, x in enumerate(rec) if x[_PER_LINE2 * _FIELD:].strip())
                                raise DataError(f"satellite {name}: a line longer than {_PER_LINE2} observation "
                                                "fields", file=str(path), line=a + j2 + 1)
                            body = "".join(x.ljust(_PER_LINE2 * _FIELD) for x in rec)
                            take(letter, letter + name[1:], body, start, list(range(a + 1, a + 1 + per_sat)))
                k += n * per_sat
            else:                        # events: n header records follow
                if k + n > len(lines):
                    raise DataError(f"the file ends inside an epoch record of {n} records", file=str(path),
                                    line=len(lines))
                k += n
        if flag in (0, 1):
            at.append(start)
            times.append(_epoch_time(lines[start - 1], version, path, start))
        else:
            events[f"flag {flag}"] += 1
    t = np.array(times, dtype="datetime64[ns]")
    if len(t) > 1 and np.any(np.diff(t) <= np.timedelta64(0, "ns")):
        j = int(np.nonzero(np.diff(t) <= np.timedelta64(0, "ns"))[0][0]) + 1
        raise DataError(f"epoch times do not increase ({t[j]} after {t[j - 1]})", file=str(path), line=at[j])
    return _Listing(version=version, first=first, types=types, type_line=type_line, records=records, times=t,
                    lines=np.array(at, dtype=np.int64), events=events, glonass=glonass,
                    rec_epoch=np.array(r_epoch, dtype=np.int64), rec_system=np.array(r_sys, dtype="<U1"),
                    rec_prn=np.array(r_prn, dtype=np.int64), rec_line=np.array(r_line, dtype=np.int64),
                    width=width, text="".join(text).encode("ascii", "replace"))


#: place values of a F14.3 field's 14 characters in thousandths (the '.' at index 10 counts 0)
_PLACES = np.array([10 ** (12 - i) for i in range(10)] + [0, 100, 10, 1], dtype=np.int64)
_NUMBER_CHARS = set("0123456789+-.eE ")


def _fields(listing: _Listing, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The observation values ((R, width) float, NaN where blank) and loss-of-lock
    indicators ((R, width) int8, 0 where blank) of the listing's records.

    A field written as ``F14.3`` (blanks, an optional minus sign and digits, the point at
    the 11th character, 3 digits) is parsed in numpy: its integer N of thousandths is
    exact, and N / 1000 is the double nearest the decimal, as ``float(text)`` gives. Other
    numbers are parsed by ``float``; text that is no finite number, or a loss-of-lock or
    signal-strength character that is neither blank nor a digit, is a DataError naming the
    file and line.
    """
    n_rec, width = len(listing.rec_epoch), listing.width
    raw = np.frombuffer(listing.text, dtype=np.uint8).reshape(n_rec, width, _FIELD)
    num = raw[..., :14]
    blank = (num == 32).all(axis=-1)
    digit = (num >= 48) & (num <= 57)
    head = num[..., :10]
    kind = np.where(head == 32, 0, np.where(head == 45, 1, np.where(digit[..., :10], 2, 3))).astype(np.int8)
    plain = (~blank & (np.diff(kind, axis=-1) >= 0).all(axis=-1) & (kind < 3).all(axis=-1)
             & (num[..., 10] == 46) & digit[..., 11:].all(axis=-1))
    neg = (kind == 1).any(axis=-1)
    thousandths = np.where(digit, num.astype(np.int64) - 48, 0) @ _PLACES
    values = np.where(plain, np.where(neg, -(thousandths / 1000.0), thousandths / 1000.0), np.nan)
    for r, t in zip(*np.nonzero(~blank & ~plain)):   # numbers written otherwise (rare)
        s = raw[r, t, :14].tobytes().decode("ascii", "replace")
        try:
            if not set(s) <= _NUMBER_CHARS:
                raise ValueError(s)
            v = float(s)
            if not np.isfinite(v):
                raise ValueError(s)
        except ValueError:
            raise DataError(f"observation {t + 1} of satellite {listing.rec_system[r]}{listing.rec_prn[r]:02d}: "
                            f"{s.strip()!r} is not a number", file=str(path), line=listing.field_line(r, t)) from None
        values[r, t] = v
    flags = raw[..., 14:16]
    bad = ~((flags == 32) | ((flags >= 48) & (flags <= 57)))
    if bad.any():
        r, t, f = (int(i) for i in np.argwhere(bad)[0])
        raise DataError(f"observation {t + 1} of satellite {listing.rec_system[r]}{listing.rec_prn[r]:02d}: its "
                        f"{'loss-of-lock indicator' if f == 0 else 'signal strength'} "
                        f"{chr(flags[r, t, f])!r} is not a digit", file=str(path), line=listing.field_line(r, t))
    lli = np.where(flags[..., 0] == 32, 0, flags[..., 0].astype(np.int16) - 48).astype(np.int8)
    return values, lli


def _signal_columns(header: tuple, systems: tuple, signals, path: Path) -> list:
    """Per system read, its signals in order of preference as ``(system, code, columns)``:
    the columns of the code, carrier, Doppler and C/N0 among the system's observation
    types in the ``header`` (:func:`_header`; -1: not listed). A system without observation
    types, or without any of its codes asked for, is a DataError naming the header line."""
    version, first, _, types, type_line, _ = header
    try:
        asked = signals_for(version, systems, signals)
    except ArgumentError as exc:
        raise DataError(f"{exc.argument}: {exc.message}", file=str(path), line=first) from None
    rinex3 = version >= 3
    label = "SYS / # / OBS TYPES" if rinex3 else "# / TYPES OF OBSERV"
    out = []
    for s in systems:
        key = s if rinex3 else " "
        codes = asked[s]
        need = " or ".join(codes)
        if key not in types:
            if not rinex3:
                raise DataError(f"the header has no {label} line", file=str(path))
            name = "GPS" if s == "G" else SYSTEMS[s]
            raise DataError(f"no {name} observation types: the header's {label} lines list the systems "
                            f"{', '.join(sorted(types)) or 'none'} ({s} with {need} is needed)",
                            file=str(path), line=min(type_line.values(), default=None))
        listed = types[key]
        present = [c for c in codes if c in listed]
        if not present:
            what = "L1 C/A pseudorange" if codes in (("C1C",), ("C1",)) and s == "G" else \
                f"{SYSTEMS[s]} pseudorange of the signals asked for"
            whose = "every system" if not rinex3 else ("GPS" if s == "G" else SYSTEMS[s])
            raise DataError(f"no {what}: the header's {label} lists {' '.join(listed) or 'nothing'} for {whose} "
                            f"({need} is needed)", file=str(path), line=type_line.get(key))
        for c in present:
            cols = [listed.index(x) if x in listed else -1 for x in (c, *companions(c))]
            out.append((s, c, cols))
    return out


def read_rinex_obs(path, systems=DEFAULT_SYSTEMS, signals=None) -> RinexPseudoranges:
    """Read the pseudoranges, carrier phase, Doppler and C/N0 of a RINEX 2.x/3.x observation
    file (module docstring).

    Parameters
    ----------
    path : str or PathLike
    systems : iterable of str
        RINEX letters of the systems to read (``G``, ``R``, ``E``, ``C``, ``J``); default GPS.
    signals : dict or None
        System letter -> pseudorange code or list of codes in order of preference, RINEX 3
        (``C1C``) and/or RINEX 2 (``C1``); a system not named takes its default
        (:data:`mixnav.gnss.signals.DEFAULT_SIGNALS`).

    Returns
    -------
    RawPseudoranges
        ``k`` epochs with at least one pseudorange, ``m`` measurements: ``week``, ``tow``
        (k,) [s]; ``epoch``, ``prn``, ``system``, ``signal``, ``pseudorange`` [m],
        ``carrier`` [cycles], ``doppler`` [Hz], ``cn0`` [dB-Hz] (each (m,); the last three
        None when the header lists no such type for the signals read, NaN where blank),
        ``lli`` (m, 4), ``line`` (m,); ``code``: the codes read joined by ``/``.

    Raises
    ------
    ArgumentError
        An unknown system letter (``systems``) or signal code (``signals.<letter>``).
    DataError
        A file that is not a RINEX 2/3 observation file, a header without the observation
        types of a system asked for or without any of its signals (naming the header line),
        a signal list with no code of the file's RINEX version, epoch times not in GPS
        time, no measurement of the systems asked for, a damaged epoch record or
        observation field, values beyond the header's types, a satellite listed twice in an
        epoch, times that do not increase (naming the line).
    """
    systems = check_systems(systems)
    check_signals(signals)
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", file=str(path))
    lines = _text_lines(path)
    header = _header(lines, path)
    sigs = _signal_columns(header, systems, signals, path)
    listing = _listing(lines, path, systems, header)
    names = ", ".join(SYSTEMS[s] for s in systems)
    n_read = sum(listing.records.get(s, 0) for s in systems)
    if n_read == 0:
        others = ", ".join(f"{s}: {n}" for s, n in sorted(listing.records.items())) or "none"
        raise DataError(f"no {names} satellite in the file's {listing.epochs} observation epochs "
                        f"(satellite records per system: {others})", file=str(path))
    values, lli = _fields(listing, path)
    rows = np.arange(len(listing.rec_epoch))
    rank = np.zeros(len(rows), dtype=np.int64)      # G R E C J
    for i, s in enumerate(GNSS_SYSTEMS):
        rank[listing.rec_system == s] = i
    # a satellite twice in one epoch
    _, first = np.unique((listing.rec_epoch * len(GNSS_SYSTEMS) + rank) * 100 + listing.rec_prn, return_index=True)
    if len(first) < len(rows):
        r = int(np.setdiff1d(rows, first)[0])
        raise DataError(f"satellite {listing.rec_system[r]}{listing.rec_prn[r]:02d} is listed twice in the epoch "
                        f"of line {listing.lines[listing.rec_epoch[r]]}", file=str(path), line=int(listing.rec_line[r]))
    chosen = np.full(len(rows), -1)
    for i, (s, _, cols) in enumerate(sigs):
        v = values[:, cols[0]]
        chosen[(chosen < 0) & (listing.rec_system == s) & np.isfinite(v) & (v > 0)] = i
    ok = chosen >= 0
    codes = list(dict.fromkeys(c for s, c, _ in sigs))
    if not ok.any():
        code = "/".join(codes)
        raise DataError(f"no {names} {code} pseudorange in the file: the {code} column is blank or not positive at "
                        f"all {n_read} {names} satellite records", file=str(path))
    only_gps = systems == ("G",)
    rejected = {(f"not GPS: {s}" if only_gps else f"system not read: {s}"): n
                for s, n in sorted(listing.records.items()) if s not in systems}
    for s in systems:
        missing = listing.records.get(s, 0) - int((ok & (listing.rec_system == s)).sum())
        if missing > 0:
            rejected[f"no {'' if s == 'G' else s + ' '}{'/'.join(c for x, c, _ in sigs if x == s)} pseudorange"] = missing
    sel = np.lexsort((listing.rec_prn, rank, listing.rec_epoch))
    sel = sel[ok[sel]]
    which = chosen[sel]

    def column(j):
        """Values and loss-of-lock indicators of column j (0 code, 1 carrier, 2 Doppler,
        3 C/N0) of each measurement's signal; None when no signal read lists it."""
        cols = np.array([c[2][j] for c in sigs])
        if (cols < 0).all():
            return None, np.zeros(len(sel), dtype=np.int8)
        col = cols[which]
        there = col >= 0
        v = np.where(there, values[sel, np.maximum(col, 0)], np.nan)
        return v, np.where(there, lli[sel, np.maximum(col, 0)], 0).astype(np.int8)

    got = [column(j) for j in range(len(LLI_COLUMNS))]
    epochs = listing.rec_epoch[sel]
    keep = np.zeros(listing.epochs, dtype=bool)
    keep[epochs] = True
    idx = np.cumsum(keep) - 1
    # in integer ns: seconds since 1980 as a float would keep only 0.24 us
    since = (listing.times[keep] - _GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64)
    week_ns = int(_WEEK) * 1_000_000_000
    week = since // week_ns
    tow = (since - week * week_ns) / 1e9
    sig_codes = np.array([c for _, c, _ in sigs])
    return RinexPseudoranges(week=week, tow=tow, epoch=idx[epochs].astype(np.int64), prn=listing.rec_prn[sel],
                             pseudorange=got[0][0], code="/".join(dict.fromkeys(sig_codes[which].tolist())),
                             rejected=rejected, epochs_all_rejected=listing.epochs - int(keep.sum()),
                             version=listing.version, source=str(path), doppler=got[2][0], cn0=got[3][0],
                             event_records=dict(sorted(listing.events.items())), system=listing.rec_system[sel],
                             signal=sig_codes[which], carrier=got[1][0], lli=np.stack([g[1] for g in got], axis=1),
                             line=listing.rec_line[sel], glonass_channels=dict(sorted(listing.glonass.items())))


@register_reader("raw-gnss", "rinex-obs")
def _read(path: Path, options: ReadOptions) -> RawPseudoranges:
    """The registered reader: ``systems`` and ``signals`` from the dataset's ``[raw_gnss]``
    table (defaults: GPS, :data:`mixnav.gnss.signals.DEFAULT_SIGNALS`)."""
    return read_rinex_obs(path, systems=options.get("systems", DEFAULT_SYSTEMS), signals=options.get("signals"))
