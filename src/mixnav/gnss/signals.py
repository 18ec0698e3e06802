"""GNSS systems and the RINEX codes of their pseudorange signals.

The raw-GNSS readers (:mod:`mixnav.io.rinex_obs`) and the dataset schema
(``[raw_gnss] systems`` and ``signals``) share these tables, so a code the config
accepts is one the reader knows.

A system is its RINEX letter (:data:`SYSTEMS`). A pseudorange signal is its RINEX
observation code: RINEX 3 ``C`` + band digit + tracking attribute (``C1C``, ``C1X``,
``C2I``); RINEX 2 ``C`` or ``P`` + band digit (``C1``, ``P1``, ``C2``). The carrier
phase, Doppler and C/N0 of a signal are the codes with ``L``, ``D`` and ``S`` in place
of the ``C`` (:func:`companions`; RINEX 2's ``P1`` has ``L1``, ``D1``, ``S1``).
"""

from __future__ import annotations

from ..data import GNSS_SYSTEMS
from ..errors import ArgumentError

#: the systems read: RINEX letter -> name (the letters of mixnav.data.GNSS_SYSTEMS)
SYSTEMS: dict[str, str] = dict(zip(GNSS_SYSTEMS, ("GPS", "GLONASS", "Galileo", "BeiDou", "QZSS"), strict=True))

#: RINEX 3 (3.00-3.05) band digits and tracking attributes of each system's code
#: pseudoranges. BeiDou's band 1 holds both RINEX 3.01/3.02's B1I (``C1I``, ``C1Q``,
#: ``C1X``; 3.03 on write it ``C2I``) and 3.04's B1C / B1A.
BANDS3: dict[str, dict[str, str]] = {
    "G": {"1": "CSLXPWYMN", "2": "CDSLXPWYMN", "5": "IQX"},
    "R": {"1": "CP", "2": "CP", "3": "IQX", "4": "ABX", "6": "ABX"},
    "E": {"1": "ABCXZ", "5": "IQX", "6": "ABCXZ", "7": "IQX", "8": "IQX"},
    "C": {"1": "IQXDPASLZN", "2": "IQX", "5": "DPX", "6": "IQXADPZ", "7": "IQXDPZ", "8": "DPX"},
    "J": {"1": "CSLXZEB", "2": "SLX", "5": "IQXDPZ", "6": "SLXEZ"},
}

#: RINEX 2 (2.10-2.12) code pseudoranges
CODES2: tuple[str, ...] = ("C1", "P1", "C2", "P2", "C5", "C6", "C7", "C8")

#: the signal read when a dataset names none, per RINEX major version and system, in order
#: of preference (a satellite record takes the first of them it has a value of)
DEFAULT_SIGNALS: dict[int, dict[str, tuple[str, ...]]] = {
    3: {"G": ("C1C",), "R": ("C1C",), "E": ("C1C", "C1X"), "C": ("C2I", "C1I"), "J": ("C1C",)},
    2: {"G": ("C1",), "R": ("C1",), "E": ("C1",), "C": ("C2", "C1"), "J": ("C1",)},
}

#: the systems read when a dataset names none (GPS: what every reader gave before)
DEFAULT_SYSTEMS: tuple[str, ...] = ("G",)


def check_systems(systems, argument: str = "systems") -> tuple[str, ...]:
    """``systems`` (an iterable of RINEX letters, or one string of them such as ``"GRE"``)
    as a tuple without repeats, in the order given; an empty one or a letter not in
    :data:`SYSTEMS` is an ArgumentError naming ``argument``."""
    try:
        letters = list(systems)
    except TypeError:
        raise ArgumentError(f"give the systems as letters (e.g. ['G', 'E'] or 'GE'), not {systems!r}",
                            argument) from None
    if not letters:
        raise ArgumentError("give at least one system", argument)
    for s in letters:
        if s not in SYSTEMS:
            raise ArgumentError(f"unknown system letter {s!r} (known: "
                                f"{', '.join(f'{k} ({v})' for k, v in SYSTEMS.items())})", argument)
    return tuple(dict.fromkeys(letters))


def code_error(system: str, code: str) -> str | None:
    """Why ``code`` is not a code-pseudorange signal of ``system`` (RINEX 2 or 3), or None."""
    if not isinstance(code, str) or len(code) not in (2, 3) or code[0] not in "CP":
        return (f"{code!r} is not a code-pseudorange observation code (RINEX 3: C + band + attribute, "
                "e.g. C1C; RINEX 2: C1, P1, C2...)")
    if len(code) == 2:
        return None if code in CODES2 else f"{code!r} is not a RINEX 2 pseudorange code ({', '.join(CODES2)})"
    bands = BANDS3[system]
    if code[0] != "C" or code[1] not in bands or code[2] not in bands[code[1]]:
        known = " ".join(f"C{b}{a}" for b, attrs in bands.items() for a in attrs)
        return f"{code!r} is not a RINEX 3 pseudorange code of {SYSTEMS[system]} (known: {known})"
    return None


def check_signals(signals, argument: str = "signals") -> dict[str, tuple[str, ...]]:
    """``signals`` (system letter -> one code or a list of codes, in order of preference)
    as a dict of tuples; a letter not in :data:`SYSTEMS`, an empty list or a code that is
    not a pseudorange signal of its system (:func:`code_error`) is an ArgumentError naming
    ``argument.<letter>``. Codes of both RINEX versions may be listed: a file uses those of
    its own version."""
    out = {}
    if signals is not None and not hasattr(signals, "items"):
        raise ArgumentError(f"give the signals as a table of system letter -> codes, not {signals!r}", argument)
    for s, codes in dict(signals or {}).items():
        check_systems([s], argument)
        try:
            codes = (codes,) if isinstance(codes, str) else tuple(codes)
        except TypeError:
            raise ArgumentError(f"give a code or a list of codes, not {codes!r}", f"{argument}.{s}") from None
        if not codes:
            raise ArgumentError("give at least one code", f"{argument}.{s}")
        for c in codes:
            why = code_error(s, c)
            if why:
                raise ArgumentError(why, f"{argument}.{s}")
        out[s] = tuple(dict.fromkeys(codes))
    return out


def signals_for(version: float, systems, signals=None) -> dict[str, tuple[str, ...]]:
    """The codes to read for each of ``systems`` from a RINEX file of ``version``: the
    codes ``signals`` names for the system that fit the version (3 characters for RINEX 3,
    2 for RINEX 2), else :data:`DEFAULT_SIGNALS`. A system whose given codes are all of the
    other version is an ArgumentError (``signals.<letter>``)."""
    major = 3 if version >= 3 else 2
    asked = check_signals(signals)
    out = {}
    for s in check_systems(systems):
        if s not in asked:
            out[s] = DEFAULT_SIGNALS[major][s]
            continue
        fit = tuple(c for c in asked[s] if len(c) == major)
        if not fit:
            raise ArgumentError(f"{', '.join(asked[s])}: no RINEX {major} code for this RINEX {version:.2f} file "
                                f"(add one, e.g. {DEFAULT_SIGNALS[major][s][0]})", f"signals.{s}")
        out[s] = fit
    return out


def companions(code: str) -> tuple[str, str, str]:
    """The carrier-phase, Doppler and C/N0 codes of the pseudorange signal ``code``
    (``C1C`` -> ``L1C``, ``D1C``, ``S1C``; RINEX 2 ``P1`` -> ``L1``, ``D1``, ``S1``)."""
    tail = code[1:]
    return "L" + tail, "D" + tail, "S" + tail
