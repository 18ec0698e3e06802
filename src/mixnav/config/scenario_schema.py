"""The strict schema of scenario files (``mixnav simulate`` / ``mixnav experiment``): the
simulated trajectory, IMU, GNSS, satellites, vehicle, installation and odometer, the initial
errors, the sweep, and the file as a whole (its ``[[methods]]`` and ``[aiding]`` tables are
:mod:`.method_schema` and :mod:`.aiding_schema`, shared with the dataset files).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import AfterValidator, BeforeValidator, Field, field_validator, model_validator

from .. import units as u
from .aiding_schema import AidingConfig
from .fields import (AngSigma, Accel, Angle, AngleVec, Duration, Frequency, Length, LengthVec, PosSigma, Rate, Speed,
                     Strict, Time, VelSigma, Windows, check_position, quantity)
from .method_schema import MethodConfig


class ScenarioInfo(Strict):
    """``report_table``: metric keys (docs/outputs.md, e.g. ``pitch_rmse_deg``,
    ``outage0_horizontal_max_m``) of the headline table that ``mixnav
    experiment`` puts first in its report (a paper's table), also the metrics
    drawn against a swept value."""

    name: str
    description: str = ""
    seed: Annotated[int, Field(ge=0)] = 0
    report_table: list[str] = Field(default_factory=list)


class StaticSegment(Strict):
    type: Literal["static"]
    duration: Duration


class UniformSegment(Strict):
    type: Literal["uniform"]
    duration: Duration


class AccelerateSegment(Strict):
    type: Literal["accelerate"]
    duration: Duration
    acceleration: Accel


class TurnSegment(Strict):
    """A level turn: give the yaw rate or the total heading change."""

    type: Literal["turn"]
    duration: Duration
    yaw_rate: Rate | None = None
    angle: Angle | None = None

    @model_validator(mode="after")
    def _one_of(self):
        if (self.yaw_rate is None) == (self.angle is None):
            raise ValueError("give exactly one of 'yaw_rate' or 'angle'")
        return self

    @property
    def rate(self) -> float:
        return self.yaw_rate if self.yaw_rate is not None else self.angle / self.duration


class ClimbSegment(Strict):
    """A pitch change (negative to descend): give the pitch rate or the angle."""

    type: Literal["climb"]
    duration: Duration
    pitch_rate: Rate | None = None
    angle: Angle | None = None

    @model_validator(mode="after")
    def _one_of(self):
        if (self.pitch_rate is None) == (self.angle is None):
            raise ValueError("give exactly one of 'pitch_rate' or 'angle'")
        return self

    @property
    def rate(self) -> float:
        return self.pitch_rate if self.pitch_rate is not None else self.angle / self.duration


Segment = Annotated[
    Union[StaticSegment, UniformSegment, AccelerateSegment, TurnSegment, ClimbSegment],
    Field(discriminator="type"),
]


def _position(v):
    check_position(*v)
    return v


class TrajectoryConfig(Strict):
    start: Annotated[tuple[Angle, Angle, Length], BeforeValidator(
        lambda v: v if isinstance(v, (list, tuple)) and len(v) == 3 else
        (_ for _ in ()).throw(ValueError("expected [latitude, longitude, height] with units"))),
        AfterValidator(_position)]
    attitude: AngleVec = (0.0, 0.0, 0.0)
    speed: Speed = 0.0
    segments: list[Segment]


class ImuConfig(Strict):
    """``white_noise``: an optional dimensionless noise process (e.g. the
    mixture 0.1 N(0, 3) + 0.9 N(0, 1) of P1-sim2) whose samples replace the
    standard normal that multiplies the ARW and VRW densities, so the filter's
    Gaussian Q is mismatched on purpose.

    ``white_noise_hold``: optional duration T (a whole number of IMU
    intervals, at most the run). Without it the multiplier is drawn per IMU
    sample, so over a GNSS epoch of ~100 samples a mixture averages towards a
    Gaussian and an AR(1) is coloured at the sample rate. With it the
    multiplier is drawn once per interval ``(t0 + kT, t0 + (k+1)T]`` (t0 the
    start of the run, the process sampled at the interval ends) per channel,
    and held as a rate noise: each sample's angle (velocity) noise is
    ``x_k ARW dt / sqrt(T)`` (``x_k VRW dt / sqrt(T)``), so the noise
    integrated over interval k is ``x_k ARW sqrt(T)``, variance
    ``ARW^2 T x_k^2``. The epoch-level process noise is then exactly the
    process: a mixture stays a mixture, and ``{type = "ar1", coefficient = psi,
    innovation = <mixture>}`` is paper P2's coloured ``W_k = H W_{k-1} + xi_k``
    (eq. 6) with ``H = psi I``. Gyro and accelerometer channels are
    independent draws (see mixnav.ins.imu_model.corrupt)."""

    rate: Frequency
    grade: str | None = None
    errors: dict[str, str | list[str]] = Field(default_factory=dict)
    white_noise: dict | None = None
    white_noise_hold: Duration | None = None


class SatelliteOutageConfig(Strict):
    """Satellites lost in ``window``: the listed ``prns``, or all but the
    ``keep`` highest (``keep = 0``: all of them). With ``fraction`` the loss
    applies only at that share of the window's epochs, drawn at random."""

    window: tuple[Time, Time]
    prns: list[int] = Field(default_factory=list)
    keep: int | None = Field(default=None, ge=0)
    fraction: float | None = Field(default=None, gt=0.0, le=1.0)

    @model_validator(mode="after")
    def _one_rule(self):
        if not self.window[1] > self.window[0]:
            raise ValueError(f"window ends ({self.window[1]:g} s) before it starts ({self.window[0]:g} s)")
        if (self.keep is None) == (not self.prns):
            raise ValueError("give either 'prns' (the satellites lost) or 'keep' (how many of the "
                             "highest stay)")
        return self


ClockNoise = quantity(u.Dimension(0.0, 1.0, -0.5), nonnegative=True)       # m/sqrt(s)
ClockDriftNoise = quantity(u.VELOCITY_RANDOM_WALK, nonnegative=True)       # m/s/sqrt(s)


class SatellitesConfig(Strict):
    """Simulated satellites and raw observables (``[gnss.satellites]``), for the
    tight filters. Sigmas are what the filters are told and, unless a noise
    process is given for that observable, the Gaussian noise added."""

    constellation: Literal["gps24", "gps30"] = "gps30"
    #: systems simulated (RINEX letters), GPS's satellites from ``constellation``, the others
    #: their nominal 24-slot constellations (mixnav.gnss.constellation); the receiver clock is
    #: the first's, the others' observations carry ``system_offsets`` on top
    systems: list[Literal["G", "R", "E", "C"]] = Field(default_factory=lambda: ["G"])
    #: the receiver's true inter-system offset of each system after the first [m] (what a
    #: receiver's inter-signal hardware delays add; the tight filters estimate them)
    system_offsets: list[quantity(u.LENGTH)] = Field(default_factory=list)  # type: ignore[valid-type]
    mask: quantity(u.ANGLE, below=(math.pi / 2, "90 deg (the zenith)")) = float(np.radians(10.0))  # type: ignore[valid-type]
    pseudorange_sigma: quantity(u.LENGTH, positive=True)
    range_rate_sigma: quantity(u.VELOCITY, positive=True)
    carrier_sigma: quantity(u.LENGTH, positive=True) = 0.003
    clock_bias_noise: ClockNoise = float(np.sqrt(0.1))
    clock_drift_noise: ClockDriftNoise = 0.1
    outages: list[SatelliteOutageConfig] = Field(default_factory=list)
    pseudorange_noise: dict | None = None
    range_rate_noise: dict | None = None
    carrier_noise: dict | None = None

    @property
    def n_satellites(self) -> int:
        return {"gps24": 24, "gps30": 30}[self.constellation]

    @model_validator(mode="after")
    def _known_prns(self):
        if len(set(self.systems)) != len(self.systems) or not self.systems:
            raise ValueError(f"systems: give distinct systems, got {self.systems}")
        if len(self.system_offsets) not in (0, len(self.systems) - 1):
            raise ValueError(f"system_offsets: one per system after the first ({len(self.systems) - 1} for "
                             f"systems = {self.systems}), got {len(self.system_offsets)}")
        for i, o in enumerate(self.outages):
            bad = [p for p in o.prns if not 1 <= p <= self.n_satellites]
            if bad:
                raise ValueError(f"outages[{i}]: PRN {bad} not in the {self.constellation} "
                                 f"constellation (1-{self.n_satellites})")
        return self


class GnssConfig(Strict):
    """Simulated fixes. ``position_sigma``/``velocity_sigma`` are what the
    filters are told (their R); the noise actually added is Gaussian with
    those sigmas unless ``position_noise``/``velocity_noise`` give a noise
    process (see mixnav.noise.processes.from_config), in NED per axis.
    ``losses``: ``[start, end, probability]`` windows in which each fix is lost
    independently with that probability (a receiver dropping epochs under foliage or
    in a street canyon; stream ``gnss-loss``, so the other draws do not change)."""

    rate: Frequency
    position_sigma: PosSigma
    velocity_sigma: VelSigma | None = None
    lever_arm: LengthVec = (0.0, 0.0, 0.0)
    outages: Windows = Field(default_factory=list)
    losses: list[tuple[Time, Time, Annotated[float, Field(ge=0.0, le=1.0)]]] = Field(default_factory=list)
    position_noise: dict | None = None
    velocity_noise: dict | None = None
    satellites: SatellitesConfig | None = None


    @field_validator("losses")
    @classmethod
    def _loss_windows(cls, v):
        for i, (a, b, _) in enumerate(v):
            if not b > a:
                raise ValueError(f"losses[{i}]: end ({b:g} s) must be after start ({a:g} s)")
        return v


class InitConfig(Strict):
    """1-sigma initial errors: the filter starts at truth plus a draw of these.
    ``clock_sigma`` (bias, drift) is the spread of the true receiver clock,
    whose estimate starts at zero."""

    attitude_sigma: AngSigma
    velocity_sigma: VelSigma
    position_sigma: PosSigma
    clock_sigma: tuple[quantity(u.LENGTH, positive=True), quantity(u.VELOCITY, positive=True)] = \
        (10.0, 1.0)


class VehicleConfig(Strict):
    """Violations of the non-holonomic constraints by the simulated vehicle
    (``[vehicle]``; absent: none, the velocity stays along the vehicle's x axis).

    ``slip_sigma`` / ``slip_time``: sideslip angle ``beta`` (std, correlation
    time) between the velocity and the vehicle's x axis in its x-y plane;
    ``bump_sigma`` / ``bump_time``: the angle ``alpha`` out of that plane (down
    positive). In the vehicle frame the velocity is
    ``speed * [sqrt(1 - sin^2 beta - sin^2 alpha), sin beta, sin alpha]``, so
    the violations vanish at rest. Each angle is a first-order Gauss-Markov
    sequence at knots every quarter correlation time (whole IMU intervals)
    joined by a C2 cubic spline (smooth, so the ideal IMU has finite rates).
    The realisation is part of the trajectory: drawn from stream ``vehicle``
    of ``seed`` (not the run's seed), the same for every run of the scenario.
    A sigma of zero (default) switches that violation off."""

    slip_sigma: quantity(u.ANGLE, nonnegative=True) = 0.0  # type: ignore[valid-type]
    slip_time: Duration = 5.0
    bump_sigma: quantity(u.ANGLE, nonnegative=True) = 0.0  # type: ignore[valid-type]
    bump_time: Duration = 1.0
    seed: Annotated[int, Field(ge=0)] = 0

    @field_validator("slip_sigma", "bump_sigma")
    @classmethod
    def _small(cls, v):
        if v > np.radians(10.0):
            raise ValueError(f"{np.degrees(v):.3g} deg: NHC violations of a land vehicle are small "
                             "angles (at most 10 deg)")
        return v


class InstallationConfig(Strict):
    """How the simulated IMU sits in the vehicle (``[installation]``).

    ``imu_misalignment``: roll, pitch, yaw of the IMU axes b relative to the
    vehicle axes v (x forward, y right, z down), ``C_vb = C(misalignment)``
    with ``C(r, p, y) = Rz(y) Ry(p) Rx(r)`` (the dataset configs' key of the
    same name, with ``imu_rotation`` zero). The truth attitude is then the
    IMU's, ``C_nb = C_nv C_vb``, and the IMU measures in b."""

    imu_misalignment: AngleVec = (0.0, 0.0, 0.0)

    @field_validator("imu_misalignment")
    @classmethod
    def _small(cls, v):
        if max(abs(a) for a in v) > np.radians(45.0):
            raise ValueError("misalignment angles are at most 45 deg")
        return v


class OdometerConfig(Strict):
    """A simulated odometer (``[odometer]``; absent: none): the forward speed,
    in the vehicle frame, of the wheel point at ``lever_arm`` (from the IMU,
    in the IMU body frame), times ``1 + scale_factor``, plus Gaussian noise of
    ``sigma`` (stream ``odometer``), rounded to a multiple of ``quantum`` when
    given; negative readings (noise at rest) are clipped to zero."""

    rate: Frequency
    sigma: quantity(u.VELOCITY, positive=True)  # type: ignore[valid-type]
    scale_factor: quantity(u.DIMENSIONLESS) = 0.0  # type: ignore[valid-type]
    quantum: quantity(u.VELOCITY, positive=True) | None = None  # type: ignore[valid-type]
    lever_arm: LengthVec = (0.0, 0.0, 0.0)

    @field_validator("scale_factor")
    @classmethod
    def _scale(cls, v):
        if not abs(v) < 0.5:
            raise ValueError(f"scale factor error {v:g} is not a small fraction (write e.g. \"0.5 %\")")
        return v


class SweepConfig(Strict):
    """A parameter swept by ``mixnav experiment``: every run is repeated per value.

    ``name`` labels the swept quantity, ``values`` are its values (numbers,
    the x axis of the sweep figures), and ``set`` maps dotted scenario keys
    (``"gnss.position_noise.weights"``, ``"methods[0].states"``) to one TOML
    value per entry of ``values``. Each variant is the scenario with those
    keys replaced, validated like a scenario file (see
    :func:`mixnav.config.loader.sweep_variants`).
    """

    name: str = Field(min_length=1)
    values: list[float] = Field(min_length=1)
    set: dict[str, list] = Field(min_length=1)

    @model_validator(mode="after")
    def _lengths(self):
        if len(set(self.values)) != len(self.values):
            raise ValueError(f"sweep values must be distinct, got {self.values}")
        for k, v in self.set.items():
            if len(v) != len(self.values):
                raise ValueError(f"sweep.set.\"{k}\" has {len(v)} entries, sweep.values has "
                                 f"{len(self.values)}: give one per value")
        return self


class ScoredSegment(Strict):
    """A span of the run scored on its own (``[scoring] segments``): every accuracy metric of
    the solution rows with ``start <= time_s < end`` (half open, so that segments meeting at
    a time share no row). ``name`` (letters, digits, ``-``, ``_``) names the block in
    metrics.json (``segments.<name>``) and the columns of an experiment's results
    (``segment_<name>_<metric>``)."""

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_-]{0,39}$")]
    start: Time
    end: Time

    @model_validator(mode="after")
    def _ordered(self):
        if not self.end > self.start:
            raise ValueError(f"end ({self.end:g} s) must be after start ({self.start:g} s)")
        return self


class ScoringConfig(Strict):
    """``[scoring]``: the spans of the run scored on their own besides the whole run
    (a paper's episode: P4's multipath 1200-1800 s). Each must lie inside the run and
    the names must differ (checked by :func:`mixnav.config.loader.load_scenario`)."""

    segments: list[ScoredSegment] = Field(default_factory=list)


class Scenario(Strict):
    scenario: ScenarioInfo
    trajectory: TrajectoryConfig
    imu: ImuConfig
    gnss: GnssConfig
    init: InitConfig
    methods: list[MethodConfig] = Field(min_length=1)
    aiding: AidingConfig | None = None
    sweep: SweepConfig | None = None
    vehicle: VehicleConfig | None = None
    installation: InstallationConfig | None = None
    odometer: OdometerConfig | None = None
    scoring: ScoringConfig | None = None

    @property
    def scored_segments(self) -> list[tuple[str, float, float]]:
        """``[(name, start_s, end_s), ...]`` of ``[scoring] segments`` (empty without)."""
        return [] if self.scoring is None else [(s.name, s.start, s.end) for s in self.scoring.segments]

    @model_validator(mode="after")
    def _unique_methods(self):
        names = [m.name for m in self.methods]
        if len(set(names)) != len(names):
            raise ValueError(f"method names must be unique, got {names}")
        for i, m in enumerate(self.methods):
            if m.type in ("tight-ekf", "tdcp-ekf"):
                if self.gnss.satellites is None:
                    raise ValueError(f"methods[{i}] ({m.name}) is tightly coupled: the scenario "
                                     "needs a [gnss.satellites] table")
                if m.states in (15, 21):
                    raise ValueError(f"methods[{i}] ({m.name}) is tightly coupled: it needs the "
                                     "receiver clock states (states = 17, or 23 with the scale factors)")
        return self

    @property
    def duration(self) -> float:
        return float(sum(s.duration for s in self.trajectory.segments))

    def vector(self, v) -> np.ndarray:
        return np.asarray(v, dtype=float)
