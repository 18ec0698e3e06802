"""A method entry (``[[methods]]``) and the checks, against the estimator registry
(:mod:`mixnav.filters.registry`), of an estimator's name, its own table and its ``[options]``
that every kind of file uses.

The estimator tables (``[robust]``, ``[mixture]``, ``[imm]``, and an IMM mode's ``[em]``) are
validated by the options model the estimator that owns the table registered, beside the
estimator (mixnav.filters: robust_adaptive.RobustOptions, gmekf_options.MixtureOptions,
imm_options.ImmOptions, em_bias.EmBiasOptions): a field here is the table's key, its value
after validation an instance of that model.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ..errors import ArgumentError
from ..names import safe_name
from .fields import Duration, Strict

#: the estimator tables a method of an INS file may carry
METHOD_TABLES = ("robust", "mixture", "imm")


def method_file_name(name: str) -> str:
    """``name`` if it can be one file-name component (it becomes ``solution_<name>.csv``,
    docs/validation.md); otherwise a ValueError saying why."""
    try:
        return safe_name(name, "method name")
    except ArgumentError as exc:
        raise ValueError(exc.message) from None


def registered_estimator(name: str, motion: str) -> str:
    """``name`` if the estimator registry (:mod:`mixnav.filters.registry`) knows it and it runs
    on ``motion``; otherwise a ValueError saying which are registered or where it runs."""
    from ..filters.registry import check_motion
    try:
        check_motion(name, motion)
    except ArgumentError as exc:
        raise ValueError(exc.message) from None
    return name


def registered_options(name: str | None, options: dict) -> dict:
    """A method's ``[methods.options]`` checked against the options model the estimator
    registered: the same keys, validated values. The message starts with the option's key
    (``options.<key>: ...``), which the loader makes the error's key."""
    from ..filters.registry import checked_options
    return checked_options(name, options)


def registered_table(table: str, estimator: str | None, values):
    """A method's ``[table]`` validated by the options model the estimator that owns the table
    registered (nested errors keep their keys)."""
    from ..filters.registry import validate_table
    return validate_table(table, estimator, values)


class MethodConfig(Strict):
    name: str
    type: Literal["loose-ekf", "tight-ekf", "tdcp-ekf"]
    #: a registered estimator (mixnav.filters.registry) that runs on the strapdown INS: "ekf" (M1),
    #: "robust-adaptive" (M2), "gaussian-mixture" (M3; M4/M5 with mixture.learn), "sage-husa", ...
    estimator: str = "ekf"
    #: the estimator tables (METHOD_TABLES), each validated by its owner's registered model
    robust: Any = None
    mixture: Any = None
    imm: Any = None
    #: the settings of an estimator without a table of its own (its registered options model)
    options: dict[str, Any] = Field(default_factory=dict)
    states: Literal[15, 17, 21, 23] = 15
    covariance_interval: Duration = 1.0
    imu_grade: str | None = None
    imu_errors: dict[str, str | list[str]] | None = None
    use_range_rate: bool = True
    #: tdcp-ekf: "clone" (stochastic cloning of the previous antenna position and
    #: clock) or "known" (the shortcut that takes the previous estimate as exact)
    tdcp_previous: Literal["clone", "known"] = "clone"
    #: land-vehicle aiding this method uses (each configured in the file's [aiding] table)
    aiding: list[Literal["nhc", "odometer", "zupt", "zaru"]] = Field(default_factory=list)
    #: installation states this method estimates: "mounting" (pitch/yaw in the vehicle),
    #: "odometer_scale", "gnss_lever" (antenna lever-arm correction), "imu_time_offset"
    estimate: list[Literal["mounting", "odometer_scale", "gnss_lever", "imu_time_offset"]] = \
        Field(default_factory=list)
    #: also run the fixed-interval RTS smoother: adds a method "<name>-smoothed"
    smooth: bool = False

    @field_validator("name")
    @classmethod
    def _file_name(cls, v):
        return method_file_name(v)

    @field_validator("estimator")
    @classmethod
    def _known_estimator(cls, v):
        return registered_estimator(v, "strapdown")

    @field_validator("options")
    @classmethod
    def _typed_options(cls, v, info):
        return registered_options(info.data.get("estimator"), v)

    @field_validator(*METHOD_TABLES)
    @classmethod
    def _estimator_table(cls, v, info):
        return registered_table(info.field_name, info.data.get("estimator"), v)

    @model_validator(mode="after")
    def _estimator_tables(self):
        from ..filters.registry import check_entry
        check_entry(self, self.estimator, METHOD_TABLES, ["gnss", *self.aiding], mode=False)
        return self
