"""The settings of the IMM (``estimator = "imm"``, a method's ``[imm]`` table): its modes, each
a registered estimator that can be a mode (:mod:`mixnav.filters.registry`: ``imm_child``)
with its own table or ``[options]``, and the Markov transition between them. Light to import
(pydantic, units, the registry); the registration of mixnav.filters.imm names
:class:`ImmOptions` as its options.
"""

from __future__ import annotations

from typing import Any, Literal, Union

from pydantic import BaseModel, Field, field_validator, model_validator

from ..errors import ArgumentError
from ..markov import check_transition
from .option_fields import STRICT, Duration
from .registry import (check_entry, checked_options, estimator_spec, imm_mode_names, training_needs,
                       validate_table)

#: the tables a mode may carry: each the settings of the registered estimator whose table it is
MODE_TABLES = ("robust", "em", "mixture")


class ImmModeOptions(BaseModel):
    """One mode of an IMM (``[[methods.imm.modes]]``): its name, the measurements that update
    it (``"gnss"``, the method type's GNSS model, and any of the method's ``aiding``) and
    its estimator, any registered one that can be a mode: ``"ekf"``, ``"robust-adaptive"``
    (optional ``[robust]`` table), ``"em-bias"`` (the EM-IMM's GNSS mode: the EKF with the EM
    multipath-bias removal on its GNSS rows, optional ``[em]`` table) or
    ``"gaussian-mixture"`` (a bank, optional ``[mixture]`` table as a method's, learned
    offline or online; not coloured); an estimator without a table of its own takes its
    settings from the mode's ``[options]``."""

    model_config = STRICT

    name: str = Field(min_length=1)
    measurements: list[Literal["gnss", "nhc", "odometer", "zupt", "zaru"]] = Field(
        min_length=1, description="a mode with no measurements is pure inertial navigation, never told apart")
    #: a registered estimator that can be a mode (``imm_mode`` in mixnav.filters.registry)
    estimator: str = "ekf"
    robust: Any = None
    em: Any = None
    mixture: Any = None
    options: dict[str, Any] = Field(default_factory=dict)

    @field_validator("estimator")
    @classmethod
    def _mode_estimator(cls, v):
        try:
            ok = estimator_spec(v).imm_mode
        except ArgumentError:
            ok = False
        if not ok:
            raise ValueError(f"estimator '{v}' cannot be a mode of an IMM (these can: {', '.join(imm_mode_names())})")
        return v

    @field_validator(*MODE_TABLES)
    @classmethod
    def _table(cls, v, info):
        return validate_table(info.field_name, info.data.get("estimator"), v)

    @field_validator("options")
    @classmethod
    def _typed_options(cls, v, info):
        return checked_options(info.data.get("estimator"), v)

    @model_validator(mode="after")
    def _unique(self):
        if len(set(self.measurements)) != len(self.measurements):
            raise ValueError(f"a measurement is listed twice: {self.measurements}")
        check_entry(self, self.estimator, MODE_TABLES, self.measurements, mode=True)
        return self


class ImmOptions(BaseModel):
    """Interacting multiple models (``estimator = "imm"``, :mod:`mixnav.filters.imm`).

    ``transition[i][j]``: probability of mode j one ``transition_interval`` after mode i
    (rows sum to one; default interval 1 s, or ``"epoch"`` to apply it once per
    measurement epoch as P4 does); ``initial_probabilities`` default uniform; ``output``
    ``"combined"`` (P4, default) or ``"most-probable"`` (the likeliest mode fed back and
    recorded).
    """

    model_config = STRICT

    modes: list[ImmModeOptions] = Field(min_length=2)
    transition: list[list[float]]
    transition_interval: Union[Duration, Literal["epoch"]] = 1.0  # type: ignore[valid-type]
    initial_probabilities: list[float] | None = None
    output: Literal["combined", "most-probable"] = "combined"

    @field_validator("transition")
    @classmethod
    def _stochastic(cls, v):
        try:
            check_transition(v)
        except ArgumentError as e:
            raise ValueError(e.message) from None
        return v

    @model_validator(mode="after")
    def _shapes(self):
        r = len(self.modes)
        if len(self.transition) != r:
            raise ValueError(f"transition must be {r} x {r} (one row and column per mode), got "
                             f"{len(self.transition)} rows")
        if self.initial_probabilities is not None:
            p = self.initial_probabilities
            if len(p) != r or any(x < 0 for x in p) or abs(sum(p) - 1.0) > 1e-9:
                raise ValueError(f"initial_probabilities must be {r} non-negative numbers summing to 1, got {p}")
        names = [m.name for m in self.modes]
        if len(set(names)) != len(names):
            raise ValueError(f"mode names must be unique, got {names}")
        return self

    def training_needs(self) -> list:
        """The modes' training needs (an IMM's mixture modes learn too; a mode is never coloured)."""
        return [need for mode in self.modes for need in training_needs(mode)]


def check_imm_entry(options: ImmOptions, measurements, mode: bool) -> None:
    """The IMM's registration check: every mode's measurements among the method's
    (``"gnss"`` and its aiding)."""
    aiding = [m for m in measurements if m != "gnss"]
    for k, m in enumerate(options.modes):
        missing = [x for x in m.measurements if x != "gnss" and x not in aiding]
        if missing:
            raise ValueError(f"imm.modes[{k}] ('{m.name}') uses {missing}, which the method's "
                             f"aiding does not list ({aiding})")
