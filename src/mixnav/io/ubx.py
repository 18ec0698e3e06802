"""Pseudoranges, carrier phase, Doppler and C/N0 of GPS, GLONASS, Galileo, BeiDou and QZSS
from a binary u-blox log (``.ubx``): the receiver's UBX-RXM-RAWX messages, read here into
the same :class:`mixnav.data.RawPseudoranges` the RINEX reader gives, so a u-blox log needs
no conversion to RINEX (``raw_gnss.format = "ubx"``; :mod:`mixnav.io.rinex_obs` for RINEX).

The message layout, the GNSS and signal identifiers and the tracking-status bits are those
of the u-blox interface descriptions: *u-blox F9 HPG 1.32 Interface Description*
(UBX-22008968), section 1.5.4 "GNSS signal identifiers" and the UBX-RXM-RAWX message
(class 0x02, id 0x15: a 16-byte header ``rcvTow`` R8 [s], ``week`` U2, ``leapS`` I1,
``numMeas`` U1, ``recStat`` X1, ``version`` U1, 2 reserved bytes; then ``numMeas``
32-byte blocks ``prMes`` R8 [m], ``cpMes`` R8 [cycles], ``doMes`` R4 [Hz], ``gnssId``,
``svId``, ``sigId``, ``freqId`` U1, ``locktime`` U2 [ms], ``cno`` U1 [dB-Hz],
``prStdev``, ``cpStdev``, ``doStdev`` X1, ``trkStat`` X1, 1 reserved byte), and
*u-blox 8 / u-blox M8 Receiver Description* (UBX-13003221) for the M8 receivers, whose
RXM-RAWX has the same layout with ``sigId`` reserved (0: read as each system's first
signal below). pyubx2's message definition (``ubxtypes_get`` "RXM-RAWX") is the same.

What is read
------------
``gnssId`` -> system: 0 GPS ``G``, 2 Galileo ``E``, 3 BeiDou ``C``, 5 QZSS ``J``,
6 GLONASS ``R``; 1 SBAS, 4 IMES and 7 NavIC are counted (``rejected``: ``"system not
read: SBAS"``) and skipped. ``svId`` is the satellite number within its system (GLONASS:
the slot; ``svId`` 255, a GLONASS satellite whose slot is not known yet, is counted as
``"R slot unknown"``). ``sigId`` -> RINEX 3 observation code (:data:`SIGNAL_CODES`):

* GPS: 0 L1 C/A ``C1C``, 3 L2 CL ``C2L``, 4 L2 CM ``C2S``, 6 L5 I ``C5I``, 7 L5 Q ``C5Q``;
* GLONASS: 0 L1 OF ``C1C``, 2 L2 OF ``C2C``;
* Galileo: 0 E1 C ``C1C``, 1 E1 B ``C1B``, 3 E5a I ``C5I``, 4 E5a Q ``C5Q``, 5 E5b I
  ``C7I``, 6 E5b Q ``C7Q``;
* BeiDou: 0 B1I D1 and 1 B1I D2 ``C2I`` (RINEX 3.03 on; 3.02 wrote ``C1I``), 2 B2I D1 and
  3 B2I D2 ``C7I``, 5 B1C pilot ``C1P``, 6 B1C data ``C1D``, 7 B2a pilot ``C5P``, 8 B2a
  data ``C5D`` (5-8: the newer receivers' identifiers, as the u-blox X20 interface
  description lists them; no log of them is in the tests);
* QZSS: 0 L1 C/A ``C1C``, 1 L1S ``C1Z``, 4 L2 CM ``C2S``, 5 L2 CL ``C2L``, 8 L5 I ``C5I``,
  9 L5 Q ``C5Q``.

A ``sigId`` not listed is counted (``"unknown signal: <letter> sigId <n>"``) and skipped.
Per system one pseudorange signal is read, chosen as the RINEX reader chooses it: the
first code of the system's ``signals`` list (default
:data:`mixnav.gnss.signals.DEFAULT_SIGNALS` for RINEX 3: G ``C1C``, R ``C1C``, E ``C1C``
then ``C1X``, C ``C2I`` then ``C1I``, J ``C1C``) that the satellite has a valid
pseudorange of at that epoch. With it come the same signal's carrier phase (NaN where
``trkStat`` says the carrier is not valid), Doppler and C/N0 (``cno``, whole dB-Hz).

Validity and loss of lock (the rule RINEX converters such as RTKLIB's ``convbin`` follow):

* ``trkStat`` bit 0 (pseudorange valid) clear: the pseudorange is dropped. A satellite
  none of whose signals asked for has a valid, positive pseudorange is counted as
  ``"<letter> <codes> pseudorange not valid (trkStat)"`` when it has one of them flagged
  invalid, else as ``"no <letter> <codes> pseudorange"`` (the RINEX reader's key: GPS
  ``"no C1C pseudorange"``);
* ``trkStat`` bit 1 (carrier phase valid) clear: carrier phase NaN;
* loss-of-lock indicator (``lli``, RINEX bits, in the carrier-phase column as converters
  write it; 0 in the pseudorange, Doppler and C/N0 columns): bit 0 (lock lost, a cycle slip possible) when the signal's ``locktime``
  is 0, is less than at the signal's previous RXM-RAWX message (the lock was lost and
  regained in between), or is shorter, by more than :data:`LOCK_TOLERANCE` (10 ms), than
  the time since that previous message while below the 64500 ms at which u-blox
  receivers hold it (the lock was lost and regained during a gap in the signal's
  messages); the first message of a signal sets it only with ``locktime`` 0. Bit 1
  (half-cycle ambiguity) when the carrier is valid and ``trkStat`` bit 2 (half cycle
  valid) is clear; ``trkStat`` bit 3 (half cycle subtracted) is no RINEX flag and is not
  kept.

Times: ``rcvTow`` [s] and ``week`` are the receiver's GPS time of the measurements;
they become GPS week and seconds of week to the ns (``rcvTow`` rounded to the ns),
``leapS`` (GPS - UTC [s]) is kept per epoch in ``leap_seconds`` (NaN where ``recStat``
bit 0 says it is not determined yet). GLONASS frequency channels are ``freqId - 7``
(``glonass_channels``, slot -> k; a slot whose channel changes within the file is a
DataError).

How
---
:class:`pyubx2.UBXReader` frames the messages of the byte stream (UBX, NMEA, RTCM 3;
bytes between messages are skipped and counted, ``event_records["bytes skipped"]``);
every UBX frame's checksum is checked with pyubx2's ``calc_checksum``; the messages that
are not RXM-RAWX are counted by name in ``event_records`` (``"NAV-PVT"``, ``"NMEA"``,
``"RTCM3"``...) and not parsed. The RXM-RAWX payloads are decoded by numpy at once
(``decode="numpy"``, the default: a structured dtype of the layout above) or message by
message by :meth:`pyubx2.UBXReader.parse` (``decode="pyubx2"``, some 20 times slower:
the independent implementation, against which tests/test_ubx.py checks the numpy
decoding value for value).

Errors
------
A DataError names the file and the byte offset (and the 1-based message number) of: a
UBX frame with a bad checksum, an RXM-RAWX payload whose length is not ``16 + 32 *
numMeas``, a measurement's satellite number out of range, the same satellite and signal
twice in one message, epoch times that do not increase, a file without any RXM-RAWX
message (the messages it has are listed) or without a measurement of the systems asked
for. A message cut off by the end of the file (a log stopped while writing) is not an
error: it is skipped, counted (``event_records["truncated message at end"]``) and
warned about (:class:`mixnav.io.imu_checks.DataWarning`, naming its byte offset).
"""

from __future__ import annotations

import io
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

from ..data import GNSS_SYSTEMS, LLI_COLUMNS, RawPseudoranges
from ..errors import ArgumentError, DataError
from ..gnss.signals import DEFAULT_SIGNALS, DEFAULT_SYSTEMS, SYSTEMS, check_signals, check_systems
from .imu_checks import DataWarning
from .registry import ReadOptions, register_reader

#: UBX gnssId -> RINEX system letter, or the name of a system not read
GNSS_IDS: dict[int, str] = {0: "G", 1: "SBAS", 2: "E", 3: "C", 4: "IMES", 5: "J", 6: "R", 7: "NavIC"}

#: (RINEX system letter, UBX sigId) -> RINEX 3 pseudorange code (module docstring; u-blox F9
#: HPG 1.32 Interface Description, UBX-22008968, 1.5.4 "GNSS signal identifiers")
SIGNAL_CODES: dict[tuple[str, int], str] = {
    ("G", 0): "C1C", ("G", 3): "C2L", ("G", 4): "C2S", ("G", 6): "C5I", ("G", 7): "C5Q",
    ("R", 0): "C1C", ("R", 2): "C2C",
    ("E", 0): "C1C", ("E", 1): "C1B", ("E", 3): "C5I", ("E", 4): "C5Q", ("E", 5): "C7I", ("E", 6): "C7Q",
    ("C", 0): "C2I", ("C", 1): "C2I", ("C", 2): "C7I", ("C", 3): "C7I", ("C", 5): "C1P", ("C", 6): "C1D",
    ("C", 7): "C5P", ("C", 8): "C5D",
    ("J", 0): "C1C", ("J", 1): "C1Z", ("J", 4): "C2S", ("J", 5): "C2L", ("J", 8): "C5I", ("J", 9): "C5Q",
}

#: SIGNAL_CODES as a (gnssId, sigId) table ("" where none)
_CODE_TABLE = np.full((256, 256), "", dtype="<U3")
for (_letter, _sig), _code in SIGNAL_CODES.items():
    _CODE_TABLE[next(g for g, x in GNSS_IDS.items() if x == _letter), _sig] = _code

#: lock time [s] below which a signal seen again after a longer time is taken as re-locked
LOCK_TOLERANCE = 0.010
#: the lock time [ms] u-blox receivers stop counting at
LOCK_MAX_MS = 64500

#: UBX-RXM-RAWX: class and message id, header and measurement block layouts (little-endian)
RAWX_ID = b"\x02\x15"
HEADER = np.dtype([("rcvTow", "<f8"), ("week", "<u2"), ("leapS", "i1"), ("numMeas", "u1"), ("recStat", "u1"),
                   ("version", "u1"), ("reserved1", "u1", (2,))])
MEAS = np.dtype([("prMes", "<f8"), ("cpMes", "<f8"), ("doMes", "<f4"), ("gnssId", "u1"), ("svId", "u1"),
                 ("sigId", "u1"), ("freqId", "u1"), ("locktime", "<u2"), ("cno", "u1"), ("prStdev", "u1"),
                 ("cpStdev", "u1"), ("doStdev", "u1"), ("trkStat", "u1"), ("reserved3", "u1")])
assert HEADER.itemsize == 16 and MEAS.itemsize == 32

_WEEK_NS = 604800 * 1_000_000_000
_UBX_HDR = b"\xb5\x62"


def _name(raw: bytes) -> str:
    """The message's name for the counts: ``NAV-PVT`` (pyubx2's table), ``UBX-0x0310``
    when pyubx2 has no name for it, ``NMEA``, ``RTCM3``."""
    if raw[:2] == _UBX_HDR:
        from pyubx2.ubxtypes_core import UBX_MSGIDS
        return UBX_MSGIDS.get(raw[2:4], f"UBX-0x{raw[2:4].hex()}")
    return "NMEA" if raw[:1] == b"$" else "RTCM3"


def _frames(data: bytes, path: Path):
    """The messages of ``data``: (number (1-based), byte offset, raw bytes) of every UBX, NMEA
    and RTCM 3 message pyubx2 frames, and the counts of what is skipped (``bytes skipped``,
    ``truncated message at end``). A UBX frame whose checksum is wrong is a DataError."""
    from pyubx2 import UBXReader
    from pyubx2.ubxhelpers import calc_checksum
    stream = io.BytesIO(data)
    # parsing=False: frame only (pyubx2 would refuse message types it does not know);
    # quitonerror=0: an unknown protocol header (junk) is skipped, a truncated end seen below
    reader = UBXReader(stream, protfilter=7, quitonerror=0, validate=1, parsing=False)
    out, skipped, end, n = [], Counter(), 0, 0
    while True:
        raw, _ = reader.read()
        if raw is None:
            break
        stop = stream.tell()
        start = stop - len(raw)
        if start < end:       # pyubx2 gives no message twice; a guard, not a case
            raise DataError(f"byte {start}: messages overlap", file=str(path))
        n += 1
        if start > end:
            skipped["bytes skipped"] += start - end
        if raw[:2] == _UBX_HDR and raw[-2:] != calc_checksum(raw[2:-2]):
            raise DataError(f"byte {start} (message {n}, UBX {_name(raw)}, {len(raw)} bytes): checksum "
                            f"{raw[-2:].hex()} is wrong (the content gives {calc_checksum(raw[2:-2]).hex()}): "
                            "the file is damaged", file=str(path))
        out.append((n, start, raw))
        end = stop
    tail = data[end:]
    cut = tail.find(_UBX_HDR)
    if cut < 0 and tail.endswith(_UBX_HDR[:1]):     # cut after the first byte of a header
        cut = len(tail) - 1
    if cut >= 0:
        at = end + cut
        skipped["truncated message at end"] += 1
        if cut:
            skipped["bytes skipped"] += cut
        warnings.warn(f"{path}: byte {at}: the file ends inside a UBX message ({len(data) - at} of its bytes): "
                      "skipped (a log stopped while writing)", DataWarning, stacklevel=3)
    elif tail:
        skipped["bytes skipped"] += len(tail)
    return out, skipped


def _decode_numpy(raws: list, starts: list, numbers: list, path: Path):
    """The RXM-RAWX headers ((k,) HEADER) and measurements ((m,) MEAS) with each
    measurement's message index ((m,) int), decoded by numpy."""
    heads = np.empty(len(raws), HEADER)
    blocks = []
    for i, raw in enumerate(raws):
        payload = raw[6:-2]
        if len(payload) < HEADER.itemsize:
            raise DataError(f"byte {starts[i]} (message {numbers[i]}, RXM-RAWX): payload of {len(payload)} bytes, "
                            "shorter than the 16-byte header", file=str(path))
        heads[i] = np.frombuffer(payload, HEADER, count=1)[0]
        if len(payload) != HEADER.itemsize + MEAS.itemsize * int(heads[i]["numMeas"]):
            raise DataError(f"byte {starts[i]} (message {numbers[i]}, RXM-RAWX): payload of {len(payload)} bytes, "
                            f"not 16 + 32 * numMeas ({int(heads[i]['numMeas'])})", file=str(path))
        blocks.append(payload[HEADER.itemsize:])
    meas = np.frombuffer(b"".join(blocks), MEAS)
    which = np.repeat(np.arange(len(raws)), heads["numMeas"].astype(np.int64))
    return heads, meas, which


def _decode_pyubx2(raws: list, starts: list, numbers: list, path: Path):
    """As :func:`_decode_numpy`, each message parsed by :meth:`pyubx2.UBXReader.parse`."""
    from pyubx2 import UBXReader
    heads = np.zeros(len(raws), HEADER)
    rows = []
    for i, raw in enumerate(raws):
        try:
            msg = UBXReader.parse(raw, validate=1, msgmode=0, parsebitfield=1)
            h = heads[i]
            h["rcvTow"], h["week"], h["leapS"], h["numMeas"] = msg.rcvTow, msg.week, msg.leapS, msg.numMeas
            h["recStat"] = int(msg.leapSec) | int(msg.clkReset) << 1
            if len(raw) - 8 != HEADER.itemsize + MEAS.itemsize * msg.numMeas:
                raise ValueError(f"payload of {len(raw) - 8} bytes, not 16 + 32 * numMeas ({msg.numMeas})")
            for j in range(1, msg.numMeas + 1):
                g = {name: getattr(msg, f"{name}_{j:02d}") for name in
                     ("prMes", "cpMes", "doMes", "gnssId", "svId", "sigId", "freqId", "locktime", "cno",
                      "prStd", "cpStd", "doStd", "prValid", "cpValid", "halfCyc", "subHalfCyc")}
                trk = g["prValid"] | g["cpValid"] << 1 | g["halfCyc"] << 2 | g["subHalfCyc"] << 3
                rows.append((g["prMes"], g["cpMes"], g["doMes"], g["gnssId"], g["svId"], g["sigId"], g["freqId"],
                             g["locktime"], g["cno"], g["prStd"], g["cpStd"], g["doStd"], trk, 0, i))
        except Exception as exc:  # noqa: BLE001 - pyubx2 raises several kinds
            raise DataError(f"byte {starts[i]} (message {numbers[i]}, RXM-RAWX): {type(exc).__name__}: {exc}",
                            file=str(path)) from None
    meas = np.array([r[:-1] for r in rows], MEAS) if rows else np.empty(0, MEAS)
    which = np.array([r[-1] for r in rows], np.int64)
    return heads, meas, which


def _signals(systems: tuple, signals) -> dict:
    """Per system, the RINEX 3 codes to read, in order of preference."""
    asked = check_signals(signals)
    out = {}
    for s in systems:
        if s not in asked:
            out[s] = DEFAULT_SIGNALS[3][s]
            continue
        fit = tuple(c for c in asked[s] if len(c) == 3)
        if not fit:
            raise ArgumentError(f"{', '.join(asked[s])}: UBX signals are named by RINEX 3 codes (e.g. "
                                f"{DEFAULT_SIGNALS[3][s][0]})", f"signals.{s}")
        out[s] = fit
    return out


def loss_of_lock(key: np.ndarray, t_ns: np.ndarray, locktime: np.ndarray) -> np.ndarray:
    """Loss-of-lock bit 0 (bool) of each measurement (module docstring): ``key`` (m,) the
    signal (one value per satellite and signal), ``t_ns`` (m,) its epoch time [ns],
    ``locktime`` (m,) [ms]; the measurements in time order within each key."""
    key = np.asarray(key)
    lock = np.asarray(locktime, np.int64)
    order = np.lexsort((t_ns, key))
    k, t, lk = key[order], np.asarray(t_ns, np.int64)[order], lock[order]
    same = np.r_[False, k[1:] == k[:-1]]
    prev = np.r_[0, lk[:-1]]
    gap_ms = np.r_[0, np.diff(t)] / 1e6
    slip = lk == 0
    slip |= same & (lk < prev)
    slip |= same & (lk < LOCK_MAX_MS) & (lk < gap_ms - LOCK_TOLERANCE * 1e3)
    out = np.empty(len(k), bool)
    out[order] = slip
    return out


def read_ubx(path, systems=DEFAULT_SYSTEMS, signals=None, decode: str = "numpy") -> RawPseudoranges:
    """Read the pseudoranges, carrier phase, Doppler and C/N0 of the UBX-RXM-RAWX messages of
    a binary u-blox log (module docstring).

    Parameters
    ----------
    path : str or PathLike
    systems : iterable of str
        RINEX letters of the systems to read (``G``, ``R``, ``E``, ``C``, ``J``); default GPS.
    signals : dict or None
        System letter -> RINEX 3 pseudorange code or list of codes in order of preference
        (as :func:`mixnav.io.rinex_obs.read_rinex_obs`'s); a system not named takes its
        default (:data:`mixnav.gnss.signals.DEFAULT_SIGNALS`, RINEX 3).
    decode : {"numpy", "pyubx2"}
        How the RXM-RAWX payloads are decoded (same values; pyubx2 is slower).

    Returns
    -------
    RawPseudoranges
        As the RINEX reader's: ``week``, ``tow`` (k,); ``epoch``, ``prn``, ``system``,
        ``signal``, ``pseudorange`` [m], ``carrier`` [cycles], ``doppler`` [Hz], ``cn0``
        [dB-Hz], ``lli`` (m, 4) (m,); ``glonass_channels``; ``leap_seconds`` (k,);
        ``rejected`` (per reason), ``event_records`` (other messages, skipped bytes);
        ``code``: the codes read joined by ``/``; ``version`` 0.

    Raises
    ------
    ArgumentError
        An unknown system letter, signal code, or ``decode``.
    DataError
        Naming the file and the byte offset (module docstring, "Errors").
    """
    systems = check_systems(systems)
    asked = _signals(systems, signals)
    if decode not in ("numpy", "pyubx2"):
        raise ArgumentError(f"{decode!r}: give 'numpy' or 'pyubx2'", "decode")
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", file=str(path))
    data = path.read_bytes()
    frames, events = _frames(data, path)
    rawx = [(n, s, r) for n, s, r in frames if r[:2] == _UBX_HDR and r[2:4] == RAWX_ID]
    for _, _, r in frames:
        if not (r[:2] == _UBX_HDR and r[2:4] == RAWX_ID):
            events[_name(r)] += 1
    if not rawx:
        seen = ", ".join(f"{k}: {v}" for k, v in sorted(events.items())) or "nothing"
        raise DataError(f"no UBX-RXM-RAWX message (raw measurements) in the file's {len(frames)} messages "
                        f"({seen}): enable RXM-RAWX output on the receiver", file=str(path))
    numbers, starts, raws = (list(x) for x in zip(*rawx))
    heads, meas, which = (_decode_numpy if decode == "numpy" else _decode_pyubx2)(raws, starts, numbers, path)

    def where(i):
        return f"byte {starts[i]} (message {numbers[i]}, RXM-RAWX)"

    tow_bad = ~np.isfinite(heads["rcvTow"]) | (heads["rcvTow"] < 0) | (heads["rcvTow"] >= 604800.0)
    if tow_bad.any():
        j = int(np.flatnonzero(tow_bad)[0])
        raise DataError(f"{where(j)}: rcvTow {float(heads['rcvTow'][j])!r} is not a time of week (0 to 604800 s)",
                        file=str(path))
    # epoch times in integer ns (rcvTow rounded to the ns)
    t_ns = heads["week"].astype(np.int64) * _WEEK_NS + np.round(heads["rcvTow"] * 1e9).astype(np.int64)
    if len(t_ns) > 1 and np.any(np.diff(t_ns) <= 0):
        j = int(np.nonzero(np.diff(t_ns) <= 0)[0][0]) + 1
        raise DataError(f"{where(j)}: epoch time (week {int(heads['week'][j])}, rcvTow {heads['rcvTow'][j]:.9f} s) "
                        f"is not after the previous message's ({int(heads['week'][j - 1])}, "
                        f"{heads['rcvTow'][j - 1]:.9f} s)", file=str(path))
    letters_of = np.array([GNSS_IDS.get(g, f"gnssId {g}") for g in range(256)], dtype=object)
    sysname = letters_of[meas["gnssId"]]
    rejected: Counter = Counter()
    read = set(systems)
    only_gps = systems == ("G",)
    is_letter = np.isin(sysname, list(GNSS_SYSTEMS))
    sys_l = np.where(is_letter, sysname, "").astype("<U1")
    sv = meas["svId"].astype(np.int64)
    # satellites at an epoch (per system), for the counts
    sat_key = which * 1_000_000 + meas["gnssId"].astype(np.int64) * 1000 + sv
    _, sat_first = np.unique(sat_key, return_index=True)
    for s, n in Counter(sysname[sat_first].tolist()).items():
        if s not in read:
            rejected[(f"not GPS: {s}" if only_gps else f"system not read: {s}")] += n
    glo_unknown = (sys_l == "R") & (sv == 255)
    if "R" in read and glo_unknown.any():
        rejected["R slot unknown"] += int(len(np.unique(sat_key[glo_unknown])))
    keep = np.isin(sys_l, systems) & ~glo_unknown
    # satellite numbers
    top = np.where(sys_l == "G", 32, 99)
    bad = keep & ((sv < 1) | (sv > top))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataError(f"{where(int(which[i]))}: {SYSTEMS[sys_l[i]]} svId {sv[i]} is not a satellite number "
                        f"({'1-32' if sys_l[i] == 'G' else '1-99'})", file=str(path))
    codes = _CODE_TABLE[meas["gnssId"], meas["sigId"]]
    unknown = keep & (codes == "")
    for (s, g), n in Counter(zip(sys_l[unknown].tolist(), meas["sigId"][unknown].tolist())).items():
        rejected[f"unknown signal: {s} sigId {g}"] += n
    keep &= codes != ""
    # one satellite and signal twice in a message
    sig_key = sat_key * 256 + meas["sigId"].astype(np.int64)
    _, first = np.unique(sig_key[keep], return_index=True)
    if len(first) < int(keep.sum()):
        i = int(np.setdiff1d(np.arange(int(keep.sum())), first)[0])
        i = int(np.flatnonzero(keep)[i])
        raise DataError(f"{where(int(which[i]))}: {sys_l[i]}{sv[i]:02d} sigId {int(meas['sigId'][i])} is listed "
                        "twice", file=str(path))
    # loss of lock over every signal read (before choosing one per satellite)
    trk = meas["trkStat"]
    lock_key = (meas["gnssId"].astype(np.int64) * 1000 + sv) * 256 + meas["sigId"].astype(np.int64)
    slip = np.zeros(len(meas), bool)
    slip[keep] = loss_of_lock(lock_key[keep], t_ns[which[keep]], meas["locktime"][keep])
    pr = meas["prMes"]
    pr_ok = ((trk & 1) == 1) & np.isfinite(pr) & (pr > 0)
    # choose the signal per satellite and epoch: the first code of the system's list with a valid pseudorange
    rank = np.full(len(meas), 10**6)
    flagged = np.zeros(len(meas), bool)      # a code asked for, pseudorange flagged invalid
    for s in systems:
        for r, c in enumerate(asked[s]):
            hit = keep & (sys_l == s) & (codes == c)
            rank[hit & pr_ok] = np.minimum(rank[hit & pr_ok], r)
            flagged |= hit & ((trk & 1) == 0)
    cand = np.flatnonzero(rank < 10**6)
    order = cand[np.lexsort((rank[cand], sat_key[cand]))]
    chosen = order[np.r_[True, sat_key[order][1:] != sat_key[order][:-1]]] if len(order) else order
    got = np.zeros(len(meas), bool)
    got[chosen] = True
    for s in systems:   # satellites of a read system without a chosen pseudorange
        sys_sats = np.unique(sat_key[(sys_l == s) & ~glo_unknown])
        if not len(sys_sats):
            continue
        have = np.isin(sys_sats, sat_key[got])
        bad_flag = np.isin(sys_sats, sat_key[flagged & (sys_l == s)])
        codes_s = "/".join(asked[s])
        n_flag = int((~have & bad_flag).sum())
        n_none = int((~have & ~bad_flag).sum())
        if n_flag:
            rejected[f"{s} {codes_s} pseudorange not valid (trkStat)"] += n_flag
        if n_none:
            rejected[f"no {'' if s == 'G' else s + ' '}{codes_s} pseudorange"] += n_none
    if not len(chosen):
        names = ", ".join(SYSTEMS[s] for s in systems)
        raise DataError(f"no {names} pseudorange of the signals asked for "
                        f"({'; '.join(f'{s}: ' + '/'.join(asked[s]) for s in systems)}) in the file's "
                        f"{len(raws)} RXM-RAWX messages (rejected: {dict(rejected) or 'none'})", file=str(path))
    # GLONASS channels (freqId - 7) of the slots read
    channels: dict[int, int] = {}
    glo = keep & (sys_l == "R")
    for slot in np.unique(sv[chosen][sys_l[chosen] == "R"]):
        rows = np.flatnonzero(glo & (sv == slot))
        k = meas["freqId"][rows].astype(np.int64) - 7
        odd = np.flatnonzero((k != k[0]) | (k < -7) | (k > 6))
        if len(odd):
            i = int(rows[odd[0]])
            why = (f"freqId {int(meas['freqId'][i])} is outside 0-13 (channel -7..6)" if k[odd[0]] == k[0]
                   else f"frequency channel (freqId - 7) {int(k[odd[0]])}, earlier {int(k[0])}")
            raise DataError(f"{where(int(which[i]))}: GLONASS slot {slot}: {why}", file=str(path))
        channels[int(slot)] = int(k[0])
    # order: epoch, system (G R E C J), satellite
    srank = np.zeros(len(meas), np.int64)
    for i, s in enumerate(GNSS_SYSTEMS):
        srank[sys_l == s] = i
    sel = chosen[np.lexsort((sv[chosen], srank[chosen], which[chosen]))]
    ep = which[sel]
    has = np.zeros(len(raws), bool)
    has[ep] = True
    idx = np.cumsum(has) - 1
    week = t_ns[has] // _WEEK_NS
    tow = (t_ns[has] - week * _WEEK_NS) / 1e9
    m = meas[sel]
    cp_ok = (m["trkStat"] & 2) == 2
    carrier = np.where(cp_ok & np.isfinite(m["cpMes"]), m["cpMes"], np.nan)
    lli = np.zeros((len(sel), len(LLI_COLUMNS)), np.int8)     # on the carrier phase, as converters write it
    lli[:, LLI_COLUMNS.index("carrier")] = slip[sel] | ((cp_ok & ((m["trkStat"] & 4) == 0)).astype(np.int8) << 1)
    leap = np.where((heads["recStat"][has] & 1) == 1, heads["leapS"][has].astype(float), np.nan)
    signal = codes[sel]
    return RawPseudoranges(
        week=week, tow=tow, epoch=idx[ep].astype(np.int64), prn=sv[sel], pseudorange=m["prMes"].astype(float),
        code="/".join(dict.fromkeys(signal.tolist())), rejected=dict(sorted(rejected.items())),
        epochs_all_rejected=int(len(raws) - has.sum()), version=0.0, source=str(path),
        doppler=np.where(np.isfinite(m["doMes"]), m["doMes"], np.nan).astype(float), cn0=m["cno"].astype(float), event_records=dict(sorted(events.items())),
        system=sys_l[sel], signal=signal, carrier=carrier,
        lli=lli,
        glonass_channels=dict(sorted(channels.items())), leap_seconds=leap)


@register_reader("raw-gnss", "ubx")
def _read(path: Path, options: ReadOptions) -> RawPseudoranges:
    """The registered reader: ``systems`` and ``signals`` from the dataset's ``[raw_gnss]``
    table (defaults: GPS, :data:`mixnav.gnss.signals.DEFAULT_SIGNALS`)."""
    return read_ubx(path, systems=options.get("systems", DEFAULT_SYSTEMS), signals=options.get("signals"))
