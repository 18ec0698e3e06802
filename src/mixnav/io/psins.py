"""Reader of the PSINS ``.imu`` text format (Gongmin Yan's PSINS toolbox).

Layout: ``%`` comment lines, then three header lines

1. pitch, roll, yaw [deg] and velocity E, N, U [m/s] at the start
   (PSINS: ENU navigation frame, yaw positive counter-clockwise from north);
2. latitude, longitude [deg], height [m], start time [s], sampling
   interval [ms], g [m/s^2];
3. scale factors of the integer increments: gyros in arcsec, accelerometers
   in ug*s (micro-g with the header's g);

then one line per sample: integer angle increments x, y, z and velocity
increments x, y, z in the sensor frame X right, Y forward, Z up.

mixnav's body frame is forward, right, down, so ``x_b = y_s, y_b = x_s,
z_b = -z_s``, and its yaw is NED (clockwise from north): ``yaw = -yaw_psins``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data import ImuData
from ..errors import DataError
from ..units import ARCSEC
from .imu_checks import check_spikes
from .registry import ReadOptions, register_reader
from .tables import read_numeric

#: Sensor (right, forward, up) to body (forward, right, down).
C_BODY_SENSOR = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class PsinsHeader:
    """The three header lines, converted to mixnav conventions (SI, NED, FRD)."""

    rpy: np.ndarray          # roll, pitch, yaw [rad], yaw NED
    v_n: np.ndarray          # north, east, down [m/s]
    lla: np.ndarray          # lat, lon [rad], h [m]
    t0: float                # [s]
    dt: float                # [s]
    g: float                 # [m/s^2]
    gyro_scale: np.ndarray   # [rad per count]
    accel_scale: np.ndarray  # [m/s per count]


def _numbers(line: str, n: int, path: Path, lineno: int) -> np.ndarray:
    try:
        vals = np.array([float(x) for x in line.split()])
    except ValueError:
        raise DataError(f"expected {n} numbers, got {line.strip()!r}", file=str(path), line=lineno) from None
    if vals.size != n:
        raise DataError(f"expected {n} numbers, got {vals.size}", file=str(path), line=lineno)
    if not np.all(np.isfinite(vals)):
        raise DataError("non-finite number in header", file=str(path), line=lineno)
    return vals


def read_psins_imu(path) -> tuple[ImuData, PsinsHeader]:
    """Read a PSINS ``.imu`` file.

    Returns
    -------
    imu : ImuData
        Increments in the body frame (FRD), SI units; the first sample ends
        at ``t0 + dt``.
    header : PsinsHeader
    """
    path = Path(path)
    if not path.is_file():
        raise DataError("PSINS IMU file does not exist", file=str(path))
    with open(path, encoding="utf-8", errors="replace") as fh:
        lines = fh.readlines()
    i = 0
    while i < len(lines) and (lines[i].lstrip().startswith("%") or not lines[i].strip()):
        i += 1
    if len(lines) - i < 4:
        raise DataError("file ends before the three header lines and data", file=str(path), line=i + 1)
    h1 = _numbers(lines[i], 6, path, i + 1)
    h2 = _numbers(lines[i + 1], 6, path, i + 2)
    h3 = _numbers(lines[i + 2], 6, path, i + 3)
    first = i + 3
    tab = read_numeric(path, 6, comment="%", skip_lines=first, what="PSINS IMU")
    data = tab.values
    dt = h2[4] * 1e-3
    if not dt > 0:
        raise DataError("sampling interval must be positive", file=str(path), line=i + 2)
    g = h2[5]
    gyro_scale = h3[0:3] * ARCSEC
    accel_scale = h3[3:6] * 1e-6 * g
    dth = (data[:, 0:3] * gyro_scale) @ C_BODY_SENSOR.T
    dv = (data[:, 3:6] * accel_scale) @ C_BODY_SENSOR.T
    n = len(data)
    time = h2[3] + dt * np.arange(1, n + 1)
    header = PsinsHeader(
        rpy=np.deg2rad([h1[1], h1[0], -h1[2]]),
        v_n=np.array([h1[4], h1[3], -h1[5]]),
        lla=np.array([np.deg2rad(h2[0]), np.deg2rad(h2[1]), h2[2]]),
        t0=h2[3], dt=dt, g=g, gyro_scale=gyro_scale, accel_scale=accel_scale)
    imu = ImuData(time=time, dt=np.full(n, dt), dtheta=dth, dvel=dv, source=str(path))
    return check_spikes(imu, tab.lines), header


@register_reader("imu", "psins")
def _read(path: Path, options: ReadOptions) -> ImuData:
    """The registered reader (``options``: ``spike_action``; the header is dropped)."""
    imu = read_psins_imu(path)[0]
    action = options.imu_checks()["spike_action"]
    return imu if action == "fail" else check_spikes(imu, None, action)
