"""The strict schema of odometry + raw-GNSS datasets (``kind = "odometry-gnss"``): a land
vehicle dead-reckoned from wheel speed and yaw rate, corrected by pseudoranges of
several systems (smartLoc). Same rules as every config: every key known, units
written out, errors naming the file and the key.
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal

from pydantic import Field, field_validator

from .evaluation_schema import Evaluation
from .dataset_schema import DatasetInfo
from .fields import (Duration, ElevationMask, NonNegLength, NonNegRate, NonNegSpeed, PosAngle, PosLength, PosRate,
                     PosSpeed, Strict, Time)
from .method_schema import method_file_name, registered_estimator, registered_options, registered_table


def unique_method_names(methods):
    """A ``[[methods]]`` list whose names are distinct (the solutions are filed by name)."""
    if methods is None:
        return methods
    names = [m.name for m in methods]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"method names must be unique: {', '.join(dup)} repeated")
    return methods


#: system letters -> the data set's system codes (smartLoc's)
SYSTEM_CODES = {"G": 1, "S": 2, "R": 4, "E": 8, "J": 16, "C": 32}


class OdometryFile(Strict):
    """Wheel speed and yaw rate. ``yaw_rate_axis``: the axis the file's turn rate is about
    (``"up"``: positive turning left, smartLoc's; ``"down"``: positive turning right).
    ``speed_sigma`` / ``yaw_rate_sigma``: the filter's per-sample noise (default: the
    median of the file's variances); ``sample_interval`` their sample interval (default:
    the file's median)."""

    format: Literal["smartloc"]
    file: str
    yaw_rate_axis: Literal["up", "down"] = "up"
    speed_sigma: PosSpeed | None = None  # type: ignore[valid-type]
    yaw_rate_sigma: PosRate | None = None  # type: ignore[valid-type]
    sample_interval: Duration | None = None  # type: ignore[valid-type]


class Pseudoranges(Strict):
    """Pseudoranges (satellite clock and atmosphere removed, as smartLoc gives them).
    ``systems``: the systems used, the receiver clock's reference first (one
    inter-system offset state per further system); ``variance``: ``"given"`` (the
    file's, times ``scale``) or ``"elevation"`` (``scale (sigma_a^2 + sigma_b^2 /
    sin^2 el)``)."""

    format: Literal["smartloc"]
    file: str
    systems: list[Literal["G", "R", "E", "C", "J", "S"]] = Field(default_factory=lambda: ["G", "R"], min_length=1)
    variance: Literal["given", "elevation"] = "given"
    scale: float = Field(default=1.0, gt=0)
    sigma_a: NonNegLength = 3.0  # type: ignore[valid-type]
    sigma_b: NonNegLength = 3.0  # type: ignore[valid-type]
    elevation_mask: ElevationMask = 0.0  # type: ignore[valid-type]

    @field_validator("systems")
    @classmethod
    def _distinct(cls, v):
        if len(set(v)) != len(v):
            raise ValueError(f"systems must be distinct, got {v}")
        return v


class VehicleReference(Strict):
    format: Literal["smartloc"]
    file: str


class DeadReckoningConfig(Strict):
    """The dead-reckoning model's noise beyond the odometry's (mixnav.motion.dead_reckoning)
    and the receiver clock's (white frequency ``clock_q_bias`` [m^2/s], random-walk
    frequency ``clock_q_drift`` [m^2/s^3], plain numbers)."""

    model: Literal["dead-reckoning"] = "dead-reckoning"
    lateral_sigma: NonNegSpeed = 0.1  # type: ignore[valid-type]
    vertical_sigma: NonNegSpeed = 0.1  # type: ignore[valid-type]
    scale_sigma0: float = Field(default=0.02, ge=0)
    bias_sigma0: NonNegRate = 0.002  # type: ignore[valid-type]
    scale_walk: float = Field(default=1e-4, ge=0)
    bias_walk: float = Field(default=1e-5, ge=0)
    clock_q_bias: float = Field(default=0.01, ge=0)
    clock_q_drift: float = Field(default=1e-3, ge=0)
    offset_sigma0: PosLength = 100.0  # type: ignore[valid-type]


class VehicleAlignment(Strict):
    """``mode = "track"``: position and heading from the first ``window`` of data
    (:func:`mixnav.alignment.track.align_track`; the filter starts at its end: causal);
    ``"reference"``: from the reference trajectory at its first epoch (an oracle start,
    reported as such). ``position_sigma``, ``heading_sigma``: the initial 1-sigma.
    ``cn0_edges``: C/N0 band edges [dB-Hz, plain numbers] for a line-of-sight weight per
    band in the window's fit (reflected signals arrive weaker). ``hand_over_mixture``: the
    epoch-mixture filters start from the LOS/NLOS mixture the window's fit learned (their
    own options win; a filter without a ``cn0_edges`` option of its own takes these bands and
    their LOS weights, one with its own takes the weights only on the same bands). ``start``: the run begins this long after the first odometry sample
    (default 0: at the data's start); every odometry sample and pseudorange before it is
    discarded, as if the recording began there (the track window is then the ``window``
    after ``start``, the reference start the reference's first epoch at or after it); the
    reference is kept whole for scoring. A start that leaves no data after it is an error
    naming ``alignment.start``. ``min_distance``: the track window lasts at least
    ``window`` and until the odometry has counted this distance since its start (a track's
    heading needs travel: a recording that starts parked or crawling would otherwise align on
    a few metres; default 0: ``window`` alone; no such distance in the data is an error
    naming ``alignment.min_distance``)."""

    mode: Literal["track", "reference"] = "track"
    start: Time = 0.0  # type: ignore[valid-type]
    window: Duration = 20.0  # type: ignore[valid-type]
    min_distance: NonNegLength = 0.0  # type: ignore[valid-type]
    cn0_edges: list[float] = Field(default_factory=list)
    position_sigma: PosLength = 10.0  # type: ignore[valid-type]
    heading_sigma: PosAngle = 0.1  # type: ignore[valid-type]
    hand_over_mixture: bool = True

    @field_validator("cn0_edges")
    @classmethod
    def _increasing(cls, v):
        if any(b <= a for a, b in zip(v, v[1:])):
            raise ValueError(f"must increase strictly, got {v}")
        return v


class VehicleMethod(Strict):
    """A method of an odometry + pseudorange dataset: a registered estimator that runs on the
    dead-reckoning model (:mod:`mixnav.filters.registry`), its ``[robust]`` or ``[mixture]``
    table or its ``options``, and ``smooth``."""

    #: the motion model the methods of this kind of dataset run on
    motion_model: ClassVar[str] = "dead-reckoning"

    name: str
    estimator: str = "ekf"
    #: the estimator tables, each validated by its owner's registered model (method_schema)
    robust: Any = None
    mixture: Any = None
    options: dict[str, Any] = Field(default_factory=dict)
    smooth: bool = False

    @field_validator("name")
    @classmethod
    def _file_name(cls, v):
        return method_file_name(v)

    @field_validator("estimator")
    @classmethod
    def _known(cls, v):
        return registered_estimator(v, cls.motion_model)

    @field_validator("robust", "mixture")
    @classmethod
    def _estimator_table(cls, v, info):
        return registered_table(info.field_name, info.data.get("estimator"), v)

    @field_validator("options")
    @classmethod
    def _typed_options(cls, v, info):
        return registered_options(info.data.get("estimator"), v)


class VehicleDataset(Strict):
    dataset: DatasetInfo
    odometry: OdometryFile
    pseudoranges: Pseudoranges
    reference: VehicleReference | None = None
    motion: DeadReckoningConfig = DeadReckoningConfig()
    alignment: VehicleAlignment = VehicleAlignment()
    methods: list[VehicleMethod] = Field(min_length=1)
    evaluation: Evaluation | None = None

    @field_validator("methods")
    @classmethod
    def _unique(cls, v):
        return unique_method_names(v)
