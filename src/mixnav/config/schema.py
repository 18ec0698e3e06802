"""The strict schema of scenario files.

Every key is known (an unknown key is an error), every value with a unit
carries it as text (``"2 deg/h"``) and is converted to SI here, through
:mod:`mixnav.units`, once, at load time. The models hold SI floats after
validation, so nothing downstream parses units again.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, field_validator, model_validator

from .. import units as u


def _quantity(dim, positive: bool = False, nonnegative: bool = False):
    def parse(v):
        if isinstance(v, bool):
            raise ValueError("expected a quantity with a unit, e.g. '2 deg/h'")
        x = u.parse_quantity(v, dim)
        if positive and not x > 0:
            raise ValueError(f"must be positive, got {v!r}")
        if nonnegative and not x >= 0:
            raise ValueError(f"must not be negative, got {v!r}")
        return x
    return Annotated[float, BeforeValidator(parse)]


def _vector(dim, positive: bool = False):
    item = _quantity(dim, positive=positive)

    def check_len(v):
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise ValueError("expected a list of three quantities, e.g. [\"1 m\", \"1 m\", \"2 m\"]")
        return v
    return Annotated[tuple[item, item, item], BeforeValidator(check_len)]


Angle = _quantity(u.ANGLE)
Rate = _quantity(u.ANGULAR_RATE)
Length = _quantity(u.LENGTH)
Speed = _quantity(u.VELOCITY, nonnegative=True)
Accel = _quantity(u.ACCELERATION)
Duration = _quantity(u.TIME, positive=True)
Time = _quantity(u.TIME, nonnegative=True)
Frequency = _quantity(u.FREQUENCY, positive=True)
PosSigma = _vector(u.LENGTH, positive=True)
VelSigma = _vector(u.VELOCITY, positive=True)
AngSigma = _vector(u.ANGLE, positive=True)
LengthVec = _vector(u.LENGTH)
AngleVec = _vector(u.ANGLE)


def _ordered_windows(v):
    for i, (a, b) in enumerate(v):
        if not b > a:
            raise ValueError(f"window {i} ends ({b:g} s) before it starts ({a:g} s)")
    return v


#: Time windows ``[[start, end], ...]`` with each end after its start.
Windows = Annotated[list[tuple[Time, Time]], AfterValidator(_ordered_windows)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


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


ClockNoise = _quantity(u.Dimension(0.0, 1.0, -0.5), nonnegative=True)       # m/sqrt(s)
ClockDriftNoise = _quantity(u.VELOCITY_RANDOM_WALK, nonnegative=True)       # m/s/sqrt(s)


class SatellitesConfig(Strict):
    """Simulated satellites and raw observables (``[gnss.satellites]``), for the
    tight filters. Sigmas are what the filters are told and, unless a noise
    process is given for that observable, the Gaussian noise added."""

    constellation: Literal["gps24", "gps30"] = "gps30"
    mask: Angle = float(np.radians(10.0))
    pseudorange_sigma: _quantity(u.LENGTH, positive=True)
    range_rate_sigma: _quantity(u.VELOCITY, positive=True)
    carrier_sigma: _quantity(u.LENGTH, positive=True) = 0.003
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
    clock_sigma: tuple[_quantity(u.LENGTH, positive=True), _quantity(u.VELOCITY, positive=True)] = \
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

    slip_sigma: _quantity(u.ANGLE, nonnegative=True) = 0.0  # type: ignore[valid-type]
    slip_time: Duration = 5.0
    bump_sigma: _quantity(u.ANGLE, nonnegative=True) = 0.0  # type: ignore[valid-type]
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
    sigma: _quantity(u.VELOCITY, positive=True)  # type: ignore[valid-type]
    scale_factor: _quantity(u.DIMENSIONLESS) = 0.0  # type: ignore[valid-type]
    quantum: _quantity(u.VELOCITY, positive=True) | None = None  # type: ignore[valid-type]
    lever_arm: LengthVec = (0.0, 0.0, 0.0)

    @field_validator("scale_factor")
    @classmethod
    def _scale(cls, v):
        if not abs(v) < 0.5:
            raise ValueError(f"scale factor error {v:g} is not a small fraction (write e.g. \"0.5 %\")")
        return v


class RobustConfig(Strict):
    """Robust adaptive EKF (``estimator = "robust-adaptive"``): IGG-III
    thresholds ``k0 < k1`` on standardised innovations and the adaptive-factor
    threshold ``c`` (see mixnav.filters.robust)."""

    k0: float = Field(default=2.5, gt=0)
    k1: float = Field(default=5.0, gt=0)
    c: float = Field(default=1.5, gt=0)

    @model_validator(mode="after")
    def _order(self):
        if not self.k0 < self.k1:
            raise ValueError(f"need k0 < k1, got k0 = {self.k0}, k1 = {self.k1}")
        return self


class MixtureSpec(Strict):
    """A 1-D mixture of a standardised noise: ``weights`` summing to 1,
    ``means`` (in units of the model's sigma; default zeros) and variance
    ``scales`` (multiples of the model's variance)."""

    weights: list[Annotated[float, Field(ge=0)]] = Field(min_length=1)
    means: list[float] | None = None
    scales: list[Annotated[float, Field(gt=0)]]

    @model_validator(mode="after")
    def _consistent(self):
        k = len(self.weights)
        if len(self.scales) != k or (self.means is not None and len(self.means) != k):
            raise ValueError("weights, means and scales need one entry per component")
        if abs(sum(self.weights) - 1.0) > 1e-6:
            raise ValueError(f"weights must sum to 1, got {sum(self.weights):.6g}")
        return self


class OnlineLearnConfig(Strict):
    """Online re-learning of the measurement mixtures (M4 beyond paper P1,
    ``mixture.learn.online``; see :mod:`mixnav.noise.learn.online`): per observable
    kind of ``learn.observables``, the last ``window`` rows' standardised
    innovations (rows, not epochs: 600 pseudorange rows are about 70 s of 8-9
    satellites at 1 Hz) are refitted by VB, warm-started from the mixture in
    use, every ``every`` measurement epochs once the window is full (default
    20: a third of a 600-row window is new at each refit; the window, not
    ``every``, sets how fast a change is tracked). Rows more than ``gate``
    standard deviations from every component of the mixture in use are left
    out of the fit (gross errors)."""

    window: int = Field(default=600, ge=20)
    every: int = Field(default=20, ge=1)
    gate: float = Field(default=10.0, ge=3)


class LearnConfig(Strict):
    """Mixtures learned offline from a training stretch (M4: ``method = "vb"``,
    M5: ``"gibbs"``; ``"em"`` too). In a scenario the training residuals are
    the scenario's own noise processes drawn over a separate stretch
    (``training_samples`` residuals per mixture, stream ``training``) and
    standardised by the sigma the filter is told.

    ``online`` (a table, :class:`OnlineLearnConfig`) also re-learns the
    ``observables``' mixtures online from the filter's innovations (VB only).
    ``offline = false`` skips the training stretch: the online learner then
    starts from the mixtures given under ``mixture.measurement`` (Gaussian for
    a kind not given), which also works on real data. ``process`` (learn the
    process-noise mixture offline) defaults to ``offline``."""

    method: Literal["vb", "gibbs", "em"]
    observables: list[Literal["pseudorange", "range_rate", "tdcp", "position", "velocity"]] = \
        Field(default_factory=lambda: ["pseudorange", "tdcp"])
    process: bool | None = None
    training_samples: int = Field(default=2000, ge=10)
    n_components: int = Field(default=4, ge=1)
    gibbs_samples: int = Field(default=1000, ge=10)
    prune: float = Field(default=0.01, ge=0, lt=1)
    offline: bool = True
    online: OnlineLearnConfig | None = None

    @model_validator(mode="after")
    def _online(self):
        if self.online is not None and self.method != "vb":
            raise ValueError(f"online re-learning uses the VB learner (warm starts): it needs "
                             f"method = \"vb\", got \"{self.method}\"")
        if not self.offline:
            if self.online is None:
                raise ValueError("offline = false learns nothing: add an 'online' table "
                                 "(or give the mixtures under mixture.measurement without 'learn')")
            if self.process:
                raise ValueError("process = true needs the training stretch (offline = true): the "
                                 "process-noise mixture is not re-learned online")
        if self.online is not None:
            if not self.observables:
                raise ValueError("online re-learning needs at least one kind in 'observables'")
            if self.online.window < 10 * self.n_components:
                raise ValueError(f"online.window = {self.online.window} rows is too short for "
                                 f"n_components = {self.n_components}: give at least 10 rows per "
                                 f"component ({10 * self.n_components})")
        return self

    @property
    def learn_process(self) -> bool:
        """Whether the process-noise mixture is learned (offline)."""
        return self.offline if self.process is None else self.process


_Psi = Annotated[float, Field(gt=-1, lt=1)]


class ColoredConfig(Strict):
    """Coloured noise (M6, paper P2): AR(1) coefficients of the process noise
    (``process``, per ``process_interval``, on the epoch's white IMU noise) and
    of each observable's measurement noise (``measurement``, per epoch, per
    channel), each ``|psi| < 1``. With a ``[mixture.colored]`` table the mixtures
    are those of the white driving noises (P2 eqs. 6-7). ``"fit"`` fits the
    coefficient to the training stretch (AR(1) per channel, median over channels;
    scenarios only). ``channels`` overrides the coefficient of single channels,
    ``"<observable>:<id>" = psi`` with ``id`` the PRN (tight) or axis 0-2 (loose).
    See mixnav.filters.colored."""

    process: _Psi | Literal["fit"] = 0.0
    measurement: dict[Literal["pseudorange", "range_rate", "position", "velocity"], _Psi | Literal["fit"]] = \
        Field(default_factory=dict)
    process_interval: Duration = 1.0
    channels: dict[str, _Psi] = Field(default_factory=dict)


class MixtureConfig(Strict):
    """Gaussian-mixture EKF (``estimator = "gaussian-mixture"``): prior,
    process-noise and per-observable measurement-noise mixtures, given or
    learned, and the bank size after reduction; with ``colored``, the
    coloured-noise variant M6. The update's guards (:mod:`mixnav.filters._bank_kernels`):
    ``gate`` (rows whose state share of the predicted variance exceeds ``gate`` times the
    noise's use the mixture's moment-matched Gaussian), ``outlier_mean`` (components
    whose standardised mean exceeds it leave the rows they explain unused); the
    divergence safeguard:
    ``divergence_window`` epochs in a row with the merged NIS per row above
    ``divergence_nis`` add the initial covariance back (0: off). ``inf``, ``inf`` and
    0 give P1's plain update."""

    max_components: int = Field(default=16, ge=1)
    gate: float = Field(default=2.0, gt=0)
    outlier_mean: float = Field(default=4.0, gt=0)
    divergence_window: int = Field(default=10, ge=0)
    divergence_nis: float = Field(default=9.0, gt=0)
    prior: MixtureSpec | None = None
    process: MixtureSpec | None = None
    measurement: dict[Literal["pseudorange", "range_rate", "tdcp", "position", "velocity"], MixtureSpec] = \
        Field(default_factory=dict)
    learn: LearnConfig | None = None
    colored: ColoredConfig | None = None


Fraction = _quantity(u.DIMENSIONLESS)
NonNegSpeed = _quantity(u.VELOCITY, nonnegative=True)
PosSpeed = _quantity(u.VELOCITY, positive=True)
PosAccel = _quantity(u.ACCELERATION, positive=True)
PosRate = _quantity(u.ANGULAR_RATE, positive=True)
PosAngle = _quantity(u.ANGLE, positive=True)
PosLength = _quantity(u.LENGTH, positive=True)


class NhcConfig(Strict):
    """Non-holonomic constraints (``mixnav.measurements.vehicle.NonHolonomic``):
    epochs at ``rate``; ``sigma`` the lateral and vertical velocity the vehicle
    really has (slip, bumps); no rows below ``min_speed``. The violations are
    correlated over seconds, and the rows are treated as independent: at 10 Hz
    the filter over-trusts them tenfold (vehicle-demo: position NEES 16-19 in
    the outages at 10 Hz, 3-4 at 1 Hz, and smaller errors), hence 1 Hz."""

    rate: Frequency = 1.0
    sigma: tuple[PosSpeed, PosSpeed] = (0.1, 0.1)
    min_speed: NonNegSpeed = 0.0


class OdometerAidingConfig(Strict):
    """Odometer aiding (``mixnav.measurements.vehicle.Odometer``). In a dataset,
    ``format``/``file`` name the speeds (``csv``: docs/data_formats.md); in a
    scenario the simulated odometer is used. ``sigma`` [m/s] when the file gives
    none; ``scale`` a known scale error; ``scale_sigma`` the initial 1-sigma of
    the estimated one (method ``estimate = ["odometer_scale"]``); ``lever_arm``
    the wheel (axle centre) in the body frame from the IMU, default the
    vehicle point. ``max_gap``: a hole between the file's samples longer than this
    warns and is counted (``odometer_gaps_accepted`` in metrics.json), or with
    ``gap_action = "fail"`` is an error naming the file and line (default: no limit)."""

    format: Literal["csv"] = "csv"
    file: str | None = None
    max_gap: Duration | None = None  # type: ignore[valid-type]
    gap_action: Literal["warn", "fail"] = "warn"
    sigma: PosSpeed = 0.05
    scale: Fraction = 0.0
    scale_sigma: Fraction = 0.01
    lever_arm: LengthVec | None = None
    rate: Frequency | None = None


class ZuptConfig(Strict):
    """Zero-velocity updates at the epochs the stillness detector finds
    (``mixnav.measurements.stillness.detect_still``: window, thresholds), at
    ``rate``; ``sigma`` the velocity at rest; no update while the navigation
    solution moves faster than ``max_speed`` (an IMU alone cannot tell rest from
    a smooth constant-velocity drive)."""

    rate: Frequency = 5.0
    sigma: PosSpeed = 0.02
    window: Duration = 1.0
    accel_std: PosAccel = 0.1
    gyro_rate: PosRate = 0.03
    gnss_speed: PosSpeed = 0.1
    min_duration: Time = 1.0
    max_speed: PosSpeed = 1.0


class ZaruConfig(Strict):
    """Zero angular-rate updates at the ZUPT epochs; ``sigma`` of one compensated
    gyro sample at rest."""

    sigma: PosRate = 0.01


class AidingConfig(Strict):
    """Land-vehicle aiding shared by the methods that list it (``aiding = [...]``).

    ``vehicle_mounting``: roll, pitch, yaw of the IMU body frame in the vehicle
    frame (x forward, y right, z down); NHC and the odometer need it (a dataset
    whose body frame is not a vehicle frame cannot use them).
    ``vehicle_point``: where the constraints hold (rear-axle centre), body frame
    from the IMU. ``mounting_sigma``: initial 1-sigma of the estimated mounting
    pitch/yaw corrections (method ``estimate = ["mounting"]``).
    ``gnss_lever_sigma`` and ``time_offset_sigma``: initial 1-sigma of the
    estimated corrections of the antenna lever arm (``estimate = ["gnss_lever"]``)
    and of the IMU time offset (``estimate = ["imu_time_offset"]``), loose
    coupling (:mod:`mixnav.measurements.loose`).
    """

    vehicle_mounting: AngleVec | None = None
    vehicle_point: LengthVec = (0.0, 0.0, 0.0)
    mounting_sigma: PosAngle = 0.05
    gnss_lever_sigma: PosLength = 0.5
    time_offset_sigma: Duration = 0.1
    nhc: NhcConfig | None = None
    odometer: OdometerAidingConfig | None = None
    zupt: ZuptConfig | None = None
    zaru: ZaruConfig | None = None


class EmBiasConfig(Strict):
    """The EM multipath-bias removal of an EM-IMM mode (``[methods.imm.modes.em]``,
    :mod:`mixnav.filters.em_bias`): the sliding ``window`` [s], ``min_samples`` in it before
    a fit (at least the two components), ``min_separation`` [m] (also at least
    ``min_separation_sigmas`` of the biased component's spread) and ``min_weight`` of the
    biased component before a bias is declared, ``max_state_sigma`` [m] (innovations enter
    the window only while the state's position sigma is at most this; default a third of
    ``min_separation``) and ``gate`` (chi-square probability above which position rows the
    current noise model cannot explain are kept out of the update), ``refit_every`` (epochs
    between EM fits, each warm-started from the last)."""

    window: Duration = 60.0  # type: ignore[valid-type]
    min_samples: int = Field(default=20, ge=2, description="at least one sample per component")
    min_separation: PosLength = 3.0  # type: ignore[valid-type]
    min_weight: float = Field(default=0.05, ge=0.0, lt=0.5)
    min_separation_sigmas: float = Field(default=2.0, ge=0.0)
    max_state_sigma: PosLength | None = None  # type: ignore[valid-type]
    gate: float = Field(default=0.9999, gt=0.5, lt=1.0)
    refit_every: int = Field(default=5, ge=1)


class ImmModeConfig(Strict):
    """One mode of an IMM (``[[methods.imm.modes]]``): its name, the measurements that update
    it (``"gnss"``, the method type's GNSS model, and any of the method's ``aiding``) and
    its estimator: ``"ekf"``, ``"robust-adaptive"`` (optional ``[robust]`` table),
    ``"em-bias"`` (the EM-IMM's GNSS mode: the EKF with the EM multipath-bias removal on its
    GNSS rows, optional ``[em]`` table) or ``"gaussian-mixture"`` (a bank, optional
    ``[mixture]`` table as a method's, learned offline or online; not coloured)."""

    name: str = Field(min_length=1)
    measurements: list[Literal["gnss", "nhc", "odometer", "zupt", "zaru"]] = Field(
        min_length=1, description="a mode with no measurements is pure inertial navigation, never told apart")
    #: a registered estimator that can be a mode (``imm_mode`` in mixnav.filters.registry)
    estimator: str = "ekf"
    robust: RobustConfig | None = None
    em: EmBiasConfig | None = None
    mixture: MixtureConfig | None = None

    @field_validator("estimator")
    @classmethod
    def _mode_estimator(cls, v):
        from ..errors import ArgumentError
        from ..filters.registry import estimator_names, estimator_spec
        try:
            ok = estimator_spec(v).imm_mode
        except ArgumentError:
            ok = False
        if not ok:
            modes = [n for n in estimator_names(standalone_only=False) if estimator_spec(n).imm_mode]
            raise ValueError(f"estimator '{v}' cannot be a mode of an IMM (these can: {', '.join(modes)})")
        return v

    @model_validator(mode="after")
    def _unique(self):
        if len(set(self.measurements)) != len(self.measurements):
            raise ValueError(f"a measurement is listed twice: {self.measurements}")
        if self.robust is not None and self.estimator != "robust-adaptive":
            raise ValueError("a [robust] table needs estimator = \"robust-adaptive\"")
        if self.em is not None and self.estimator != "em-bias":
            raise ValueError("an [em] table needs estimator = \"em-bias\"")
        if self.mixture is not None and self.estimator != "gaussian-mixture":
            raise ValueError("a [mixture] table needs estimator = \"gaussian-mixture\"")
        if self.mixture is not None and self.mixture.colored is not None:
            raise ValueError("a mode cannot be the coloured-noise bank (M6: it differences the measurements "
                             "and carries AR(1) states the other modes do not have)")
        if self.estimator == "em-bias" and "gnss" not in self.measurements:
            raise ValueError("an em-bias mode removes a bias from the GNSS: list \"gnss\" in its measurements")
        return self


class ImmConfig(Strict):
    """Interacting multiple models (``estimator = "imm"``, :mod:`mixnav.filters.imm`).

    ``transition[i][j]``: probability of mode j one ``transition_interval`` after mode i
    (rows sum to one; default interval 1 s, or ``"epoch"`` to apply it once per
    measurement epoch as P4 does); ``initial_probabilities`` default uniform; ``output``
    ``"combined"`` (P4, default) or ``"most-probable"`` (the likeliest mode fed back and
    recorded).
    """

    modes: list[ImmModeConfig] = Field(min_length=2)
    transition: list[list[float]]
    transition_interval: Union[Duration, Literal["epoch"]] = 1.0  # type: ignore[valid-type]
    initial_probabilities: list[float] | None = None
    output: Literal["combined", "most-probable"] = "combined"

    @field_validator("transition")
    @classmethod
    def _stochastic(cls, v):
        from ..filters.imm import check_transition
        from ..errors import ArgumentError
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


def registered_estimator(name: str, motion: str) -> str:
    """``name`` if the estimator registry (:mod:`mixnav.filters.registry`) knows it and it runs
    on ``motion``; otherwise a ValueError saying which are registered or where it runs."""
    from ..errors import ArgumentError
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
    from ..errors import ArgumentError
    from ..filters.registry import estimator_spec
    if name is None or not options:
        return options
    try:
        spec = estimator_spec(name)
    except ArgumentError:
        return options          # the estimator's own check says it
    if spec.table is not None:
        raise ValueError(f"estimator \"{name}\" takes its settings from its own table ([{spec.table}]), "
                         "not [options]")
    try:
        checked = spec.parse_options(options)
    except ArgumentError as exc:
        raise ValueError(f"options.{exc.argument}: {exc.message}") from None
    return {k: getattr(checked, k) for k in options}


class MethodConfig(Strict):
    name: str
    type: Literal["loose-ekf", "tight-ekf", "tdcp-ekf"]
    #: a registered estimator (mixnav.filters.registry) that runs on the strapdown INS: "ekf" (M1),
    #: "robust-adaptive" (M2), "gaussian-mixture" (M3; M4/M5 with mixture.learn), "sage-husa", ...
    estimator: str = "ekf"
    robust: RobustConfig | None = None
    mixture: MixtureConfig | None = None
    imm: ImmConfig | None = None
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
        # the name becomes solution_<name>.csv: one safe file-name component (docs/validation.md)
        from ..errors import ArgumentError
        from ..io.outdir import safe_name
        try:
            return safe_name(v, "method name")
        except ArgumentError as exc:
            raise ValueError(exc.message) from None

    @field_validator("estimator")
    @classmethod
    def _known_estimator(cls, v):
        return registered_estimator(v, "strapdown")

    @field_validator("options")
    @classmethod
    def _typed_options(cls, v, info):
        return registered_options(info.data.get("estimator"), v)

    @model_validator(mode="after")
    def _estimator_tables(self):
        if self.options and self.estimator == "robust-adaptive":
            raise ValueError("estimator \"robust-adaptive\" takes its settings from its own table ([robust]), "
                             "not [options]")
        if self.robust is not None and self.estimator != "robust-adaptive":
            raise ValueError("a [robust] table needs estimator = \"robust-adaptive\"")
        if self.mixture is not None and self.estimator != "gaussian-mixture":
            raise ValueError("a [mixture] table needs estimator = \"gaussian-mixture\"")
        if (self.imm is not None) != (self.estimator == "imm"):
            raise ValueError("estimator = \"imm\" and an [imm] table go together")
        if self.imm is not None:
            for k, mode in enumerate(self.imm.modes):
                missing = [x for x in mode.measurements if x != "gnss" and x not in self.aiding]
                if missing:
                    raise ValueError(f"imm.modes[{k}] ('{mode.name}') uses {missing}, which the method's "
                                     f"aiding does not list ({self.aiding})")
        return self


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
