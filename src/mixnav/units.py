"""Physical units as IMU datasheets write them: the one place they are converted.

Inside mixnav every quantity is SI with radians (rad, m, s). Config files and
reports speak the language of IMU datasheets (``"2 deg/h"``,
``"0.1 deg/sqrt(h)"``, ``"30 ug/sqrt(Hz)"``, ``"300 ppm"``). This module parses
such text into SI floats, checking the physical dimension, and converts SI
values back into a chosen unit for reports. Nothing else in mixnav should
multiply by ``pi/180`` or ``3600`` on text it read.

Why hand-written rather than built on pint: pint reads ``g`` as gram and
``ug`` as microgram, while a navigation datasheet means standard gravity
(9.80665 m/s^2). The grammar needed here (products, quotients, powers and
``sqrt(...)`` of a few dozen base units) is small enough that a tokenizer and
a recursive-descent parser of ~150 lines are easier to trust than a
redefined registry.

Grammar of a quantity (whitespace is ignored between tokens)::

    quantity := number unit?                 # "2 deg/h", "30ug/sqrt(Hz)"
    unit     := power (('*' | '/') power)*   # left to right: a/b/c = a*b^-1*c^-1
    power    := atom ('^' exponent)?
    atom     := NAME | 'sqrt' '(' unit ')' | '(' unit ')'
    exponent := signed_number | '(' signed_number ('/' number)? ')'

Dimensions are exponents of (angle, length, time). Angle is kept as its own
dimension, although SI treats it as dimensionless, so that ``"2 m/s"`` cannot
be accepted where ``"2 deg/s"`` was meant.
"""

from __future__ import annotations

import difflib
import math
import numbers
from functools import lru_cache
from typing import NamedTuple

import numpy as np

__all__ = [
    "DEG", "ARCMIN", "ARCSEC", "G0", "HOUR",
    "Dimension", "UnitError",
    "DIMENSIONLESS", "ANGLE", "LENGTH", "TIME", "FREQUENCY", "ANGULAR_RATE",
    "ANGLE_RANDOM_WALK", "VELOCITY", "ACCELERATION", "VELOCITY_RANDOM_WALK",
    "GYRO_BIAS_DRIFT", "ACCEL_BIAS_DRIFT",
    "parse_quantity", "parse_unit", "to_unit",
]

# --------------------------------------------------------------------------
# Plain numeric constants, for code that needs a factor rather than text.
# --------------------------------------------------------------------------
DEG = math.pi / 180.0          #: one degree [rad]
ARCMIN = DEG / 60.0            #: one arc minute [rad]
ARCSEC = DEG / 3600.0          #: one arc second [rad]
G0 = 9.80665                   #: standard gravity [m/s^2]; what "g", "mg", "ug" mean
HOUR = 3600.0                  #: one hour [s]

_TOL = 1e-9  # exponent tolerance: sqrt and ^0.5 round-trip through floats


class Dimension(NamedTuple):
    """Physical dimension as exponents of (angle, length, time).

    Floats, not ints, so that ``sqrt(h)`` gives a time exponent of 0.5.
    Compare with :meth:`matches` (tolerance 1e-9) rather than ``==``.

    Attributes
    ----------
    angle : float
        Exponent of angle [rad].
    length : float
        Exponent of length [m].
    time : float
        Exponent of time [s].
    """

    angle: float
    length: float
    time: float

    def matches(self, other: "Dimension") -> bool:
        """True when every exponent agrees with ``other`` to within 1e-9."""
        return all(abs(a - b) <= _TOL for a, b in zip(self, other))

    def words(self) -> str:
        """The exponents in words, e.g. ``"angle/time^0.5"`` or ``"1/time"``."""
        num, den = [], []
        for name, e in zip(("angle", "length", "time"), self):
            if abs(e) <= _TOL:
                continue
            mag = abs(e)
            # round so that 0.49999999999 prints as 0.5
            term = name if abs(mag - 1.0) <= _TOL else f"{name}^{round(mag, 9):g}"
            (num if e > 0 else den).append(term)
        if not num and not den:
            return "dimensionless"
        return "*".join(num or ["1"]) + "".join("/" + d for d in den)

    def describe(self) -> str:
        """Name and exponents, e.g. ``"angle random walk (angle/time^0.5)"``."""
        for dim, name, _ in _NAMED:
            if self.matches(dim):
                words = self.words()
                return name if name == words else f"{name} ({words})"
        return self.words()


DIMENSIONLESS = Dimension(0.0, 0.0, 0.0)
ANGLE = Dimension(1.0, 0.0, 0.0)
LENGTH = Dimension(0.0, 1.0, 0.0)
TIME = Dimension(0.0, 0.0, 1.0)
FREQUENCY = Dimension(0.0, 0.0, -1.0)
ANGULAR_RATE = Dimension(1.0, 0.0, -1.0)
#: rate noise density: deg/sqrt(h) == deg/s/sqrt(Hz) dimensionally
ANGLE_RANDOM_WALK = Dimension(1.0, 0.0, -0.5)
VELOCITY = Dimension(0.0, 1.0, -1.0)
ACCELERATION = Dimension(0.0, 1.0, -2.0)
#: acceleration noise density: ug/sqrt(Hz) == m/s/sqrt(h) dimensionally
VELOCITY_RANDOM_WALK = Dimension(0.0, 1.0, -1.5)
#: random walk of a gyro bias: rate/sqrt(time), e.g. deg/h/sqrt(h), deg/s^2/sqrt(Hz)
GYRO_BIAS_DRIFT = Dimension(1.0, 0.0, -1.5)
#: random walk of an accelerometer bias: accel/sqrt(time), e.g. ug/s/sqrt(Hz),
#: m/s^3/sqrt(Hz). Note "ug/sqrt(Hz)" alone is VELOCITY_RANDOM_WALK, not this.
ACCEL_BIAS_DRIFT = Dimension(0.0, 1.0, -2.5)
#: random walk of a time offset (a clock's phase): time/sqrt(time), e.g. ms/sqrt(s)
TIME_RANDOM_WALK = Dimension(0.0, 0.0, 0.5)

# (dimension, name in words, accepted spellings shown in error messages);
# every spelling here is checked by the tests to parse to its dimension.
_NAMED: tuple[tuple[Dimension, str, tuple[str, ...]], ...] = (
    (DIMENSIONLESS, "dimensionless", ("ppm", "%", "")),
    (ANGLE, "angle", ("deg", "rad", "arcsec")),
    (LENGTH, "length", ("m", "km", "ft")),
    (TIME, "time", ("s", "ms", "h")),
    (FREQUENCY, "frequency", ("Hz",)),
    (ANGULAR_RATE, "angular rate", ("deg/h", "deg/s", "rad/s")),
    (ANGLE_RANDOM_WALK, "angle random walk", ("deg/sqrt(h)", "deg/s/sqrt(Hz)", "rad/sqrt(s)")),
    (VELOCITY, "velocity", ("m/s", "km/h")),
    (ACCELERATION, "acceleration", ("m/s^2", "mg", "ug")),
    (VELOCITY_RANDOM_WALK, "velocity random walk", ("ug/sqrt(Hz)", "m/s/sqrt(h)", "m/s^1.5")),
    (GYRO_BIAS_DRIFT, "gyro bias drift", ("deg/h/sqrt(h)", "deg/s^2/sqrt(Hz)", "rad/s^1.5")),
    (ACCEL_BIAS_DRIFT, "accelerometer bias drift", ("ug/s/sqrt(Hz)", "m/s^3/sqrt(Hz)", "m/s^2.5")),
    (TIME_RANDOM_WALK, "time random walk", ("ms/sqrt(s)", "s/sqrt(s)", "s^0.5")),
)

# Base units: name -> (factor to SI, dimension). Case-sensitive on purpose:
# "Hz", "Gal", "mGal" are spelled that way on datasheets.
_BASE: dict[str, tuple[float, Dimension]] = {
    # angle
    "rad": (1.0, ANGLE), "mrad": (1e-3, ANGLE), "urad": (1e-6, ANGLE),
    "deg": (DEG, ANGLE), "°": (DEG, ANGLE), "arcmin": (ARCMIN, ANGLE), "arcsec": (ARCSEC, ANGLE),
    # length
    "m": (1.0, LENGTH), "km": (1e3, LENGTH), "cm": (1e-2, LENGTH), "mm": (1e-3, LENGTH),
    "ft": (0.3048, LENGTH),
    # time ("us" is microsecond; micro-g is "ug", so no clash)
    "s": (1.0, TIME), "ms": (1e-3, TIME), "us": (1e-6, TIME), "min": (60.0, TIME),
    "h": (HOUR, TIME), "hr": (HOUR, TIME), "day": (86400.0, TIME),
    # frequency
    "Hz": (1.0, FREQUENCY),
    # acceleration: g is standard gravity, never gram
    "g": (G0, ACCELERATION), "mg": (1e-3 * G0, ACCELERATION), "ug": (1e-6 * G0, ACCELERATION),
    "µg": (1e-6 * G0, ACCELERATION),  # U+00B5 MICRO SIGN
    "μg": (1e-6 * G0, ACCELERATION),  # U+03BC GREEK SMALL LETTER MU (what some editors type)
    "Gal": (1e-2, ACCELERATION), "mGal": (1e-5, ACCELERATION),
    # dimensionless
    "ppm": (1e-6, DIMENSIONLESS), "%": (1e-2, DIMENSIONLESS),
}


class UnitError(ValueError):
    """A quantity's text could not be read, or has the wrong dimension.

    The message quotes the text given, says what dimension was expected and
    lists a few accepted spellings, so the user can fix the config directly.
    """


class _SyntaxProblem(Exception):
    """Internal: what is wrong inside a unit expression (no context yet)."""


# --------------------------------------------------------------------------
# Tokenizer
# --------------------------------------------------------------------------
class _Token(NamedTuple):
    kind: str  # "name", "number", "end", or the punctuation character itself
    text: str
    pos: int   # 0-based character offset in the unit text


_DIGITS = frozenset("0123456789")
_NAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZµμ")
_ONE_CHAR_NAMES = frozenset("%°")  # units that are a single symbol, may touch a name
_PUNCT = frozenset("*/^()+-")


def _tokenize(text: str) -> list[_Token]:
    toks: list[_Token] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c.isspace():
            i += 1
        elif c in _NAME_CHARS:
            j = i
            while j < n and text[j] in _NAME_CHARS:
                j += 1
            toks.append(_Token("name", text[i:j], i))
            i = j
        elif c in _ONE_CHAR_NAMES:
            toks.append(_Token("name", c, i))
            i += 1
        elif c in _DIGITS or c == ".":
            # only valid as an exponent; the parser says so if it is misplaced
            j = i
            while j < n and (text[j] in _DIGITS or text[j] == "."):
                j += 1
            toks.append(_Token("number", text[i:j], i))
            i = j
        elif c in _PUNCT:
            toks.append(_Token(c, c, i))
            i += 1
        else:
            raise _SyntaxProblem(f"unexpected character {c!r} at character {i + 1}")
    toks.append(_Token("end", "", n))
    return toks


# --------------------------------------------------------------------------
# Recursive-descent parser; each rule returns (factor to SI, Dimension)
# --------------------------------------------------------------------------
def _mul(a: Dimension, b: Dimension) -> Dimension:
    return Dimension(a.angle + b.angle, a.length + b.length, a.time + b.time)


def _pow(a: Dimension, p: float) -> Dimension:
    # "+ 0.0" turns -0.0 (from 0 * -1) into 0.0 so reprs stay clean
    return Dimension(a.angle * p + 0.0, a.length * p + 0.0, a.time * p + 0.0)


def _found(tok: _Token) -> str:
    return "the end" if tok.kind == "end" else f"{tok.text!r} at character {tok.pos + 1}"


def _unknown_unit(tok: _Token) -> _SyntaxProblem:
    # Suggest a spelling: first a case-only difference ("hz" -> "Hz"), then near misses.
    same_case = [k for k in _BASE if k.lower() == tok.text.lower()]
    close = same_case or difflib.get_close_matches(tok.text, list(_BASE), n=3, cutoff=0.6)
    hint = f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""
    return _SyntaxProblem(f"unknown unit {tok.text!r}{hint}; known units: {', '.join(_BASE)}")


class _Parser:
    def __init__(self, text: str):
        self.toks = _tokenize(text)
        self.i = 0

    def peek(self) -> _Token:
        return self.toks[self.i]

    def take(self) -> _Token:
        tok = self.toks[self.i]
        if tok.kind != "end":
            self.i += 1
        return tok

    def parse(self) -> tuple[float, Dimension]:
        f, d = self.unit()
        tok = self.peek()
        if tok.kind != "end":
            hint = "; join units with '*' or '/'" if tok.kind in ("name", "(") else ""
            raise _SyntaxProblem(f"unexpected {_found(tok)}{hint}")
        return f, d

    def unit(self) -> tuple[float, Dimension]:
        f, d = self.power(after=None)
        while self.peek().kind in ("*", "/"):
            op = self.take()
            g, e = self.power(after=op.text)
            if op.kind == "/":
                g, e = 1.0 / g, _pow(e, -1.0)
            f, d = f * g, _mul(d, e)
        return f, d

    def power(self, after: str | None) -> tuple[float, Dimension]:
        f, d = self.atom(after)
        if self.peek().kind == "^":
            self.take()
            p = self.exponent()
            f, d = f ** p, _pow(d, p)
        return f, d

    def exponent(self) -> float:
        if self.peek().kind == "(":
            opener = self.take()
            p = self.signed_number()
            if self.peek().kind == "/":
                self.take()
                q = self.signed_number()
                if q == 0.0:
                    raise _SyntaxProblem("exponent divides by zero")
                p /= q
            self.close(opener)
            return p
        return self.signed_number()

    def signed_number(self) -> float:
        sign = 1.0
        if self.peek().kind in ("+", "-"):
            sign = -1.0 if self.take().kind == "-" else 1.0
        tok = self.take()
        if tok.kind != "number":
            raise _SyntaxProblem(f"expected a number after '^' but found {_found(tok)}")
        try:
            return sign * float(tok.text)
        except ValueError:
            raise _SyntaxProblem(f"{tok.text!r} at character {tok.pos + 1} is not a number") from None

    def atom(self, after: str | None) -> tuple[float, Dimension]:
        tok = self.take()
        if tok.kind == "name" and tok.text == "sqrt":
            if self.peek().kind != "(":
                raise _SyntaxProblem(f"expected '(' after 'sqrt' but found {_found(self.peek())}")
            opener = self.take()
            f, d = self.unit()
            self.close(opener, "sqrt(")
            return math.sqrt(f), _pow(d, 0.5)
        if tok.kind == "name":
            if tok.text not in _BASE:
                raise _unknown_unit(tok)
            return _BASE[tok.text]
        if tok.kind == "(":
            f, d = self.unit()
            self.close(tok)
            return f, d
        where = f" after {after!r}" if after else ""
        raise _SyntaxProblem(f"expected a unit{where} but found {_found(tok)}")

    def close(self, opener: _Token, label: str = "(") -> None:
        tok = self.take()
        if tok.kind != ")":
            found = "" if tok.kind == "end" else f", found {_found(tok)}"
            raise _SyntaxProblem(f"missing ')' to close {label!r} opened at character "
                                 f"{opener.pos + 1}{found}")


@lru_cache(maxsize=256)
def _parse_unit_cached(unit_text: str) -> tuple[float, Dimension]:
    # Units are parsed at config load; the cache makes repeated report
    # conversions (to_unit in loops) cost a dict lookup.
    if not unit_text.strip():
        return 1.0, DIMENSIONLESS
    return _Parser(unit_text).parse()


# --------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------
def parse_unit(unit_text: str) -> tuple[float, Dimension]:
    """Factor to SI and dimension of a unit expression.

    Parameters
    ----------
    unit_text : str
        A unit expression such as ``"deg/sqrt(h)"`` or ``"m/s^2"``. Factors
        are applied left to right: ``"deg/s/sqrt(Hz)"`` is
        deg * s^-1 * Hz^-0.5. An empty string is dimensionless with factor 1.

    Returns
    -------
    factor : float
        Multiply a value in this unit by ``factor`` to get SI (rad, m, s).
    dimension : Dimension
        Exponents of (angle, length, time).

    Raises
    ------
    UnitError
        Unknown base unit (the message names it and lists the known ones)
        or bad syntax (the message says where).

    Examples
    --------
    >>> parse_unit("deg/sqrt(h)")[1]
    Dimension(angle=1.0, length=0.0, time=-0.5)
    """
    if not isinstance(unit_text, str):
        raise UnitError(f"a unit must be text such as 'deg/h', got {unit_text!r}")
    try:
        return _parse_unit_cached(unit_text)
    except _SyntaxProblem as exc:
        raise UnitError(f"cannot read unit {unit_text!r}: {exc}") from None


def _examples(expected: Dimension, number: str = "2") -> str:
    """A few accepted spellings of ``expected``, written with ``number``."""
    for dim, _, spellings in _NAMED:
        if expected.matches(dim):
            units = list(spellings)
            break
    else:
        # an unnamed dimension: spell it in SI so the example always parses
        def term(n: str, e: float) -> str:
            return n if abs(e - 1.0) <= _TOL else f"{n}^{round(e, 9):g}"
        parts = [(n, e) for n, e in zip(("rad", "m", "s"), expected) if abs(e) > _TOL]
        num = "*".join(term(n, e) for n, e in parts if e > 0)
        den = [(n, -e) for n, e in parts if e < 0]
        units = [num + "".join("/" + term(n, e) for n, e in den) if num
                 else "*".join(term(n, -e) for n, e in den)]
    return ", ".join(f"'{number} {u}'" if u else f"'{number}'" for u in units)


def _scan_number(text: str) -> tuple[str, int] | None:
    """Leading number of ``text`` (after blanks): its text and end offset.

    Accepts ``-1.5e-3``, ``+2``, ``.5``, ``2.``; ``nan``/``inf`` are
    returned too so the caller can say they are not finite.
    """
    i, n = 0, len(text)
    while i < n and text[i].isspace():
        i += 1
    start = i
    if i < n and text[i] in "+-":
        i += 1
    for word in ("infinity", "inf", "nan"):
        if text[i:i + len(word)].lower() == word and not (
                i + len(word) < n and text[i + len(word)] in _NAME_CHARS):
            return text[start:i + len(word)], i + len(word)
    digits_start = i
    while i < n and text[i] in _DIGITS:
        i += 1
    if i < n and text[i] == ".":
        i += 1
        while i < n and text[i] in _DIGITS:
            i += 1
    if not any(c in _DIGITS for c in text[digits_start:i]):
        return None
    # exponent only if "e" is followed by digits: "2 e" is not 2e0
    if i < n and text[i] in "eE":
        j = i + 1
        if j < n and text[j] in "+-":
            j += 1
        if j < n and text[j] in _DIGITS:
            while j < n and text[j] in _DIGITS:
                j += 1
            i = j
    return text[start:i], i


#: largest magnitude of a parsed quantity in SI units (docs/validation.md): 1e12 m is seven
#: astronomical units; beyond it a value is a typo, and squared (a variance) it overflows soon
MAX_ABS_SI = 1e12


def parse_quantity(text: str, expected: Dimension) -> float:
    """Parse ``"<number> <unit>"`` into an SI float, checking its dimension.

    Parameters
    ----------
    text : str
        E.g. ``"2 deg/h"``, ``"0.1 deg/sqrt(h)"``, ``"30ug/sqrt(Hz)"``,
        ``"-1.5e-3 m/s^2"``. For ``expected == DIMENSIONLESS`` the unit may
        be omitted (``"0.5"``) and a plain int/float is accepted too; for any
        other dimension the unit is required and must be written in text.
    expected : Dimension
        The dimension the value must have, e.g. :data:`ANGULAR_RATE`.

    Returns
    -------
    float
        The value in SI units (rad, m, s combined as ``expected`` says).

    Raises
    ------
    UnitError
        Missing unit, bare number for a value with units, unknown unit, bad
        syntax, wrong dimension, or a number that is not finite. The message
        quotes the text, names the expected dimension and gives examples.

    Examples
    --------
    >>> parse_quantity("36 km/h", VELOCITY)
    10.0
    """
    if isinstance(text, bool) or not isinstance(text, (str, numbers.Real)):
        # bool is an int, but True in a config is a mistake, not the number 1
        raise UnitError(f"expected a quantity written as text, e.g. {_examples(expected)}; "
                        f"got {text!r}")
    if not isinstance(text, str):
        if not expected.matches(DIMENSIONLESS):
            raise UnitError(f"a bare number ({text!r}) is not allowed for a value with units "
                            f"({expected.describe()}); write e.g. {_examples(expected, f'{text:g}')}")
        value = float(text)
        if not math.isfinite(value):
            raise UnitError(f"value must be a finite number, got {text!r}")
        if not abs(value) <= MAX_ABS_SI:
            raise UnitError(f"{text!r} is beyond {MAX_ABS_SI:g}: not a physical setting")
        return value

    scanned = _scan_number(text)
    if scanned is None:
        raise UnitError(f"{text!r} does not start with a number; a value of {expected.describe()} "
                        f"is written number first, e.g. {_examples(expected)}")
    number, end = scanned
    value = float(number)  # also turns overflow such as "1e999" into inf
    if not math.isfinite(value):
        raise UnitError(f"value must be a finite number, got {text!r}")
    unit_text = text[end:].strip()
    if not unit_text and not expected.matches(DIMENSIONLESS):
        raise UnitError(f"{text!r} is missing its unit: a value of {expected.describe()} needs one, "
                        f"e.g. {_examples(expected, number)}")
    try:
        factor, dim = _parse_unit_cached(unit_text)
    except _SyntaxProblem as exc:
        raise UnitError(f"cannot read {text!r} as {expected.describe()}: in unit {unit_text!r}, {exc}; "
                        f"accepted spellings include {_examples(expected, number)}") from None
    if not dim.matches(expected):
        raise UnitError(f"{text!r} has dimension {dim.describe()}, but {expected.describe()} "
                        f"is expected; write e.g. {_examples(expected, number)}")
    si = value * factor
    if not abs(si) <= MAX_ABS_SI:
        raise UnitError(f"{text!r} is {si:.3g} in SI units: beyond {MAX_ABS_SI:g}, not a physical setting "
                        "(its square would not be representable)")
    return si


def to_unit(value_si, unit_text: str):
    """Express an SI value in ``unit_text`` (for reports and plots).

    Only the factor is applied; the dimension is not checked, since the
    caller knows what it holds.

    Parameters
    ----------
    value_si : float or numpy.ndarray
        Value(s) in SI (rad, m, s), any shape.
    unit_text : str
        Target unit, e.g. ``"deg/h"``.

    Returns
    -------
    float or numpy.ndarray
        ``value_si / factor``, with the same type (and shape) as the input;
        lists and tuples come back as arrays.

    Examples
    --------
    >>> round(to_unit(parse_quantity("2 deg/h", ANGULAR_RATE), "deg/h"), 12)
    2.0
    """
    factor, _ = parse_unit(unit_text)
    if isinstance(value_si, (np.ndarray, numbers.Real)):
        return value_si / factor
    return np.asarray(value_si, dtype=float) / factor
