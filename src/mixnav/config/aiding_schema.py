"""The ``[aiding]`` table of scenario and dataset files: land-vehicle aiding (non-holonomic
constraints, odometer, zero-velocity and zero-angular-rate updates) shared by the methods
that list it.
"""

from __future__ import annotations

from typing import Literal

from .. import units as u
from .fields import (AngleVec, Duration, Fraction, Frequency, LengthVec, NonNegSpeed, PosAccel, PosAngle, PosLength,
                     PosRate, PosSpeed, Strict, Time, TimeWalk, quantity, reader_format)

#: an angle per acceleration (rad per m/s^2): ``"0.3 deg/(m/s^2)"``
PitchPerAccel = quantity(u.Dimension(1.0, -1.0, 2.0))


class NhcConfig(Strict):
    """Non-holonomic constraints (``mixnav.measurements.vehicle.NonHolonomic``):
    epochs at ``rate``; ``sigma`` the lateral and vertical velocity the vehicle
    really has (slip, bumps); no rows below ``min_speed``. The violations are
    correlated over seconds, and the rows are treated as independent: at 10 Hz
    the filter over-trusts them tenfold (vehicle-demo: position NEES 16-19 in
    the outages at 10 Hz, 3-4 at 1 Hz, and smaller errors), hence 1 Hz.
    ``pitch_per_accel`` (e.g. ``"0.3 deg/(m/s^2)"``): the body's pitch on its
    suspension per m/s^2 of forward acceleration (squat, dive when braking); the
    vertical row then expects that pitch times the forward speed instead of 0
    (``NonHolonomic``'s ``pitch_per_accel``). Default 0: the plain constraint."""

    rate: Frequency = 1.0
    sigma: tuple[PosSpeed, PosSpeed] = (0.1, 0.1)
    min_speed: NonNegSpeed = 0.0
    pitch_per_accel: PitchPerAccel = 0.0


class OdometerAidingConfig(Strict):
    """Odometer aiding (``mixnav.measurements.vehicle.Odometer``). In a dataset,
    ``format``/``file`` name the speeds (``csv``: docs/data_formats.md; ``comma2k19``: a
    comma2k19 segment's rear wheels, ``file`` the segment folder); in a
    scenario the simulated odometer is used. ``sigma`` [m/s] when the file gives
    none; ``scale`` a known scale error; ``scale_sigma`` the initial 1-sigma of
    the estimated one (method ``estimate = ["odometer_scale"]``); ``lever_arm``
    the wheel (axle centre) in the body frame from the IMU, default the
    vehicle point. ``max_gap``: a hole between the file's samples longer than this
    warns and is counted (``odometer_gaps_accepted`` in metrics.json), or with
    ``gap_action = "fail"`` is an error naming the file and line (default: no limit).
    ``time_offset`` [s] is added to the file's stamps (a dataset only): a speed stamped when
    it arrived lags the IMU (a comma2k19 segment's CAN speeds by about 0.08 s, so -0.08 s;
    benchmarks/results/comma2k19_odometer.md)."""

    format: reader_format("odometer") = "csv"  # type: ignore[valid-type]
    file: str | None = None
    max_gap: Duration | None = None  # type: ignore[valid-type]
    gap_action: Literal["warn", "fail"] = "warn"
    sigma: PosSpeed = 0.05
    scale: Fraction = 0.0
    scale_sigma: Fraction = 0.01
    lever_arm: LengthVec | None = None
    rate: Frequency | None = None
    time_offset: quantity(u.TIME) = 0.0  # type: ignore[valid-type]


class ZuptConfig(Strict):
    """Zero-velocity updates at the epochs the stillness detector finds
    (``mixnav.measurements.stillness.detect_still``: window, thresholds, the level
    test ``accel_drift`` that ends a stop where the car pulls away), at
    ``rate``; ``sigma`` the velocity at rest; no update while the navigation
    solution moves faster than ``max_speed`` (an IMU alone cannot tell rest from
    a smooth constant-velocity drive)."""

    rate: Frequency = 5.0
    sigma: PosSpeed = 0.02
    window: Duration = 1.0
    accel_std: PosAccel = 0.1
    gyro_rate: PosRate = 0.03
    accel_drift: PosAccel = 0.1
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
    coupling (:mod:`mixnav.measurements.loose`). ``time_offset_walk``: the offset
    state's random-walk density [s/sqrt(s), written e.g. ``"1 ms/sqrt(s)"``]; 0, the
    default, holds the offset constant (a fixed latency). An IMU clock whose offset
    wanders against GNSS time (a free-running logger) needs a walk, or the state settles
    on a mean and is over-confident (docs/aiding.md, "Installation states").
    """

    vehicle_mounting: AngleVec | None = None
    vehicle_point: LengthVec = (0.0, 0.0, 0.0)
    mounting_sigma: PosAngle = 0.05
    gnss_lever_sigma: PosLength = 0.5
    time_offset_sigma: Duration = 0.1
    time_offset_walk: TimeWalk = 0.0
    nhc: NhcConfig | None = None
    odometer: OdometerAidingConfig | None = None
    zupt: ZuptConfig | None = None
    zaru: ZaruConfig | None = None


