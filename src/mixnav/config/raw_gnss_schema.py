"""The strict schema of raw-GNSS datasets (``kind = "gnss-raw"``: a phone log, a RINEX
observation file or a u-blox log with its navigation file, or a smartLoc log of corrected
pseudoranges), scored against a static ``[reference_point]`` or a moving ``[reference]``.

Every epoch is solved by weighted least squares (single-point positioning, SPP); the
``[[methods]]`` may add filters on the GNSS-only constant-velocity model
(:class:`mixnav.motion.ConstantVelocityMotion`) with any estimator that runs on a motion
model other than the strapdown INS (every registered estimator whose registration lists
``"constant-velocity"``: :mod:`mixnav.filters.registry`), started from the first SPP fix
(:mod:`mixnav.experiment.spp_process`). Same rules as every config: every key known,
units written out, errors naming the file and the key.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import Field, field_validator, model_validator

from .evaluation_schema import Evaluation
from .. import units as u
from .dataset_schema import DatasetInfo, RawGnss, ReferencePoint
from .fields import Strict, quantity
from .method_schema import registered_estimator
from .vehicle_schema import VehicleMethod, unique_method_names

#: sections of an IMU dataset that a raw-GNSS one must not have (a config error naming them)
FOREIGN_SECTIONS = ("imu", "gnss", "alignment", "installation", "aiding", "odometry", "pseudoranges")

AccelDensity = quantity(u.VELOCITY_RANDOM_WALK, nonnegative=True)


class RawMethod(VehicleMethod):
    """A method of a raw-GNSS dataset: ``estimator = "wls"`` (the epoch-by-epoch SPP; with a
    ``[methods.robust]`` table of ``k0``, ``k1`` the robust SPP, IGG-III on standardised
    residuals, :mod:`mixnav.gnss.spp`) or an estimator of the constant-velocity filter. ``robust``, ``mixture``, ``options``,
    ``smooth`` as for the odometry datasets (:class:`mixnav.config.vehicle_schema.VehicleMethod`);
    ``smooth`` adds the RTS-smoothed ``<name>-smoothed`` (filters only)."""

    motion_model: ClassVar[str] = "constant-velocity"

    estimator: str = "wls"

    @field_validator("estimator")
    @classmethod
    def _known(cls, v):
        if v == "wls":          # the epoch-by-epoch single-point solution, not a filter
            return v
        return registered_estimator(v, cls.motion_model)

    @model_validator(mode="after")
    def _wls_plain(self):
        if self.estimator == "wls":
            if self.mixture is not None:
                raise ValueError("mixture: the 'wls' method (epoch-by-epoch SPP) takes no mixture table "
                                 "(a [robust] table makes it the robust SPP)")
            if self.robust is not None and "c" in self.robust.model_fields_set:
                raise ValueError("robust.c: the robust SPP has no prediction to adapt (only k0, k1: "
                                 "IGG-III thresholds on standardised residuals)")
            if self.robust is not None and "absurd_sigma" in self.robust.model_fields_set:
                raise ValueError("robust.absurd_sigma: the robust SPP has no prediction to gate (only k0, k1: "
                                 "IGG-III thresholds on standardised residuals)")
            if self.options:
                raise ValueError("options: the 'wls' method (epoch-by-epoch SPP) takes no options")
            if self.smooth:
                raise ValueError("smooth: the 'wls' method (epoch-by-epoch SPP) has nothing to smooth")
        return self


class ConstantVelocityConfig(Strict):
    """The GNSS-only constant-velocity model of the filters (:mod:`mixnav.motion.constant_velocity`).

    ``accel_sigma``, ``vertical_accel_sigma``: white-acceleration densities (horizontal,
    vertical; e.g. ``"1 m/s^2/sqrt(Hz)"``: a pedestrian or a car, ``"0.01 m/s^2/sqrt(Hz)"``: a
    receiver known to be static); ``clock_q_bias`` [m^2/s], ``clock_q_drift`` [m^2/s^3]
    (plain numbers): the receiver clock's white-frequency and random-walk-frequency
    densities. The default ``clock_q_bias`` lets the bias move tens of metres per second:
    phones (duty-cycled chips) re-estimate their clock at every epoch, the android-static
    log by about 30 m; a receiver with a continuous clock can use a small value.
    ``step``: the prediction interval (the model is propagated in steps of at most this
    long between epochs). ``velocity_sigma``, ``clock_drift_sigma``: 1-sigma of the
    initial velocity (zero) and clock drift (zero); position and clock bias start at the
    first SPP fix with its covariance, inflated by ``position_sigma_factor``.
    ``clock_jump``: a jump of the SPP clock bias beyond its drift by more than this is
    taken off the pseudoranges the filters see (millisecond jumps exactly:
    :func:`mixnav.gnss.spp.clock_jumps`), counted in metrics.json. ``start``: the filters
    start at the first SPP fix at or after this time [s since the first epoch] (default 0:
    the first fix; the start sweep, :func:`mixnav.start_sweep`, moves it); the epoch-by-epoch
    SPP is not changed by it."""

    model: Literal["constant-velocity"] = "constant-velocity"
    accel_sigma: AccelDensity = 1.0  # type: ignore[valid-type]
    vertical_accel_sigma: AccelDensity = 0.3  # type: ignore[valid-type]
    clock_q_bias: float = Field(default=1000.0, ge=0, le=1e8)
    clock_q_drift: float = Field(default=1.0, ge=0, le=1e6)
    step: quantity(u.TIME, positive=True) = 1.0  # type: ignore[valid-type]
    velocity_sigma: quantity(u.VELOCITY, positive=True) = 5.0  # type: ignore[valid-type]
    clock_drift_sigma: quantity(u.VELOCITY, positive=True) = 100.0  # type: ignore[valid-type]
    position_sigma_factor: float = Field(default=1.0, ge=1.0, le=100.0)
    clock_jump: quantity(u.LENGTH, positive=True) = 1000.0  # type: ignore[valid-type]
    start: quantity(u.TIME, nonnegative=True) = 0.0  # type: ignore[valid-type]

    @field_validator("accel_sigma", "vertical_accel_sigma")
    @classmethod
    def _plausible(cls, v):
        # 100 m/s^2/sqrt(Hz) is 10 g of white acceleration each second: a unit slip, not a user
        if v > 100.0:
            raise ValueError(f"{v:g} m/s^2/sqrt(Hz) is beyond any vehicle (at most 100): check the unit")
        return v

    @field_validator("step")
    @classmethod
    def _short(cls, v):
        if v > 60.0:
            raise ValueError(f"a prediction step of {v:g} s is too long (at most 60 s)")
        return v


#: reference formats whose time stamps are GPS time with the week (nothing to say about them)
ABSOLUTE_TIME_FORMATS = ("gps-week-csv", "rtklib-pos", "smartloc")


class RawReference(Strict):
    """``[reference]`` of a raw-GNSS dataset: the trajectory of a moving receiver's antenna,
    every epoch scored against it at the epoch's time (:mod:`mixnav.experiment.spp_process`).

    ``format``: ``"gps-week-csv"`` (GPS week, time of week, latitude, longitude, ellipsoidal
    height: :mod:`mixnav.io.gps_week_csv`), ``"rtklib-pos"`` (an RTKLIB solution in GPST,
    e.g. an RTK fix; ``qualities``: the quality flags kept, default ``[1]``, fixed),
    ``"csv"`` (mixnav's generic reference CSV, :mod:`mixnav.io.generic_csv`),
    ``"kf-gins-nav"``, or ``"smartloc"`` (a smartLoc ``*_GT.txt``, on the log's own seconds:
    only with ``[raw_gnss] format = "smartloc"``, whose log has no GPS time either). ``time`` (``"csv"`` and ``"kf-gins-nav"`` only, whose time column is a
    bare number of seconds): ``"gps-week-seconds"`` (default: GPS seconds of the week of the
    first observation epoch, going on past 604800 s across a roll-over, as KF-GINS files and
    ``[raw_gnss] imu_time`` of the INS datasets) or ``"gps-seconds"`` (GPS seconds since
    1980-01-06). ``max_gap``: two reference samples further apart than this bound a gap;
    epochs inside a gap are not scored (counted: ``reference_epochs`` in metrics.json), as
    are epochs before the first or after the last sample; the default 1 s keeps the
    straight-line interpolation within a*T^2/8 = 0.375 m of a car accelerating or turning at
    3 m/s^2 (0.3 g)."""

    format: Literal["gps-week-csv", "rtklib-pos", "csv", "kf-gins-nav", "smartloc"]
    file: str
    time: Literal["gps-week-seconds", "gps-seconds"] = "gps-week-seconds"
    qualities: list[int] = Field(default_factory=lambda: [1])
    max_gap: quantity(u.TIME, positive=True) = 1.0  # type: ignore[valid-type]

    @model_validator(mode="after")
    def _keys_of_format(self):
        if "time" in self.model_fields_set and self.format in ABSOLUTE_TIME_FORMATS:
            raise ValueError(f"time: format \"{self.format}\" says its own time axis (the key is for "
                             "\"csv\" and \"kf-gins-nav\", whose time column is bare seconds)")
        if "qualities" in self.model_fields_set and self.format != "rtklib-pos":
            raise ValueError(f"qualities: format \"{self.format}\" has no quality flags (only \"rtklib-pos\")")
        return self


class RawGnssDataset(Strict):
    """``kind = "gnss-raw"``: ``[raw_gnss]``, at most one of ``[reference_point]`` (a static
    receiver's surveyed point) and ``[reference]`` (a moving receiver's trajectory), the
    ``[motion]`` of the filters and the ``[[methods]]`` (default: one ``wls`` method named
    ``spp``)."""

    dataset: DatasetInfo
    raw_gnss: RawGnss
    reference_point: ReferencePoint | None = None
    reference: RawReference | None = None
    motion: ConstantVelocityConfig = ConstantVelocityConfig()
    methods: list[RawMethod] | None = Field(default=None, min_length=1)
    evaluation: Evaluation | None = None

    @field_validator("methods")
    @classmethod
    def _unique(cls, v):
        return unique_method_names(v)

    def run_methods(self) -> list[RawMethod]:
        """The methods to run: ``[[methods]]``, or the SPP alone (named ``spp``)."""
        return list(self.methods) if self.methods else [RawMethod(name="spp", estimator="wls")]
