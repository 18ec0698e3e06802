"""The strict schema of real-data configs (``mixnav process``).

Same rules as scenario files: every key known, every unit-bearing value
written with its unit, errors naming the file and the key.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from .evaluation_schema import Evaluation
from .. import units as u
from .aiding_schema import AidingConfig
from .fields import (AngleVec, AngSigma, ElevationMask, Fraction, LengthVec, PosSigma, Strict, VelSigma, Windows, check_position,
                     quantity, reader_format)
from .method_schema import MethodConfig
from ..errors import ArgumentError
from ..gnss.signals import DEFAULT_SYSTEMS, check_signals, check_systems

Offset = quantity(u.TIME)
Gap = quantity(u.TIME, positive=True)
MinSpeed = quantity(u.VELOCITY, positive=True)


class DatasetInfo(Strict):
    """``kind``: ``ins-gnss`` (IMU + GNSS fixes, ``[gnss]``, or IMU + a RINEX observation
    and navigation file, ``[raw_gnss]``, filtered by ``methods``),
    ``gnss-raw`` (raw GNSS measurements: epoch-by-epoch single-point
    positioning and constant-velocity filters, sections ``raw_gnss``,
    ``reference_point``, ``motion`` and ``methods``:
    :mod:`mixnav.config.raw_gnss_schema`) or
    ``odometry-gnss`` (wheel speed and yaw rate + pseudoranges: the dead-reckoning
    model, :mod:`mixnav.config.vehicle_schema`)."""

    name: str
    description: str = ""
    data_dir: str = "."
    kind: Literal["ins-gnss", "gnss-raw", "odometry-gnss"] = "ins-gnss"


class ImuFile(Strict):
    """IMU file: format, file names (relative to the data folder), checks, filter noise model."""

    format: reader_format("imu")  # type: ignore[valid-type]
    file: str
    tag: str | None = None
    #: drive-0708 format: where the time tag puts the first IMU tick, "tag" (the tag's start: the
    #: data README's rule) or "first-bytes" (the tag's first pair: when the first bytes came;
    #: docs/data_formats.md, "drive-0708 time tags")
    tag_start: Literal["tag", "first-bytes"] = "tag"
    max_gap: Gap = 0.05
    gap_action: Literal["warn", "fail"] = "warn"
    #: an IMU sample beyond 2000 deg/s or 50 g: "fail" (an error naming the line) or "reject"
    #: (replaced from its neighbours, counted: imu_spikes_rejected in metrics.json)
    spike_action: Literal["fail", "reject"] = "fail"
    grade: str | None = None
    errors: dict[str, str | list[str]] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _tag_keys(self):
        # only drive-0708's reader has a time-tag companion file: elsewhere the keys would be
        # ignored without a word, and a user would believe the time base was changed
        if self.format != "drive-0708":
            for key in ("tag", "tag_start"):
                if key in self.model_fields_set:
                    raise ValueError(f"{key}: read by format = \"drive-0708\" only (its time-tag file); "
                                     f"format \"{self.format}\" has no time tag")
        return self


class GnssFile(Strict):
    format: reader_format("gnss-fixes")  # type: ignore[valid-type]
    file: str
    qualities: list[int] = Field(default_factory=lambda: [1, 2, 5])
    min_sigma: quantity(u.LENGTH, nonnegative=True) = 0.0  # type: ignore[valid-type]
    use_velocity: bool = True
    # the file's velocity is valid this long before its epoch time (rtklib-pos
    # only): it is interpolated to the epoch times (io.rtklib.PosSolution.velocity_at_epochs)
    velocity_delay: quantity(u.TIME, nonnegative=True) = 0.0  # type: ignore[valid-type]
    withhold: Windows = Field(default_factory=list)
    #: a hole between used fixes longer than this (outside the withheld windows) is reported:
    #: a warning and gnss_gaps_s in metrics.json ("warn"), or an error naming the line ("fail")
    max_gap: Gap = 5.0
    gap_action: Literal["warn", "fail"] = "warn"
    # optional corruption of the recorded fixes (NED metres per axis), e.g. to
    # test a method under mixture noise or outliers on real data
    corrupt_position: dict | None = None
    corrupt_seed: int = 0


class ReferenceFile(Strict):
    """The reference trajectory, and which point of the vehicle it gives:
    the GNSS antenna (an RTK solution) or the IMU (an INS/GNSS reference
    such as KF-GINS' truth.nav)."""

    format: reader_format("reference")  # type: ignore[valid-type]
    file: str
    qualities: list[int] = Field(default_factory=lambda: [1])
    point: Literal["antenna", "imu"] = "antenna"
    #: rtklib-pos: the velocity columns are valid this long before the epoch (as ``[gnss]``'s)
    velocity_delay: quantity(u.TIME, nonnegative=True) = 0.0  # type: ignore[valid-type]


class Installation(Strict):
    """Where the sensors sit on the vehicle (body frame forward, right, down).

    ``imu_rotation``: the mounting, roll, pitch, yaw of the IMU axes relative
    to the body axes; ``imu_misalignment``: a small rotation (roll, pitch,
    yaw) applied after it: ``C_b_imu = C(misalignment) C(rotation)`` with
    ``C(r, p, y) = Rz(y) Ry(p) Rx(r)``. ``imu_position`` and
    ``antenna_position`` in the body frame; ``imu_time_offset`` added to
    every IMU time stamp; ``imu_clock_drift`` (a fraction, written in ppm) the rate at
    which that offset grows: a stamp ``t`` becomes ``t + imu_time_offset + imu_clock_drift
    (t - t_0)``, ``t_0`` the first increment's start, and each increment's length is
    scaled by ``1 + imu_clock_drift`` (a free-running IMU clock, or time tags spread over
    the wrong span, against GNSS time). Default 0.
    """

    imu_rotation: AngleVec = (0.0, 0.0, 0.0)
    imu_misalignment: AngleVec = (0.0, 0.0, 0.0)
    imu_position: LengthVec = (0.0, 0.0, 0.0)
    antenna_position: LengthVec = (0.0, 0.0, 0.0)
    imu_time_offset: Offset = 0.0
    imu_clock_drift: Fraction = 0.0

    @field_validator("imu_clock_drift")
    @classmethod
    def _drift_small(cls, v):
        # 1 % is 36 s an hour: beyond any crystal; more likely a unit left out ("300" for 300 ppm)
        if not abs(v) < 1e-2:
            raise ValueError(f"must be below 1 % (10000 ppm) in size, got {v:g}: give the unit, e.g. \"250 ppm\"")
        return v


class Alignment(Strict):
    """How the INS is initialised.

    ``gnss-velocity``: at the first GNSS epoch at or above ``min_speed``,
    heading and pitch from the GNSS velocity, roll zero (MEMS units that
    cannot sense Earth rate). ``static``: levelling from the accelerometers
    and heading from the gyros over the first ``static_duration`` seconds
    (navigation and tactical grade). With ``gyro_bias_from_static`` the mean
    gyro rate over the first ``static_duration`` seconds (the vehicle at rest)
    starts the gyro-bias estimate. ``level-then-gnss`` (MEMS units on a
    vehicle that starts parked): roll and pitch from the accelerometers and
    the gyro bias from the gyros over the first ``static_duration`` seconds,
    which must be at rest (1 s blocks: specific-force magnitude scatter below
    0.1 m/s^2 and mean rate magnitude below 0.03 rad/s in at least 80 % of
    them; the last second's mean specific force within 1 deg of the window's;
    mean specific force gravity within 5 %; no fix at ``min_speed``); the
    attitude carried
    by the bias-compensated gyros to the first fix after the window at or
    above ``min_speed``, where the heading turns the vehicle's forward axis
    (``[aiding] vehicle_mounting``, else the body x axis) onto the GNSS track
    (:func:`mixnav.alignment.align_level_then_gnss`).
    """

    method: Literal["gnss-velocity", "static", "level-then-gnss"] = "gnss-velocity"
    min_speed: MinSpeed = 5.0
    static_duration: Gap = 30.0
    gyro_bias_from_static: bool = False
    attitude_sigma: AngSigma
    velocity_sigma: VelSigma
    position_sigma: PosSigma


class RawGnss(Strict):
    """Raw GNSS measurements and the broadcast ephemeris for single-point positioning.

    ``file``: the measurement log; ``navigation``: the RINEX navigation file, or with
    ``format = "rinex-obs"`` a list of them (e.g. one per system and hour: every system of
    ``systems`` other than GPS needs its broadcast records; both relative to the data folder). ``elevation_mask``, ``sigma_a``,
    ``sigma_b`` (pseudorange sigma ``sqrt(a^2 + b^2 / sin^2(el))``),
    ``troposphere`` (Saastamoinen), ``ionosphere`` (Klobuchar, when the
    navigation header has its coefficients), ``weights`` (``"elevation"``: the sigma above;
    ``"rtklib"`` / ``"rtklib-2.4.3"``: RTKLIB demo5's / 2.4.3's pntpos variance model, the SPP only), ``validate`` and ``fde``
    (RTKLIB-style validation of each epoch and RAIM FDE, default off) set the solver
    (:class:`mixnav.gnss.spp.SppOptions`); ``max_sv_time_uncertainty``
    rejects measurements the receiver reports as worse than it (Android logs).
    ``format = "rinex-obs"``: a RINEX 2.x/3.x observation file (:mod:`mixnav.io.rinex_obs`):
    ``systems`` (RINEX letters ``G``, ``R``, ``E``, ``C``, ``J``; default ``["G"]``, GPS L1
    C/A as before) and ``signals`` (a table of system letter -> pseudorange code, or list of
    codes in order of preference, e.g. ``{ E = ["C1C", "C1X"], C = "C2I" }``; a system not
    named takes :data:`mixnav.gnss.signals.DEFAULT_SIGNALS`) choose what is read.
    ``format = "ubx"``: a binary u-blox log's RXM-RAWX messages (:mod:`mixnav.io.ubx`), with
    the same ``systems`` and ``signals`` (RINEX 3 codes). The phone-log format reads GPS
    alone, so it takes neither key. ``format = "smartloc"`` (gnss-raw only): a smartLoc
    ``*_Input.txt`` log (:mod:`mixnav.io.smartloc`), pseudoranges already corrected (satellite
    clock and atmosphere removed) with the satellites' positions and variances: no
    ``navigation``; the file's variances weigh the pseudoranges and the file has no
    atmosphere left, so ``sigma_a``, ``sigma_b``, ``troposphere``, ``ionosphere``,
    ``max_sv_time_uncertainty`` and ``signals`` are refused; ``systems``: the letters of the
    file's systems to use (``G``, ``R``...).
    """

    format: reader_format("raw-gnss")  # type: ignore[valid-type]
    file: str
    navigation: str | list[str] | None = None
    elevation_mask: ElevationMask = 10.0 * u.DEG  # type: ignore[valid-type]
    sigma_a: quantity(u.LENGTH, nonnegative=True) = 3.0  # type: ignore[valid-type]
    sigma_b: quantity(u.LENGTH, nonnegative=True) = 3.0  # type: ignore[valid-type]
    troposphere: bool = True
    ionosphere: bool = True
    #: the SPP's pseudorange weights: "elevation" (sigma_a, sigma_b) or "rtklib" / "rtklib-2.4.3"
    #: (RTKLIB demo5's / 2.4.3 b34's pntpos variance model: code, broadcast accuracy, ionosphere,
    #: troposphere; gnss/spp.py)
    weights: Literal["elevation", "rtklib", "rtklib-2.4.3"] = "elevation"
    #: validate each SPP epoch as RTKLIB pntpos does (chi-square of the weighted residuals at
    #: 99.9 %, GDOP <= 30; a failing epoch is no solution), and with ``fde`` try leaving out
    #: each satellite (RAIM FDE); off by default (gnss/spp.py, "Validation"). The key is
    #: ``validate`` (the field's own name would shadow pydantic's ``validate``)
    validate_epochs: bool = Field(default=False, alias="validate")
    fde: bool = False
    max_sv_time_uncertainty: quantity(u.TIME, positive=True) = 500e-9  # type: ignore[valid-type]
    systems: list[str] = Field(default_factory=lambda: list(DEFAULT_SYSTEMS))
    signals: dict[str, str | list[str]] = Field(default_factory=dict)

    @field_validator("systems")
    @classmethod
    def _systems(cls, v):
        try:
            return list(check_systems(v))
        except ArgumentError as exc:
            raise ValueError(exc.message) from None

    @field_validator("signals")
    @classmethod
    def _signals(cls, v):
        try:
            return {k: list(c) for k, c in check_signals(v).items()}
        except ArgumentError as exc:   # argument "signals.<letter>"
            raise ValueError(f"{exc.argument.split('.', 1)[-1]}: {exc.message}") from None

    @field_validator("navigation")
    @classmethod
    def _some_nav(cls, v):
        if isinstance(v, list) and not v:
            raise ValueError("give at least one file")
        return v

    def files(self, key: str) -> list[str]:
        """``file`` or ``navigation`` as a list (empty: no navigation, ``smartloc``)."""
        v = getattr(self, key)
        return [] if v is None else [v] if isinstance(v, str) else list(v)

    @model_validator(mode="after")
    def _fde_needs_validation(self):
        if self.fde and not self.validate_epochs:
            raise ValueError("fde: needs validate = true (a satellite is left out when an epoch fails validation)")
        return self

    @model_validator(mode="after")
    def _smartloc_keys(self):
        if self.format != "smartloc":
            if self.navigation is None:
                raise ValueError("navigation: required: the broadcast navigation file(s) of the raw measurements")
            return self
        if self.navigation is not None:
            raise ValueError("navigation: a smartLoc log gives the satellites' positions and corrected "
                             "pseudoranges: it takes no navigation file")
        for key, why in (("sigma_a", "the file's variances weigh the pseudoranges"),
                         ("sigma_b", "the file's variances weigh the pseudoranges"),
                         ("troposphere", "the file's pseudoranges have their atmosphere removed"),
                         ("ionosphere", "the file's pseudoranges have their atmosphere removed"),
                         ("weights", "the file's variances weigh the pseudoranges"),
                         ("validate_epochs", "the corrected-pseudorange SPP does not validate its epochs"),
                         ("fde", "the corrected-pseudorange SPP does not validate its epochs"),
                         ("max_sv_time_uncertainty", "a phone log's key"),
                         ("signals", "the file has one pseudorange per satellite")):
            if key in self.model_fields_set:
                key = type(self).model_fields[key].alias or key
                raise ValueError(f"{key}: not used with format = \"smartloc\" ({why})")
        return self

    @model_validator(mode="after")
    def _rinex_keys(self):
        if self.format not in ("rinex-obs", "ubx") and isinstance(self.navigation, list) and len(self.navigation) > 1:
            raise ValueError(f"navigation: format \"{self.format}\" reads GPS from one navigation file "
                             f"(several files: format = \"rinex-obs\" or \"ubx\")")
        if self.format not in ("rinex-obs", "ubx"):
            for key in ("systems", "signals"):
                if key in self.model_fields_set and not (key == "systems" and self.format == "smartloc"):
                    raise ValueError(f"{key}: only format = \"rinex-obs\" or \"ubx\" reads other systems or signals "
                                     f"(\"{self.format}\" reads GPS L1 C/A)")
        if self.format == "ubx":
            for s, codes in self.signals.items():
                if not any(len(c) == 3 for c in codes):
                    raise ValueError(f"signals: {s}: {', '.join(codes)}: a u-blox log's signals are named by "
                                     "RINEX 3 codes (e.g. C1C)")
        return self


class InsRawGnss(RawGnss):
    """``[raw_gnss]`` of an ``ins-gnss`` dataset (instead of ``[gnss]`` fixes): a RINEX
    observation file and its navigation file for the tightly coupled INS
    (:mod:`mixnav.experiment.rinex_ins`).

    The keys of the raw-GNSS datasets (``format = "rinex-obs"`` or ``"ubx"``, a u-blox log's
    RXM-RAWX messages, :mod:`mixnav.io.ubx`; ``file``, ``navigation``:
    here each one file or a list of files, e.g. hourly observation files and the daily
    navigation files they span, observation files in time order; the SPP's ``elevation_mask``, ``sigma_a``, ``sigma_b``, ``troposphere``,
    ``ionosphere``), plus: ``imu_time``: how the IMU file's time stamps (after
    ``installation.imu_time_offset``) are given, ``"gps-week-seconds"`` (GPS seconds of the
    week of the first RINEX epoch, as KF-GINS files; continuing past 604800 s across a week
    roll-over) or ``"gps-seconds"`` (GPS seconds since 1980-01-06 00:00); ``pseudorange_sigma``,
    ``range_rate_sigma``: what the tight filter is told (one sigma for every satellite), or
    with ``pseudorange_weights = "elevation"`` the SPP's ``sqrt(sigma_a^2 + sigma_b^2 / sin^2 el)``
    per pseudorange (the range rates keep ``range_rate_sigma``); ``carrier_sigma``: the carrier
    1-sigma a ``tdcp-ekf`` is told (its TDCP rows ``2 carrier_sigma^2``; the carrier is the
    file's, TDCP rows only between epochs without a cycle slip: :mod:`mixnav.gnss.cycle_slips`);
    ``clock_q_bias`` [m^2/s], ``clock_q_drift`` [m^2/s^3]: the receiver clock's noise
    densities in the filter; ``clock_jump``: SPP clock jumps beyond this come off the
    pseudoranges (millisecond steps of a steered clock; :func:`mixnav.gnss.spp.clock_jumps`);
    ``withhold``, ``max_gap``, ``gap_action``: as ``[gnss]``'s, on the observation epochs
    (a withheld epoch gives neither the SPP fix nor the tight rows)."""

    format: Literal["rinex-obs", "ubx"] = "rinex-obs"
    file: str | list[str]
    navigation: str | list[str]
    imu_time: Literal["gps-week-seconds", "gps-seconds"] = "gps-week-seconds"
    pseudorange_sigma: quantity(u.LENGTH, positive=True) = 3.0  # type: ignore[valid-type]
    pseudorange_weights: Literal["constant", "elevation"] = "constant"
    range_rate_sigma: quantity(u.VELOCITY, positive=True) = 0.1  # type: ignore[valid-type]
    #: tdcp-ekf's carrier sigma [m]; 3 mm as the scenarios' [gnss.satellites] carrier_sigma
    carrier_sigma: quantity(u.LENGTH, positive=True) = 0.003  # type: ignore[valid-type]
    #: tdcp-ekf: a second signal per system (letter -> pseudorange code(s), as ``signals``) whose
    #: carrier the geometry-free cycle-slip check sets against the first's (gnss/cycle_slips.py);
    #: none named: no geometry-free check
    second_signals: dict[str, str | list[str]] = Field(default_factory=dict)
    clock_q_bias: float = Field(default=0.1, ge=0, le=1e8)
    clock_q_drift: float = Field(default=0.01, ge=0, le=1e6)
    clock_jump: quantity(u.LENGTH, positive=True) = 1000.0  # type: ignore[valid-type]
    withhold: Windows = Field(default_factory=list)
    max_gap: Gap = 5.0
    gap_action: Literal["warn", "fail"] = "warn"

    @field_validator("file", "navigation")
    @classmethod
    def _some(cls, v):
        if isinstance(v, list) and not v:
            raise ValueError("give at least one file")
        return v

    @field_validator("second_signals")
    @classmethod
    def _second_signals(cls, v):
        try:
            return {k: list(c) for k, c in check_signals(v, "second_signals").items()}
        except ArgumentError as exc:   # argument "second_signals.<letter>"
            raise ValueError(f"{exc.argument.split('.', 1)[-1]}: {exc.message}") from None

    @model_validator(mode="after")
    def _second_on_another_band(self):
        """A second signal of a system read, on another band than its first signal's (on the
        same band the geometry-free combination has no ionosphere and no second carrier)."""
        from ..gnss.signals import DEFAULT_SIGNALS
        for s, codes in self.second_signals.items():
            if s not in self.systems:
                raise ValueError(f"second_signals: {s}: not one of systems = {list(self.systems)}")
            first = self.signals.get(s) or DEFAULT_SIGNALS[3][s] + DEFAULT_SIGNALS[2][s]
            bands = {c[1] for c in first}
            same = [c for c in codes if c[1] in bands]
            if same:
                raise ValueError(f"second_signals: {s}: {', '.join(same)} is on the band of the first signal "
                                 f"({', '.join(first)}): name a signal of another frequency (e.g. C2L, C7I)")
        return self


class ReferencePoint(Strict):
    """A surveyed static point: WGS-84 geodetic (``latitude``, ``longitude``, ellipsoidal
    ``height``) or Earth-centred, Earth-fixed (``x``, ``y``, ``z`` [m], as RINEX headers and
    survey reports give it), one of the two. After validation ``latitude``,
    ``longitude``, ``height`` are always set (ECEF converted)."""

    latitude: quantity(u.ANGLE) | None = None  # type: ignore[valid-type]
    longitude: quantity(u.ANGLE) | None = None  # type: ignore[valid-type]
    height: quantity(u.LENGTH) | None = None  # type: ignore[valid-type]
    x: quantity(u.LENGTH) | None = None  # type: ignore[valid-type]
    y: quantity(u.LENGTH) | None = None  # type: ignore[valid-type]
    z: quantity(u.LENGTH) | None = None  # type: ignore[valid-type]

    @model_validator(mode="after")
    def _one_form(self):
        geo = [self.latitude, self.longitude, self.height]
        ecef = [self.x, self.y, self.z]
        if any(v is not None for v in ecef):
            if any(v is not None for v in geo):
                raise ValueError("give the point either geodetic (latitude, longitude, height) or ECEF "
                                 "(x, y, z), not both")
            if any(v is None for v in ecef):
                raise ValueError("an ECEF point needs all of x, y and z")
            import numpy as np
            from ..geodesy.frames import ecef_to_lla
            r = float(np.linalg.norm(ecef))
            if not 6.2e6 < r < 6.5e6:
                raise ValueError(f"the ECEF point is {r / 1e3:.1f} km from the Earth's centre, not near its "
                                 "surface (6356-6378 km): a unit or a sign is wrong")
            lat, lon, h = ecef_to_lla(np.array(ecef, dtype=float))
            for k, v in (("latitude", lat), ("longitude", lon), ("height", h)):   # frozen model: set once here
                object.__setattr__(self, k, float(v))
        elif any(v is None for v in geo):
            raise ValueError("give latitude, longitude and height (or x, y, z in ECEF)")
        check_position(self.latitude, self.longitude, self.height)   # docs/validation.md
        return self


#: sections each kind needs, and those it must not have
#: (gnss-raw and odometry-gnss files have schemas of their own: config/raw_gnss_schema.py, vehicle_schema.py)
#: (an ins-gnss dataset has its GNSS as fixes, [gnss], or raw, [raw_gnss]: exactly one, loader._check_kind)
KIND_SECTIONS = {"ins-gnss": (("imu", "alignment", "methods"), ("reference_point",))}


class Dataset(Strict):
    dataset: DatasetInfo
    imu: ImuFile | None = None
    gnss: GnssFile | None = None
    reference: ReferenceFile | None = None
    installation: Installation = Installation()
    alignment: Alignment | None = None
    methods: list[MethodConfig] | None = Field(default=None, min_length=1)
    aiding: AidingConfig | None = None
    raw_gnss: InsRawGnss | None = None
    reference_point: ReferencePoint | None = None
    evaluation: Evaluation | None = None
