"""The strict schema of real-data configs (``mixnav process``).

Same rules as scenario files: every key known, every unit-bearing value
written with its unit, errors naming the file and the key.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .. import units as u
from .schema import (AngleVec, AngSigma, LengthVec, MethodConfig, PosSigma, Strict, VelSigma, Windows,
                     _quantity)

Offset = _quantity(u.TIME)
Gap = _quantity(u.TIME, positive=True)
MinSpeed = _quantity(u.VELOCITY, positive=True)


class DatasetInfo(Strict):
    name: str
    description: str = ""
    data_dir: str = "."


class ImuFile(Strict):
    """IMU file: format, file names (relative to the data folder), checks, filter noise model."""

    format: Literal["drive-0708", "kf-gins", "psins", "csv"]
    file: str
    tag: str | None = None
    max_gap: Gap = 0.05
    gap_action: Literal["warn", "fail"] = "warn"
    grade: str | None = None
    errors: dict[str, str] = Field(default_factory=dict)


class GnssFile(Strict):
    format: Literal["rtklib-pos", "kf-gins", "csv"]
    file: str
    qualities: list[int] = Field(default_factory=lambda: [1, 2, 5])
    min_sigma: _quantity(u.LENGTH, nonnegative=True) = 0.0  # type: ignore[valid-type]
    use_velocity: bool = True
    withhold: Windows = Field(default_factory=list)
    # optional corruption of the recorded fixes (NED metres per axis), e.g. to
    # test a method under mixture noise or outliers on real data
    corrupt_position: dict | None = None
    corrupt_seed: int = 0


class ReferenceFile(Strict):
    """The reference trajectory, and which point of the vehicle it gives:
    the GNSS antenna (an RTK solution) or the IMU (an INS/GNSS reference
    such as KF-GINS' truth.nav)."""

    format: Literal["rtklib-pos", "kf-gins-nav", "csv"]
    file: str
    qualities: list[int] = Field(default_factory=lambda: [1])
    point: Literal["antenna", "imu"] = "antenna"


class Installation(Strict):
    """Where the sensors sit on the vehicle (body frame forward, right, down).

    ``imu_rotation``: the mounting, roll, pitch, yaw of the IMU axes relative
    to the body axes; ``imu_misalignment``: a small rotation (roll, pitch,
    yaw) applied after it: ``C_b_imu = C(misalignment) C(rotation)`` with
    ``C(r, p, y) = Rz(y) Ry(p) Rx(r)``. ``imu_position`` and
    ``antenna_position`` in the body frame; ``imu_time_offset`` added to
    every IMU time stamp.
    """

    imu_rotation: AngleVec = (0.0, 0.0, 0.0)
    imu_misalignment: AngleVec = (0.0, 0.0, 0.0)
    imu_position: LengthVec = (0.0, 0.0, 0.0)
    antenna_position: LengthVec = (0.0, 0.0, 0.0)
    imu_time_offset: Offset = 0.0


class Alignment(Strict):
    """How the INS is initialised.

    ``gnss-velocity``: at the first GNSS epoch at or above ``min_speed``,
    heading and pitch from the GNSS velocity, roll zero (MEMS units that
    cannot sense Earth rate). ``static``: levelling from the accelerometers
    and heading from the gyros over the first ``static_duration`` seconds
    (navigation and tactical grade). With ``gyro_bias_from_static`` the mean
    gyro rate over the first ``static_duration`` seconds (the vehicle at rest)
    starts the gyro-bias estimate.
    """

    method: Literal["gnss-velocity", "static"] = "gnss-velocity"
    min_speed: MinSpeed = 5.0
    static_duration: Gap = 30.0
    gyro_bias_from_static: bool = False
    attitude_sigma: AngSigma
    velocity_sigma: VelSigma
    position_sigma: PosSigma


class Dataset(Strict):
    dataset: DatasetInfo
    imu: ImuFile
    gnss: GnssFile
    reference: ReferenceFile | None = None
    installation: Installation = Installation()
    alignment: Alignment
    methods: list[MethodConfig] = Field(min_length=1)
