"""Unit-typed fields for the estimators' settings models (the tables a file gives them).

An estimator's settings model lives beside the estimator (mixnav.filters), below the
config layer, so it cannot use :mod:`mixnav.config.fields`; these are the same rule
(a value written with its unit, ``"60 s"``, held in SI; the same messages), through
:mod:`mixnav.units`.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BeforeValidator, ConfigDict

from .. import units as u

#: every key known, frozen once validated (as the config's models)
STRICT = ConfigDict(extra="forbid", frozen=True)


def positive_quantity(dim):
    """A positive float written with a unit of dimension ``dim``, held in SI."""
    def parse(v):
        if isinstance(v, bool):
            raise ValueError("expected a quantity with a unit, e.g. '2 deg/h'")
        x = u.parse_quantity(v, dim)
        if not x > 0:
            raise ValueError(f"must be positive, got {v!r}")
        return x
    return Annotated[float, BeforeValidator(parse)]


Duration = positive_quantity(u.TIME)
PosLength = positive_quantity(u.LENGTH)
