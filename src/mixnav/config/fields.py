"""The unit-typed fields every config schema is built of (scenario, dataset, vehicle, raw GNSS).

Every value with a unit carries it as text (``"2 deg/h"``) and is converted to SI
here, through :mod:`mixnav.units`, once, at load time: the models hold SI floats
after validation, so nothing downstream parses units again. :class:`Strict`
makes every key known (an unknown key is an error).
"""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict

from .. import units as u
from ..filters.option_fields import quantity  # the one unit field (filters cannot import config)
from ..formats import check_format


def reader_format(kind: str):
    """A ``format`` key naming any reader of ``kind`` (mixnav.formats: the readers' own
    registrations, found without importing io); an unknown one lists the registered formats."""
    return Annotated[str, AfterValidator(lambda v: check_format(kind, v))]


def vector(dim, positive: bool = False):
    """Three :func:`quantity` values of dimension ``dim`` (``["1 m", "1 m", "2 m"]``)."""
    item = quantity(dim, positive=positive)

    def check_len(v):
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise ValueError("expected a list of three quantities, e.g. [\"1 m\", \"1 m\", \"2 m\"]")
        return v
    return Annotated[tuple[item, item, item], BeforeValidator(check_len)]


Angle = quantity(u.ANGLE)
Rate = quantity(u.ANGULAR_RATE)
Length = quantity(u.LENGTH)
Speed = quantity(u.VELOCITY, nonnegative=True)
Accel = quantity(u.ACCELERATION)
Duration = quantity(u.TIME, positive=True)
Time = quantity(u.TIME, nonnegative=True)
Frequency = quantity(u.FREQUENCY, positive=True)
PosSigma = vector(u.LENGTH, positive=True)
VelSigma = vector(u.VELOCITY, positive=True)
AngSigma = vector(u.ANGLE, positive=True)
LengthVec = vector(u.LENGTH)
AngleVec = vector(u.ANGLE)

Fraction = quantity(u.DIMENSIONLESS)
NonNegSpeed = quantity(u.VELOCITY, nonnegative=True)
PosSpeed = quantity(u.VELOCITY, positive=True)
PosAccel = quantity(u.ACCELERATION, positive=True)
PosRate = quantity(u.ANGULAR_RATE, positive=True)
PosAngle = quantity(u.ANGLE, positive=True)
PosLength = quantity(u.LENGTH, positive=True)
NonNegRate = quantity(u.ANGULAR_RATE, nonnegative=True)
NonNegLength = quantity(u.LENGTH, nonnegative=True)
NonNegAngle = quantity(u.ANGLE, nonnegative=True)
TimeWalk = quantity(u.TIME_RANDOM_WALK, nonnegative=True)
#: an elevation mask: 0 (the horizon) up to, not including, the zenith (a mask of 90 deg or more
#: leaves no satellite: every epoch would be unsolvable)
ElevationMask = quantity(u.ANGLE, nonnegative=True, below=(math.pi / 2, "90 deg (the zenith)"))


def _ordered_windows(v):
    for i, (a, b) in enumerate(v):
        if not b > a:
            raise ValueError(f"window {i} ends ({b:g} s) before it starts ({a:g} s)")
    return v


#: Time windows ``[[start, end], ...]`` with each end after its start.
Windows = Annotated[list[tuple[Time, Time]], AfterValidator(_ordered_windows)]


class Strict(BaseModel):
    """Every key known (an unknown key is an error); frozen once validated."""

    model_config = ConfigDict(extra="forbid", frozen=True)


#: plausible geodetic positions (docs/validation.md): the NED mechanization is singular at
#: the poles; heights from the Dead Sea shore to far above any aircraft
MAX_LATITUDE = math.radians(89.0)
HEIGHT_RANGE = (-1000.0, 100e3)


def check_position(lat: float, lon: float, h: float) -> None:
    """A ValueError unless ``lat`` [rad], ``lon`` [rad], ``h`` [m] is a plausible position."""
    if not abs(lat) <= MAX_LATITUDE:
        raise ValueError(f"latitude {math.degrees(lat):.6g} deg is outside +-{math.degrees(MAX_LATITUDE):g} deg "
                         "(beyond +-90 deg it does not exist; near the poles the NED mechanization is singular)")
    if not -math.pi <= lon <= 2 * math.pi:
        raise ValueError(f"longitude {math.degrees(lon):.6g} deg is outside -180..360 deg")
    if not HEIGHT_RANGE[0] <= h <= HEIGHT_RANGE[1]:
        raise ValueError(f"height {h:.6g} m is outside {HEIGHT_RANGE[0]:g}..{HEIGHT_RANGE[1]:g} m")
