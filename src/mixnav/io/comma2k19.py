"""Reader of a comma2k19 segment (comma.ai, MIT licence): IMU, GNSS, CAN speeds, pose.

A segment folder holds numpy arrays saved without the ``.npy`` extension::

    processed_log/IMU/accelerometer/{t,value}      ~104 Hz, (N, 3) m/s^2, forward-right-down
    processed_log/IMU/gyro/{t,value}               (N, 3) rad/s, Android's bias correction applied
    processed_log/IMU/gyro_uncalibrated/{t,value}  the same without it
    processed_log/CAN/speed/{t,value}              ~83 Hz, (M,) or (M, 1) vehicle speed [m/s]
    processed_log/CAN/wheel_speed/{t,value}        (M, 4) front left, front right, rear left, rear right [m/s]
    processed_log/GNSS/live_gnss_ublox/{t,value}   ~10 Hz u-blox fixes: lat [deg], lon [deg], speed [m/s],
                                                   UTC time [ms since 1970], altitude [m], bearing [deg]
    global_pose/frame_times                        (F,) boot time of each camera frame (20 Hz)
    global_pose/frame_gps_times                    (F, 2) GPS week, time of week [s]
    global_pose/frame_positions, frame_velocities  (F, 3) ECEF [m], [m/s] of the camera
    global_pose/frame_orientations                 (F, 4) Hamilton quaternion, scalar first: C_ec,
                                                   camera (forward, right, down) to ECEF

**One time axis: the device boot time** ``t`` [s], which stamps every log.
Every reader here returns times on it. GPS time is one constant offset away:
:func:`read_comma_clock` reads it from ``global_pose`` (``frame_gps_times -
frame_times``, constant to the microsecond in the example segment), and
:class:`CommaClock` converts boot time to GPS week/time of week and back, and
UTC to boot time (GPS - UTC = 18 leap seconds from 2017 on).

What each log's stamp means (measured on the example segment; see
benchmarks/results/comma2k19_odometer.md):

- IMU: the accelerometer and gyro ``t`` are the time base. If the two
  differ, the gyro rates are interpolated linearly onto the accelerometer's
  stamps (accelerometer samples outside the gyro's span are dropped); in the
  example they are identical.
- GNSS: the log's ``t`` is when the fix *arrived*, 0.18-0.24 s after the
  fix's own UTC time. By default (``fix_time="utc"``) a fix is placed at its
  UTC time mapped to boot time through the clock; on that time the GNSS
  speed's derivative matches the IMU's forward acceleration with no lag
  (+-0.02 s between the two halves of the minute), on the log time with a
  0.19 s lag. The first fixes of a segment may therefore fall up to ~0.2 s
  before the first IMU sample (the segment was cut on log time).
- CAN: speeds are stamped at arrival; the CAN speed lags the IMU by about
  0.08 s (``time_offset`` corrects it, default 0: no hidden estimate).
- global_pose: comma's own INS/GNSS/vision optimiser, the best reference
  available but *not an independent truth* (it uses these same GNSS and IMU
  data). It is the pose of the camera, not of the IMU or the rear axle.

**Registered readers** (:mod:`mixnav.io.registry`, format ``comma2k19``; a dataset
table's ``file`` is the segment folder, e.g. ``file = "."`` with ``data_dir`` the
segment): ``imu`` (:func:`read_comma_imu`, the calibrated gyro; ``max_gap``,
``gap_action``), ``gnss-fixes`` (:func:`read_comma_gnss` at the fixes' UTC time,
positions only, the default sigmas; ``max_gap``, ``gap_action``), ``odometer``
(:func:`read_comma_odometer`, the rear wheels; ``sigma``, ``max_gap``,
``gap_action``) and ``reference`` (:func:`read_comma_pose`, comma's pose, NOT an
independent truth); ``reference`` in format ``comma2k19-ublox``: the u-blox fixes
as a position-only reference (the truth of a window whose fixes the filter was
denied, :func:`read_comma_ublox_reference`).

All arrays are validated on the way in (:class:`~mixnav.errors.DataError`
naming the file; for time checks the "line" is the 1-based row of the
array): shapes, finiteness, strictly increasing times, gaps beyond
``max_gap`` (warned or refused, as ``gap_action`` says), implausible sizes.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..attitude import dcm_to_quat, quat_to_dcm
from ..data import MAX_VEHICLE_SPEED, GnssFixes, ImuData, OdometerData, Trajectory
from ..errors import ArgumentError, DataError
from ..geodesy.frames import dcm_ecef_to_ned, ecef_to_lla
from ..units import DEG
from .imu_checks import check_plausible, rates_to_increments
from .registry import ReadOptions, register_reader
from .tables import check_gap_action, check_times

#: GPS - UTC [s] from 2017-01-01 until the next leap second (none announced as of 2024).
GPS_UTC_LEAP_SECONDS = 18
#: The GPS epoch, 1980-01-06 00:00:00 UTC, in Unix seconds.
GPS_EPOCH_UNIX = 315964800.0
WEEK_SECONDS = 604800.0

_IMU = "processed_log/IMU"
_CAN = "processed_log/CAN"
_GNSS = "processed_log/GNSS/live_gnss_ublox"
_POSE = "global_pose"


# ---------------------------------------------------------------------------
# Loading and argument checks
# ---------------------------------------------------------------------------
def _segment(segment) -> Path:
    p = Path(segment)
    if not p.is_dir():
        raise DataError("comma2k19 segment folder does not exist", file=str(p))
    return p


def _load(path: Path, shape: tuple, what: str) -> np.ndarray:
    """A numpy array of ``shape`` (None: any length) with finite values."""
    if not path.is_file():
        raise DataError(f"{what} file does not exist (is this a comma2k19 segment folder?)", file=str(path))
    try:
        a = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise DataError(f"not a numpy array file ({exc})", file=str(path)) from None
    if not isinstance(a, np.ndarray) or a.dtype.kind not in "fiu":
        raise DataError(f"{what}: expected a numeric array", file=str(path))
    a = a.astype(float)
    if shape and len(shape) == 1 and a.ndim == 2 and a.shape[1] == 1:
        a = a[:, 0]
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise DataError(f"{what}: expected shape {want}, got {a.shape}", file=str(path))
    if not len(a):
        raise DataError(f"{what} is empty", file=str(path))
    bad = ~np.isfinite(a)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        raise DataError(f"{what} has a non-finite value (NaN or inf) in row {row + 1}", file=str(path),
                        line=row + 1)
    return a


def _log(seg: Path, rel: str, cols: int | None, what: str, max_gap=None, gap_action="warn"):
    """``t`` and ``value`` of one log, rows matched, times strictly increasing."""
    t = _load(seg / rel / "t", (None,), f"{what} time")
    v = _load(seg / rel / "value", (None,) if cols is None else (None, cols), what)
    if len(v) != len(t):
        raise DataError(f"{what}: {len(v)} values but {len(t)} times in {seg / rel / 't'}",
                        file=str(seg / rel / "value"))
    gaps = check_times(t, np.arange(1, len(t) + 1), str(seg / rel / "t"), max_gap=max_gap,
                       gap_action=gap_action, what=what).gaps
    return t, v, gaps


def _positive(value, name: str, allow_none: bool = False):
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (math.isfinite(value) and value > 0):
        raise ArgumentError(f"must be a finite positive number, got {value!r}", name)
    return float(value)


def _gap_args(max_gap, gap_action):
    _positive(max_gap, "max_gap", allow_none=True)
    check_gap_action(gap_action)


def _sigma3(value, name: str) -> np.ndarray:
    """A sigma given as one number (all axes) or three (north, east, down)."""
    a = np.atleast_1d(np.asarray(value, dtype=float)) if not isinstance(value, (str, bool)) else None
    if a is None or a.shape not in ((1,), (3,)) or not np.all(np.isfinite(a)) or not np.all(a > 0):
        raise ArgumentError(f"must be one positive number or three (north, east, down), got {value!r}", name)
    return np.broadcast_to(a, (3,)).astype(float)


# ---------------------------------------------------------------------------
# The clocks
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CommaClock:
    """Boot time <-> GPS time of one segment: ``GPS = week0 + t + offset``.

    Attributes
    ----------
    week : int
        GPS week of the segment's first pose frame.
    offset : float
        GPS seconds of ``week`` minus boot time [s] (constant over a segment).
    leap_seconds : int
        GPS - UTC [s] used by :meth:`utc_to_boot`.
    """

    week: int
    offset: float
    leap_seconds: int = GPS_UTC_LEAP_SECONDS

    def boot_to_gps(self, t):
        """Boot time [s] -> seconds of GPS week ``self.week`` (may exceed one week)."""
        return np.asarray(t, dtype=float) + self.offset

    def gps_to_boot(self, week, tow):
        """GPS week and time of week [s] -> boot time [s]."""
        return (np.asarray(week, dtype=float) - self.week) * WEEK_SECONDS + np.asarray(tow, dtype=float) - self.offset

    def utc_to_boot(self, unix_utc):
        """UTC as Unix seconds -> boot time [s] (adds the GPS - UTC leap seconds)."""
        gps = np.asarray(unix_utc, dtype=float) - GPS_EPOCH_UNIX + self.leap_seconds
        return gps - self.week * WEEK_SECONDS - self.offset


def read_comma_clock(segment, *, leap_seconds: int = GPS_UTC_LEAP_SECONDS) -> CommaClock:
    """The boot-to-GPS offset of a segment, from ``global_pose`` frame times.

    Raises
    ------
    DataError
        Missing files, or offsets that vary by more than 1 ms over the
        segment (then boot time and GPS time are not one offset apart).
    """
    seg = _segment(segment)
    t = _load(seg / _POSE / "frame_times", (None,), "frame times")
    g = _load(seg / _POSE / "frame_gps_times", (None, 2), "frame GPS times")
    if len(g) != len(t):
        raise DataError(f"{len(g)} GPS times but {len(t)} frame times", file=str(seg / _POSE / "frame_gps_times"))
    week0 = int(g[0, 0])
    off = (g[:, 0] - week0) * WEEK_SECONDS + g[:, 1] - t
    spread = float(off.max() - off.min())
    if spread > 1e-3:
        raise DataError(f"GPS time minus boot time varies by {spread:.4g} s over the segment (> 1 ms): "
                        "the two clocks are not one offset apart", file=str(seg / _POSE / "frame_gps_times"))
    if isinstance(leap_seconds, bool) or not isinstance(leap_seconds, numbers.Integral) or leap_seconds < 0:
        raise ArgumentError(f"must be a whole number of seconds >= 0, got {leap_seconds!r}", "leap_seconds")
    return CommaClock(week=week0, offset=float(np.median(off)), leap_seconds=int(leap_seconds))


# ---------------------------------------------------------------------------
# IMU
# ---------------------------------------------------------------------------
def read_comma_imu(segment, *, gyro: str = "calibrated", max_gap: float | None = 0.05,
                   gap_action: str = "warn") -> ImuData:
    """Accelerometer and gyro of a segment as increments, body forward-right-down.

    Parameters
    ----------
    segment : path-like
        The segment folder (holding ``processed_log``).
    gyro : {"calibrated", "uncalibrated"}
        ``gyro`` (Android's bias estimate removed) or ``gyro_uncalibrated``.
    max_gap : float or None
        Longest accepted interval between samples of either sensor [s].
    gap_action : {"warn", "fail"}
        A longer interval warns (counted in ``ImuData.gaps``) or raises.

    Returns
    -------
    ImuData
        One increment per accelerometer interval ``(t[k-1], t[k]]`` on boot
        time: the trapezoid of the rates [rad/s] and specific forces
        [m/s^2] at its two ends (N stamps give N - 1 increments). Gyro rates
        stamped differently from the accelerometer are linearly interpolated
        onto the accelerometer's stamps first.
    """
    if gyro not in ("calibrated", "uncalibrated"):
        raise ArgumentError(f"must be 'calibrated' or 'uncalibrated', got {gyro!r}", "gyro")
    _gap_args(max_gap, gap_action)
    seg = _segment(segment)
    ta, f, gaps = _log(seg, f"{_IMU}/accelerometer", 3, "accelerometer", max_gap, gap_action)
    name = "gyro" if gyro == "calibrated" else "gyro_uncalibrated"
    tg, w, _ = _log(seg, f"{_IMU}/{name}", 3, "gyro", max_gap, gap_action)
    if not np.array_equal(ta, tg):
        keep = (ta >= tg[0]) & (ta <= tg[-1])
        if keep.sum() < 2:
            raise DataError("the gyro and accelerometer logs do not overlap in time",
                            file=str(seg / _IMU / name / "t"))
        ta, f = ta[keep], f[keep]
        w = np.column_stack([np.interp(ta, tg, w[:, i]) for i in range(3)])
    imu = replace(rates_to_increments(ta, w, f, source=str(seg / _IMU)), gaps=gaps)
    return check_plausible(imu, "rad/s", "m/s^2")


# ---------------------------------------------------------------------------
# GNSS
# ---------------------------------------------------------------------------
def read_comma_gnss(segment, *, pos_sigma=(2.5, 2.5, 5.0), vel_sigma=None, fix_time: str = "utc",
                    clock: CommaClock | None = None, max_gap: float | None = None,
                    gap_action: str = "warn") -> GnssFixes:
    """The u-blox fixes (``live_gnss_ublox``) of a segment.

    Parameters
    ----------
    segment : path-like
    pos_sigma : float or 3 floats
        1-sigma position error [m], north, east, down (one number: all
        three). The log carries no accuracy; the default suits a u-blox M8
        single-point fix in open sky (2.5 m CEP). In the example the fixes
        sit 2.2 m ahead of comma's pose along track (0.14 s x speed) and
        1.2 m above it, with a robust scatter of only 0.1-0.4 m about that
        offset: the errors are biases, not white noise.
    vel_sigma : float or 3 floats, optional
        When given, velocity fixes are formed from the ground speed and
        bearing (north = speed cos(bearing), east = speed sin(bearing)) with
        this 1-sigma [m/s]; the log has no vertical velocity, so *down is
        set to 0* and its sigma should be generous. None: positions only.
    fix_time : {"utc", "log"}
        "utc": the fix's own UTC time mapped to boot time through ``clock``
        (the validity time of the fix); "log": the boot time the message
        was logged (0.18-0.24 s late in the example).
    clock : CommaClock, optional
        Default: :func:`read_comma_clock` of the segment (needs ``global_pose``).
    max_gap, gap_action :
        As for the IMU; fixes come at 10 Hz with occasional missed epochs.

    Returns
    -------
    GnssFixes
        ``time`` (M,) boot time [s], ``lla`` (M, 3) latitude, longitude
        [rad], ellipsoidal height [m] (the u-blox altitude is ellipsoidal:
        it agrees with comma's pose to about 1 m, the geoid there is -32 m),
        ``pos_sigma`` (M, 3), optionally ``vel_n``/``vel_sigma`` (M, 3).
    """
    if fix_time not in ("utc", "log"):
        raise ArgumentError(f"must be 'utc' or 'log', got {fix_time!r}", "fix_time")
    psig = _sigma3(pos_sigma, "pos_sigma")
    vsig = None if vel_sigma is None else _sigma3(vel_sigma, "vel_sigma")
    _gap_args(max_gap, gap_action)
    seg = _segment(segment)
    tlog, v, _ = _log(seg, _GNSS, 6, "u-blox fixes", None)
    vfile = str(seg / _GNSS / "value")
    lat, lon, speed, utc_ms, alt, bearing = v.T
    bad = (np.abs(lat) > 90) | (np.abs(lon) > 180) | (speed < 0) | (speed > MAX_VEHICLE_SPEED)
    if bad.any():
        k = int(np.argmax(bad))
        raise DataError(f"implausible fix in row {k + 1}: lat {lat[k]:.6g} deg, lon {lon[k]:.6g} deg, "
                        f"speed {speed[k]:.6g} m/s", file=vfile, line=k + 1)
    if fix_time == "utc":
        clock = clock if clock is not None else read_comma_clock(seg)
        t = clock.utc_to_boot(utc_ms / 1000.0)
        # the arrival can only follow the fix; anything else is a wrong clock or leap second count
        late = tlog - t
        if not (-0.5 < np.median(late) < 2.0):
            raise DataError(f"fixes are logged {np.median(late):.3f} s after their UTC time (median): "
                            "expected a fraction of a second; wrong clock offset or leap seconds?", file=vfile)
    else:
        t = tlog
    check_times(t, np.arange(1, len(t) + 1), vfile if fix_time == "utc" else str(seg / _GNSS / "t"),
                max_gap=max_gap, gap_action=gap_action, what="GNSS fix")
    lla = np.column_stack([lat * DEG, lon * DEG, alt])
    m = len(t)
    if vsig is None:
        return GnssFixes(time=t, lla=lla, pos_sigma=np.tile(psig, (m, 1)), source=str(seg / _GNSS))
    vel = np.column_stack([speed * np.cos(bearing * DEG), speed * np.sin(bearing * DEG), np.zeros(m)])
    return GnssFixes(time=t, lla=lla, pos_sigma=np.tile(psig, (m, 1)), vel_n=vel,
                     vel_sigma=np.tile(vsig, (m, 1)), source=str(seg / _GNSS))


# ---------------------------------------------------------------------------
# CAN speeds
# ---------------------------------------------------------------------------
#: Odometer sources: what ``read_comma_odometer(source=...)`` returns.
ODOMETER_SOURCES = ("rear_wheels", "speed")


def read_comma_odometer(segment, *, source: str = "rear_wheels", sigma: float = 0.1, time_offset: float = 0.0,
                        max_gap: float | None = 0.1, gap_action: str = "warn") -> OdometerData:
    """The car's CAN speed as odometer samples on boot time.

    Parameters
    ----------
    segment : path-like
    source : {"rear_wheels", "speed"}
        "rear_wheels" (default): the mean of the rear left and rear right
        wheel speeds, the speed of the rear-axle centre, the point of a
        front-steered car that does not slip sideways (the non-holonomic
        constraint holds there). "speed": the car's vehicle-speed signal,
        which in the example segment is the mean of all four wheel speeds
        (to 1e-14 m/s), so it mixes in the front axle (faster in turns).
        Both read about 0.9 % below the GNSS speed (a scale factor for the
        filter to estimate).
    sigma : float
        1-sigma noise of every sample [m/s] (the log has none). The wheel
        speeds come in steps of 0.01 km/h; once scaled, the odometer's
        robust scatter about comma's pose speed is 0.04-0.05 m/s and about
        the u-blox speed 0.07-0.08 m/s (which includes the GNSS noise).
    time_offset : float
        Added to every CAN time [s]; about -0.08 s aligns the CAN speed with
        the IMU in the example (arrival latency; a rough estimate, the two
        halves of the minute give -0.14 and -0.08 s). Default 0: as logged.
    max_gap, gap_action :
        Longest accepted interval between CAN samples [s] (~12 ms nominal)
        and what a longer one does ("warn" or "fail").

    Returns
    -------
    OdometerData
        ``time`` (M,) boot time [s], ``speed`` (M,) [m/s] (unsigned: the
        wheel-speed sensors do not tell reversing), ``sigma`` (M,) [m/s].
    """
    if source not in ODOMETER_SOURCES:
        raise ArgumentError(f"must be one of {', '.join(ODOMETER_SOURCES)}, got {source!r}", "source")
    sigma = _positive(sigma, "sigma")
    if isinstance(time_offset, bool) or not isinstance(time_offset, numbers.Real) or not math.isfinite(time_offset):
        raise ArgumentError(f"must be a finite time [s], got {time_offset!r}", "time_offset")
    _gap_args(max_gap, gap_action)
    seg = _segment(segment)
    if source == "speed":
        rel = f"{_CAN}/speed"
        t, speed, gaps = _log(seg, rel, None, "CAN speed", max_gap, gap_action)
    else:
        rel = f"{_CAN}/wheel_speed"
        t, v, gaps = _log(seg, rel, 4, "CAN wheel speeds", max_gap, gap_action)
        speed = v[:, 2:].mean(axis=1)
    vfile = str(seg / rel / "value")
    bad = (speed < 0) | (speed > MAX_VEHICLE_SPEED)
    if bad.any():
        k = int(np.argmax(bad))
        raise DataError(f"speed {speed[k]:.6g} m/s in row {k + 1} is negative or above "
                        f"{MAX_VEHICLE_SPEED:g} m/s (wrong unit?)", file=vfile, line=k + 1)
    return OdometerData(time=t + float(time_offset), speed=speed, sigma=np.full(len(t), sigma), signed=False,
                        source=vfile, gaps=gaps)


# ---------------------------------------------------------------------------
# comma's pose
# ---------------------------------------------------------------------------
def read_comma_pose(segment) -> Trajectory:
    """comma's ``global_pose`` of the camera as a Trajectory on boot time.

    Not an independent truth: it is comma's own tightly coupled
    INS/GNSS/vision optimiser, fed by the same GNSS and IMU. The point and
    the body are the *camera* (forward, right, down), not the IMU.

    Returns
    -------
    Trajectory
        ``time`` (F,) boot time [s] (20 Hz), ``lla`` (F, 3) [rad, rad, m]
        from the ECEF positions, ``v_n`` (F, 3) NED velocity from the ECEF
        velocities, ``q_nb`` (F, 4) camera to NED (``C_nc = C_ne C_ec``,
        ``C_ec`` the frame quaternion). ``extra``: ``gps_week``, ``gps_tow``
        (F,), ``position_ecef``, ``velocity_ecef`` (F, 3), ``point`` = "camera".
    """
    seg = _segment(segment)
    t = _load(seg / _POSE / "frame_times", (None,), "frame times")
    n = len(t)
    gps = _load(seg / _POSE / "frame_gps_times", (n, 2), "frame GPS times")
    p = _load(seg / _POSE / "frame_positions", (n, 3), "frame positions")
    v = _load(seg / _POSE / "frame_velocities", (n, 3), "frame velocities")
    q = _load(seg / _POSE / "frame_orientations", (n, 4), "frame orientations")
    check_times(t, np.arange(1, n + 1), str(seg / _POSE / "frame_times"), what="frame")
    r = np.linalg.norm(p, axis=1)
    if np.any((r < 6.2e6) | (r > 6.5e6)):
        k = int(np.argmax((r < 6.2e6) | (r > 6.5e6)))
        raise DataError(f"row {k + 1} is {r[k]:.6g} m from the Earth's centre: not an ECEF position on the ground",
                        file=str(seg / _POSE / "frame_positions"), line=k + 1)
    qn = np.linalg.norm(q, axis=1)
    if np.any(np.abs(qn - 1.0) > 1e-3):
        k = int(np.argmax(np.abs(qn - 1.0)))
        raise DataError(f"quaternion in row {k + 1} has norm {qn[k]:.6g}, not 1",
                        file=str(seg / _POSE / "frame_orientations"), line=k + 1)
    lla = ecef_to_lla(p)
    c_ne = dcm_ecef_to_ned(lla[:, 0], lla[:, 1])
    v_n = np.einsum("kij,kj->ki", c_ne, v)
    c_nc = c_ne @ quat_to_dcm(q / qn[:, None])
    return Trajectory(time=t, lla=lla, v_n=v_n, q_nb=dcm_to_quat(c_nc),
                      extra={"gps_week": gps[:, 0].astype(int), "gps_tow": gps[:, 1], "position_ecef": p,
                             "velocity_ecef": v, "point": "camera"})


# ---------------------------------------------------------------------------
# All of it
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CommaSegment:
    """A segment's data on boot time (see the module docstring)."""

    imu: ImuData
    gnss: GnssFixes
    odometer: OdometerData
    reference: Trajectory
    clock: CommaClock


def read_comma_segment(segment, *, gnss_pos_sigma=(2.5, 2.5, 5.0), gnss_vel_sigma=None,
                       odometer_source: str = "rear_wheels", odometer_sigma: float = 0.1,
                       odometer_time_offset: float = 0.0, gyro: str = "calibrated") -> CommaSegment:
    """IMU, GNSS fixes, odometer, comma's pose and the clock of one segment.

    The arguments are those of :func:`read_comma_imu` (``gyro``),
    :func:`read_comma_gnss` (``pos_sigma``, ``vel_sigma``) and
    :func:`read_comma_odometer` (``source``, ``sigma``, ``time_offset``);
    the other arguments keep their defaults.
    """
    clock = read_comma_clock(segment)
    return CommaSegment(
        imu=read_comma_imu(segment, gyro=gyro),
        gnss=read_comma_gnss(segment, pos_sigma=gnss_pos_sigma, vel_sigma=gnss_vel_sigma, clock=clock),
        odometer=read_comma_odometer(segment, source=odometer_source, sigma=odometer_sigma,
                                     time_offset=odometer_time_offset),
        reference=read_comma_pose(segment), clock=clock)


# ---------------------------------------------------------------------------
# The registered readers (format "comma2k19": a table's file is the segment folder)
# ---------------------------------------------------------------------------
def read_comma_ublox_reference(segment, *, max_gap: float | None = None, gap_action: str = "warn") -> Trajectory:
    """The u-blox fixes as a position-only Trajectory (the antenna; no velocity, no attitude).

    Not an independent truth either: it is the same receiver the filter uses. It is the truth
    of a window whose fixes the filter was *denied* (an outage), the way the tuner's
    cross-validation and docs/evaluation.md's outage sweep use a recording's own GNSS.
    """
    fixes = read_comma_gnss(segment, max_gap=max_gap, gap_action=gap_action)
    return Trajectory(time=fixes.time, lla=fixes.lla, v_n=None, q_nb=None,
                      extra={"point": "antenna", "source": fixes.source})


@register_reader("imu", "comma2k19")
def _read_imu(path: Path, options: ReadOptions) -> ImuData:
    """The registered IMU reader: the calibrated gyro (``options``: ``max_gap``, ``gap_action``)."""
    return read_comma_imu(path, max_gap=options.get("max_gap", 0.05), gap_action=options.get("gap_action", "warn"))


@register_reader("gnss-fixes", "comma2k19")
def _read_fixes(path: Path, options: ReadOptions) -> GnssFixes:
    """The registered GNSS reader: the u-blox fixes at their UTC time, positions only, the
    default sigmas (``options``: ``max_gap``, ``gap_action``; the dataset's ``min_sigma``
    floors them afterwards). No velocity: the log's speed and bearing are horizontal, and a
    zero vertical velocity would be wrong by the road's grade (0.3-0.5 m/s at 2.7 %)."""
    return read_comma_gnss(path, max_gap=options.get("max_gap"), gap_action=options.get("gap_action", "warn"))


@register_reader("odometer", "comma2k19")
def _read_odometer(path: Path, options: ReadOptions) -> OdometerData:
    """The registered odometer reader: the rear-wheel mean (``options``: ``sigma`` [m/s],
    ``max_gap``, ``gap_action``; CAN time as logged, ``time_offset`` 0)."""
    return read_comma_odometer(path, sigma=options.get("sigma", 0.1), max_gap=options.get("max_gap", 0.1),
                               gap_action=options.get("gap_action", "warn"))


@register_reader("reference", "comma2k19")
def _read_pose(path: Path, options: ReadOptions) -> Trajectory:
    """The registered reference reader: comma's ``global_pose`` (NOT an independent truth)."""
    return read_comma_pose(path)


@register_reader("reference", "comma2k19-ublox")
def _read_ublox_reference(path: Path, options: ReadOptions) -> Trajectory:
    """The u-blox fixes as the reference (the truth of withheld windows)."""
    return read_comma_ublox_reference(path)
