"""Unit-typed fields for the estimators' settings models (the tables a file gives them).

An estimator's settings model lives beside the estimator (mixnav.filters), below the
config layer, so the unit field is defined here (a value written with its unit, ``"60 s"``,
held in SI, through :mod:`mixnav.units`) and :mod:`mixnav.config.fields` builds on it.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BeforeValidator, ConfigDict

from .. import units as u

#: every key known, frozen once validated (as the config's models)
STRICT = ConfigDict(extra="forbid", frozen=True)


def quantity(dim, positive: bool = False, nonnegative: bool = False, below: tuple[float, str] | None = None):
    """A float field written with a unit of dimension ``dim`` (``"2 deg/h"``), held in SI;
    ``below``: ``(limit in SI, the limit as written)``, an exclusive upper bound. The one
    definition: :mod:`mixnav.config.fields` uses it too."""
    def parse(v):
        if isinstance(v, bool):
            raise ValueError("expected a quantity with a unit, e.g. '2 deg/h'")
        x = u.parse_quantity(v, dim)
        if positive and not x > 0:
            raise ValueError(f"must be positive, got {v!r}")
        if nonnegative and not x >= 0:
            raise ValueError(f"must not be negative, got {v!r}")
        if below is not None and not x < below[0]:
            raise ValueError(f"must be below {below[1]}, got {v!r}")
        return x
    return Annotated[float, BeforeValidator(parse)]


def positive_quantity(dim):
    """A positive float written with a unit of dimension ``dim``, held in SI."""
    return quantity(dim, positive=True)


Duration = positive_quantity(u.TIME)
PosLength = positive_quantity(u.LENGTH)
