"""Physical units as datasheets write them: the one place they are converted.

Inside mixnav every quantity is SI with radians (rad, m, s). Config files and
reports speak the language of IMU datasheets (``"2 deg/h"``,
``"0.1 deg/sqrt(h)"``, ``"30 ug/sqrt(Hz)"``, ``"300 ppm"``); this module
parses such text into SI floats, checking the dimension, and formats SI
values back.

Hand-written rather than built on pint: pint reads ``g`` as gram and ``ug``
as microgram, while a navigation datasheet means standard gravity, and the
grammar needed here (products, quotients, powers, ``sqrt(...)``) is small.
"""

from __future__ import annotations

import math
import re
from functools import lru_cache
from typing import NamedTuple

import numpy as np

DEG = math.pi / 180.0
ARCMIN = DEG / 60.0
ARCSEC = DEG / 3600.0
G0 = 9.80665  # standard gravity [m/s^2]; what "g", "mg", "ug" mean
HOUR = 3600.0


class Dimension(NamedTuple):
    """Exponents of (angle, length, time); floats so that sqrt gives 0.5."""

    angle: float
    length: float
    time: float

    def __mul__(self, other):  # type: ignore[override]
        return Dimension(self.angle + other.angle, self.length + other.length, self.time + other.time)

    def power(self, p: float) -> "Dimension":
        return Dimension(self.angle * p, self.length * p, self.time * p)

    def same(self, other: "Dimension") -> bool:
        return all(abs(a - b) < 1e-9 for a, b in zip(self, other))

    def words(self) -> str:
        """E.g. ``angle/time^0.5``."""
        num, den = [], []
        for name, e in zip(("angle", "length", "time"), self):
            if abs(e) < 1e-9:
                continue
            s = name if abs(abs(e) - 1) < 1e-9 else f"{name}^{abs(e):g}"
            (num if e > 0 else den).append(s)
        top = "*".join(num) or "1"
        return top + "".join("/" + d for d in den) if (num or den) else "dimensionless"


DIMENSIONLESS = Dimension(0.0, 0.0, 0.0)
ANGLE = Dimension(1.0, 0.0, 0.0)
LENGTH = Dimension(0.0, 1.0, 0.0)
TIME = Dimension(0.0, 0.0, 1.0)
FREQUENCY = Dimension(0.0, 0.0, -1.0)
ANGULAR_RATE = Dimension(1.0, 0.0, -1.0)
ANGLE_RANDOM_WALK = Dimension(1.0, 0.0, -0.5)
VELOCITY = Dimension(0.0, 1.0, -1.0)
ACCELERATION = Dimension(0.0, 1.0, -2.0)
VELOCITY_RANDOM_WALK = Dimension(0.0, 1.0, -1.5)
GYRO_BIAS_DRIFT = Dimension(1.0, 0.0, -1.5)      # deg/s^2/sqrt(Hz), deg/h/sqrt(h)
ACCEL_BIAS_DRIFT = Dimension(0.0, 1.0, -2.5)     # m/s^3/sqrt(Hz), ug/s/sqrt(Hz)

_BASE: dict[str, tuple[float, Dimension]] = {
    "rad": (1.0, ANGLE), "mrad": (1e-3, ANGLE), "urad": (1e-6, ANGLE),
    "deg": (DEG, ANGLE), "°": (DEG, ANGLE), "arcmin": (ARCMIN, ANGLE), "arcsec": (ARCSEC, ANGLE),
    "m": (1.0, LENGTH), "km": (1e3, LENGTH), "cm": (1e-2, LENGTH), "mm": (1e-3, LENGTH),
    "ft": (0.3048, LENGTH),
    "s": (1.0, TIME), "ms": (1e-3, TIME), "us": (1e-6, TIME), "min": (60.0, TIME),
    "h": (HOUR, TIME), "hr": (HOUR, TIME), "day": (86400.0, TIME),
    "Hz": (1.0, FREQUENCY),
    "g": (G0, ACCELERATION), "mg": (1e-3 * G0, ACCELERATION), "ug": (1e-6 * G0, ACCELERATION),
    "µg": (1e-6 * G0, ACCELERATION), "Gal": (1e-2, ACCELERATION), "mGal": (1e-5, ACCELERATION),
    "ppm": (1e-6, DIMENSIONLESS), "%": (1e-2, DIMENSIONLESS),
}

_EXAMPLES = "e.g. '2 deg/h', '0.1 deg/sqrt(h)', '30 ug/sqrt(Hz)', '300 ppm', '1.5 m'"


class UnitError(ValueError):
    """A quantity's text could not be read, or has the wrong dimension."""


_TOKEN = re.compile(r"\s*(sqrt\(|[A-Za-z°µ%]+|\^|[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?|[*/()])")


def _tokenize(text: str) -> list[str]:
    pos, out = 0, []
    text = text.strip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            raise UnitError(f"cannot read unit '{text}' at '{text[pos:]}'; {_EXAMPLES}")
        out.append(m.group(1))
        pos = m.end()
    return out


class _Parser:
    """expr := factor (('*'|'/') factor)* ; factor := atom ('^' number)? ;
    atom := NAME | 'sqrt(' expr ')' | '(' expr ')'"""

    def __init__(self, text):
        self.text = text
        self.toks = _tokenize(text)
        self.i = 0

    def peek(self):
        return self.toks[self.i] if self.i < len(self.toks) else None

    def take(self):
        t = self.peek()
        if t is None:
            raise UnitError(f"unit '{self.text}' ends too early; {_EXAMPLES}")
        self.i += 1
        return t

    def parse(self):
        f, d = self.expr()
        if self.peek() is not None:
            raise UnitError(f"unexpected '{self.peek()}' in unit '{self.text}'; {_EXAMPLES}")
        return f, d

    def expr(self):
        f, d = self.factor()
        while self.peek() in ("*", "/"):
            op = self.take()
            g, e = self.factor()
            if op == "*":
                f, d = f * g, d * e
            else:
                f, d = f / g, d * e.power(-1.0)
        return f, d

    def factor(self):
        f, d = self.atom()
        if self.peek() == "^":
            self.take()
            t = self.take()
            try:
                p = float(t)
            except ValueError:
                raise UnitError(f"expected a number after '^' in unit '{self.text}'") from None
            f, d = f ** p, d.power(p)
        return f, d

    def atom(self):
        t = self.take()
        if t in ("sqrt(", "("):
            f, d = self.expr()
            if self.take() != ")":
                raise UnitError(f"missing ')' in unit '{self.text}'")
            return (math.sqrt(f), d.power(0.5)) if t == "sqrt(" else (f, d)
        if t in _BASE:
            return _BASE[t]
        raise UnitError(f"unknown unit '{t}' in '{self.text}'; known units: {', '.join(_BASE)}")


@lru_cache(maxsize=512)
def parse_unit(unit_text: str) -> tuple[float, Dimension]:
    """Factor to SI and dimension of a unit expression such as ``deg/sqrt(h)``."""
    if not unit_text.strip():
        return 1.0, DIMENSIONLESS
    return _Parser(unit_text).parse()


_NUMBER = re.compile(r"\s*([-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf))", re.IGNORECASE)


def parse_quantity(text, expected: Dimension) -> float:
    """Parse ``"<number> <unit>"`` into an SI float of the expected dimension.

    Parameters
    ----------
    text : str (or int/float for dimensionless values only)
    expected : Dimension

    Raises
    ------
    UnitError
        Missing or unknown unit, bad syntax, wrong dimension, non-finite number.
    """
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise UnitError(f"expected a quantity as text, e.g. '2 deg/h', got {text!r}")
    if not isinstance(text, str):
        if expected.same(DIMENSIONLESS):
            if not math.isfinite(text):
                raise UnitError(f"value must be finite, got {text!r}")
            return float(text)
        raise UnitError(f"a bare number ({text!r}) is not allowed for a value with units "
                        f"({expected.words()}); write e.g. '{text} {_example_unit(expected)}'")
    m = _NUMBER.match(text)
    if not m:
        raise UnitError(f"'{text}' does not start with a number; {_EXAMPLES}")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise UnitError(f"value must be finite, got '{text}'")
    unit = text[m.end():].strip()
    if not unit and not expected.same(DIMENSIONLESS):
        raise UnitError(f"'{text}' has no unit; a value of {expected.words()} needs one, "
                        f"e.g. '{m.group(1)} {_example_unit(expected)}'")
    factor, dim = parse_unit(unit)
    if not dim.same(expected):
        raise UnitError(f"'{text}' has dimension {dim.words()}, expected {expected.words()}")
    return value * factor


def to_unit(value_si, unit_text: str):
    """Express an SI value (or array) in the given unit."""
    factor, _ = parse_unit(unit_text)
    return np.asarray(value_si) / factor if isinstance(value_si, np.ndarray) else value_si / factor


def _example_unit(dim: Dimension) -> str:
    for name, ex in ((ANGULAR_RATE, "deg/h"), (ANGLE_RANDOM_WALK, "deg/sqrt(h)"), (ANGLE, "deg"),
                     (LENGTH, "m"), (TIME, "s"), (FREQUENCY, "Hz"), (VELOCITY, "m/s"),
                     (ACCELERATION, "m/s^2"), (VELOCITY_RANDOM_WALK, "ug/sqrt(Hz)"),
                     (GYRO_BIAS_DRIFT, "deg/h/sqrt(h)"), (ACCEL_BIAS_DRIFT, "ug/s/sqrt(Hz)")):
        if dim.same(name):
            return ex
    return "<unit>"
