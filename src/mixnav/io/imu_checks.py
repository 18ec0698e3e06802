"""Shared IMU conversions and plausibility checks for the readers."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from ..data import ImuData
from ..errors import DataError

G0 = 9.80665
#: Largest plausible 99th-percentile angular rate of a vehicle [rad/s]: 290 deg/s.
#: Cars stay below 1 rad/s and aircraft below 3; deg/s data declared as rad/s
#: (a 10 deg/s turn read as 10 rad/s) lands above it.
MAX_RATE = 5.0
#: Spikes: beyond the widest common MEMS gyro range (2000 deg/s) or 50 g (check_spikes).
SPIKE_RATE = float(np.radians(2000.0))
SPIKE_FORCE = 50.0 * G0
#: A record "moves" when the 5-95 % spread of its specific force's norm exceeds this [m/s^2] ...
MOVING_FORCE_SPREAD = 1.0
#: ... and then its 99th-percentile rate is above this [rad/s] (0.5 deg/s).
MIN_MOVING_RATE = float(np.radians(0.5))


class DataWarning(UserWarning):
    """Data accepted with a documented handling (a spike replaced, a gap accepted)."""


def rates_to_increments(t, w, f, source=None, lines=None) -> ImuData:
    """Angular rate [rad/s] and specific force [m/s^2] samples to increments.

    The increment over ``(t[k-1], t[k]]`` is the trapezoid of the two samples,
    so N samples give N - 1 increments (the first sample only opens the first
    interval).
    """
    if len(t) < 2:
        raise DataError("need at least two IMU samples", file=source)
    dt = np.diff(t)
    dth = 0.5 * (w[1:] + w[:-1]) * dt[:, None]
    dv = 0.5 * (f[1:] + f[:-1]) * dt[:, None]
    return ImuData(time=np.asarray(t[1:], float), dt=dt, dtheta=dth, dvel=dv, source=source)


def check_spikes(imu: ImuData, lines=None, action: str = "fail") -> ImuData:
    """Find IMU samples beyond what any sensor in a vehicle measures (docs/validation.md).

    A spike is an increment whose mean rate exceeds :data:`SPIKE_RATE` (2000
    deg/s, the top of the widest common MEMS gyro range) or whose mean specific
    force exceeds :data:`SPIKE_FORCE` (50 g). ``action="fail"`` (the default)
    raises a DataError naming the file and line of the first one; ``"reject"``
    replaces each spike's rates by those interpolated from the good increments
    around it, and counts the increments replaced (``ImuData.spikes``,
    ``imu_spikes_rejected`` in metrics.json; one bad sample of a rate file
    spoils the two increments it ends and opens). ``lines``: the file line of each increment.
    """
    if action not in ("fail", "reject"):
        raise ValueError(f"spike action must be 'fail' or 'reject', got {action!r}")
    w = imu.dtheta / imu.dt[:, None]
    f = imu.dvel / imu.dt[:, None]
    wn, fn = np.linalg.norm(w, axis=1), np.linalg.norm(f, axis=1)
    bad = (wn > SPIKE_RATE) | (fn > SPIKE_FORCE)
    if not bad.any():
        return imu
    k = int(np.argmax(bad))
    where = f"{int(bad.sum())} sample(s) beyond {np.degrees(SPIKE_RATE):.0f} deg/s or {SPIKE_FORCE / G0:.0f} g"
    if action == "fail" or (~bad).sum() < 2:
        line = None if lines is None else int(np.asarray(lines)[k])
        raise DataError(f"IMU spike: angular rate {np.degrees(wn[k]):.4g} deg/s, specific force {fn[k]:.4g} m/s^2 "
                        f"(t = {imu.time[k]:.3f} s); {where}. No vehicle moves so; set imu.spike_action = "
                        "\"reject\" to replace such samples by their neighbours (counted in metrics.json)",
                        file=imu.source, line=line)
    good = np.flatnonzero(~bad)
    t = imu.time
    w2 = np.column_stack([np.interp(t, t[good], w[good, i]) for i in range(3)])
    f2 = np.column_stack([np.interp(t, t[good], f[good, i]) for i in range(3)])
    warnings.warn(f"{imu.source}: {where} replaced by interpolation (imu.spike_action = 'reject')",
                  DataWarning, stacklevel=2)
    return replace(imu, dtheta=w2 * imu.dt[:, None], dvel=f2 * imu.dt[:, None], spikes=int(bad.sum()))


def check_plausible(imu: ImuData, gyro_unit: str, accel_unit: str, lines=None,
                    spike_action: str = "fail") -> ImuData:
    """Refuse data whose size does not fit the declared units; find spikes (:func:`check_spikes`).

    The median specific force over a record must be near gravity (a vehicle
    spends most of its time near 1 g), and the 99th percentile of the rate
    below 5 rad/s (deg/s data declared as rad/s gives tens of "rad/s"). In the
    other direction, a record whose specific force varies like a moving
    vehicle's (5-95 % spread of its norm above
    :data:`MOVING_FORCE_SPREAD`) must turn: a 99th-percentile rate below
    :data:`MIN_MOVING_RATE` (0.5 deg/s) is rad/s data declared as deg/s (57
    times too small). Returns the data with spikes handled.
    """
    f = np.linalg.norm(imu.dvel / imu.dt[:, None], axis=1)
    w = np.linalg.norm(imu.dtheta / imu.dt[:, None], axis=1)
    fm = float(np.median(f))
    if not 0.5 * G0 < fm < 1.5 * G0:
        raise DataError(f"median specific force is {fm:.4g} m/s^2 with the accelerometer declared in "
                        f"'{accel_unit}'; gravity is 9.8 m/s^2: the unit is probably wrong", file=imu.source)
    wp = float(np.percentile(w, 99))
    if wp > MAX_RATE:
        raise DataError(f"99 % of angular rates are below {wp:.4g} rad/s with the gyro declared in "
                        f"'{gyro_unit}': implausible for a vehicle (> {MAX_RATE:g} rad/s); "
                        "the unit is probably wrong (deg/s declared as rad/s?)", file=imu.source)
    fs = float(np.percentile(f, 95) - np.percentile(f, 5))   # robust to a few spikes
    if fs > MOVING_FORCE_SPREAD and wp < MIN_MOVING_RATE:
        raise DataError(f"the specific force varies like a moving vehicle's (5-95 % spread {fs:.3g} m/s^2) but 99 % of "
                        f"angular rates are below {np.degrees(wp):.3g} deg/s with the gyro declared in "
                        f"'{gyro_unit}': a vehicle that moves turns faster; the unit is probably wrong "
                        "(rad/s declared as deg/s?)", file=imu.source)
    return check_spikes(imu, lines, spike_action)


#: check_turns: the GNSS track must turn this much [rad] (over intervals with both fixes
#: above MIN_TRACK_SPEED) before the gyro is compared with it
MIN_TRACK_TURN = float(np.radians(90.0))
MIN_TRACK_SPEED = 3.0
#: the gyro's turning over the GNSS track's must lie in this range (a unit error is 57x off)
TURN_RATIO = (0.2, 5.0)


def check_turns(imu: ImuData, time: np.ndarray, lla: np.ndarray, vel_n: np.ndarray | None,
                gyro_unit: str = "the declared unit") -> dict | None:
    """Compare the gyro's turning with the GNSS track's: a gyro unit error is 57 times off.

    Over consecutive fixes (at most 2 s apart) both moving faster than
    :data:`MIN_TRACK_SPEED`, the track's course change is summed (absolute) and
    so is the angle the gyros measured (norm of the angle increments). Once the
    track has turned :data:`MIN_TRACK_TURN`, their ratio must lie within
    :data:`TURN_RATIO`, else a DataError names the IMU file (rad/s declared as
    deg/s gives 1/57, the reverse 57). Returns ``{"track_turn_deg",
    "gyro_turn_deg", "ratio"}`` or None when the track turns too little. Times
    of the IMU and the fixes on one axis [s]; ``lla`` [rad, rad, m].
    """
    if len(time) < 3 or len(imu) < 2:
        return None
    if vel_n is not None:
        vn, ve = vel_n[:, 0], vel_n[:, 1]
    else:  # course from consecutive positions (metres on a local sphere)
        dn = np.gradient(lla[:, 0], time) * 6.371e6
        de = np.gradient(lla[:, 1], time) * 6.371e6 * np.cos(lla[:, 0])
        vn, ve = dn, de
    speed = np.hypot(vn, ve)
    course = np.arctan2(ve, vn)
    dt = np.diff(time)
    ok = (speed[1:] > MIN_TRACK_SPEED) & (speed[:-1] > MIN_TRACK_SPEED) & (dt <= 2.0) & (dt > 0)
    ok &= (time[:-1] >= imu.time[0]) & (time[1:] <= imu.time[-1])
    dc = np.abs((np.diff(course) + np.pi) % (2 * np.pi) - np.pi)
    track = float(dc[ok].sum())
    if not track >= MIN_TRACK_TURN:
        return None
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(imu.dtheta, axis=1))])
    at = np.interp(time, np.concatenate([[imu.time[0] - imu.dt[0]], imu.time]), cum)
    gyro = float(np.diff(at)[ok].sum())
    ratio = gyro / track
    if not TURN_RATIO[0] <= ratio <= TURN_RATIO[1]:
        hint = "rad/s declared as deg/s?" if ratio < 1 else "deg/s declared as rad/s?"
        raise DataError(f"the gyros measured {np.degrees(gyro):.4g} deg of turning while the GNSS track turned "
                        f"{np.degrees(track):.4g} deg over the same moving intervals (ratio {ratio:.3g}, expected "
                        f"{TURN_RATIO[0]:g}..{TURN_RATIO[1]:g}) with the gyro in {gyro_unit}: the gyro unit is "
                        f"probably wrong ({hint})", file=imu.source)
    return {"track_turn_deg": float(np.degrees(track)), "gyro_turn_deg": float(np.degrees(gyro)),
            "ratio": float(ratio)}
