"""Odometer readers: the generic odometer CSV and the comma2k19 segment.

1. The CSV: round trips (speed, cumulative distance, increments, units),
   and every kind of bad input naming the file and the line.
2. comma2k19 (skips without ../shared/data): one time axis, rates, gravity,
   and the odometer against the GNSS and comma's pose.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from mixnav.attitude import dcm_to_quat
from mixnav.data import MAX_VEHICLE_SPEED, OdometerData
from mixnav.errors import ArgumentError, DataError
from mixnav.geodesy.frames import dcm_ecef_to_ned, lla_to_ecef, lla_to_ned
from mixnav.io import comma2k19 as cm
from mixnav.io.odometer_csv import read_odometer_csv

from .conftest import data_file


def assert_data_error(excinfo, path, line, pattern):
    """The DataError names ``path`` and ``line`` and its message matches ``pattern``."""
    exc = excinfo.value
    assert type(exc) is DataError
    assert exc.file == str(path)
    assert exc.line == line, str(exc)
    assert str(exc).startswith(f"{path}, line {line}: "), str(exc)
    assert re.search(pattern, str(exc), re.IGNORECASE), str(exc)


def write_lines(path, lines):
    Path(path).write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    return path


# A car speeding up and slowing down: v(t) = 10 + 3 sin(0.5 t) m/s, 10 Hz for 20 s.
N, DT, T0 = 201, 0.1, 1000.0


def num(x) -> str:
    """A number as text that reads back exactly (numpy scalars included)."""
    return repr(float(x))


def true_speed(t):
    return 10.0 + 3.0 * np.sin(0.5 * (t - T0))


def true_distance(t):
    return 10.0 * (t - T0) + 6.0 * (1.0 - np.cos(0.5 * (t - T0)))


TIMES = T0 + DT * np.arange(N)


def speed_lines(head="time[s],speed[m/s]", factor=1.0, sigma=None):
    rows = [head]
    for k, t in enumerate(TIMES):
        row = f"{num(t)},{num(true_speed(t) * factor)}"
        rows.append(row + (f",{num(sigma[k])}" if sigma is not None else ""))
    return rows


def distance_lines(head="time[s],distance[m]", factor=1.0):
    return [head] + [f"{num(t)},{num(true_distance(t) * factor)}" for t in TIMES]


def increment_lines(head="time[s],distance_increment[m]"):
    d = true_distance(TIMES)
    inc = np.concatenate([[123.0], np.diff(d)])   # the first increment has no interval: ignored
    return [head] + [f"{num(t)},{num(i)}" for t, i in zip(TIMES, inc)]


# ===========================================================================
# 1. Round trips
# ===========================================================================
def test_speed_round_trip(tmp_path):
    od = read_odometer_csv(write_lines(tmp_path / "odo.csv", speed_lines()), sigma=0.05)
    assert isinstance(od, OdometerData) and len(od) == N and not od.signed
    np.testing.assert_allclose(od.time, TIMES, rtol=0, atol=1e-12)
    np.testing.assert_allclose(od.speed, true_speed(TIMES), rtol=1e-14)
    np.testing.assert_array_equal(od.sigma, np.full(N, 0.05))
    assert od.source == str(tmp_path / "odo.csv")


@pytest.mark.parametrize("make", [distance_lines, increment_lines])
def test_distance_forms_agree_with_speed(tmp_path, make):
    od = read_odometer_csv(write_lines(tmp_path / "odo.csv", make()), sigma=0.05)
    # One sample per interval, at its midpoint.
    assert len(od) == N - 1
    mid = 0.5 * (TIMES[1:] + TIMES[:-1])
    np.testing.assert_allclose(od.time, mid, rtol=0, atol=1e-12)
    # Mean speed over 0.1 s = speed at the midpoint up to v'' dt^2 / 24 = 0.75 * 0.01 / 24 = 3e-4 m/s.
    err = np.abs(od.speed - true_speed(mid))
    assert err.max() < 3.2e-4
    assert err.max() > 1e-5          # and it is the midpoint rule, not exact: the test can fail
    # The speed file read at the same times agrees as well (interpolated).
    sp = read_odometer_csv(write_lines(tmp_path / "s.csv", speed_lines()), sigma=0.05)
    assert np.abs(np.interp(od.time, sp.time, sp.speed) - od.speed).max() < 1e-3


def test_distance_forms_give_identical_samples(tmp_path):
    a = read_odometer_csv(write_lines(tmp_path / "a.csv", distance_lines()), sigma=0.1)
    b = read_odometer_csv(write_lines(tmp_path / "b.csv", increment_lines()), sigma=0.1)
    np.testing.assert_allclose(a.speed, b.speed, rtol=1e-9)
    np.testing.assert_array_equal(a.time, b.time)


def test_distance_in_km_and_time_in_ms(tmp_path):
    rows = ["time[ms],distance[km]"] + [f"{num(t * 1e3)},{num(true_distance(t) / 1e3)}" for t in TIMES]
    od = read_odometer_csv(write_lines(tmp_path / "odo.csv", rows), sigma=0.1)
    ref = read_odometer_csv(write_lines(tmp_path / "ref.csv", distance_lines()), sigma=0.1)
    np.testing.assert_allclose(od.time, ref.time, rtol=1e-12)
    np.testing.assert_allclose(od.speed, ref.speed, rtol=1e-7)


@pytest.mark.parametrize("head, units", [
    ("time[s],speed[km/h]", None),
    ("speed,time[s]", {"speed": "km/h"}),            # columns in any order; unit from the argument
    ("time,speed", {"speed": "km/h", "time": "s"}),
    ("time[s],speed[km/h]", {"speed": "km/h"}),       # given twice, agreeing
])
def test_km_per_hour_is_converted(tmp_path, head, units):
    rows = [head]
    for t in TIMES:
        kmh = true_speed(t) * 3.6
        rows.append(f"{num(kmh)},{num(t)}" if head.startswith("speed") else f"{num(t)},{num(kmh)}")
    od = read_odometer_csv(write_lines(tmp_path / "odo.csv", rows), sigma=0.1, units=units)
    np.testing.assert_allclose(od.speed, true_speed(TIMES), rtol=1e-12)
    assert 7.0 < od.speed.min() and od.speed.max() < 13.0


def test_sigma_column_with_its_unit(tmp_path):
    sig = 0.1 + 0.01 * np.arange(N)
    rows = speed_lines("time[s],speed[m/s],sigma[km/h]", sigma=sig * 3.6)
    od = read_odometer_csv(write_lines(tmp_path / "odo.csv", rows))      # no sigma argument needed
    np.testing.assert_allclose(od.sigma, sig, rtol=1e-12)
    # A distance file's sigma belongs to the interval its line closes.
    rows = ["time[s],distance[m],sigma[m/s]"] + [f"{num(t)},{num(true_distance(t))},{num(s)}"
                                                  for t, s in zip(TIMES, sig)]
    od = read_odometer_csv(write_lines(tmp_path / "d.csv", rows))
    np.testing.assert_allclose(od.sigma, sig[1:], rtol=1e-12)


def test_signed_speeds_are_kept(tmp_path):
    rows = ["time[s],speed[m/s]", "0,1.0", "0.1,-0.5", "0.2,-1.5"]
    od = read_odometer_csv(write_lines(tmp_path / "odo.csv", rows), sigma=0.1, signed=True)
    assert od.signed
    np.testing.assert_array_equal(od.speed, [1.0, -0.5, -1.5])
    rows = ["time[s],distance[m]", "0,10", "0.5,9", "1,9.5"]
    od = read_odometer_csv(write_lines(tmp_path / "d.csv", rows), sigma=0.1, signed=True)
    np.testing.assert_allclose(od.speed, [-2.0, 1.0])


# ===========================================================================
# 2. Bad input: the file and the line
# ===========================================================================
BAD = 7          # the damaged line (1-based, the header is line 1)


def _set(rows, line, value, col=1):
    toks = rows[line - 1].split(",")
    toks[col] = value
    rows[line - 1] = ",".join(toks)
    return rows


def _case(case):
    """(rows, line named, message pattern, read kwargs) for one kind of bad input."""
    rows = speed_lines()
    if case == "non-numeric":
        return _set(rows, BAD, "fast"), BAD, r"not a number: 'fast'", {}
    if case == "nan":
        return _set(rows, BAD, "nan"), BAD, r"non-finite", {}
    if case == "negative":
        return _set(rows, BAD, "-0.3"), BAD, r"speed is negative \(-0.3 m/s\).*signed", {}
    if case == "absurd":
        return _set(rows, BAD, "120.5"), BAD, r"above 100 m/s.*unit", {}
    if case == "absurd km/h declared m/s":
        rows = speed_lines(factor=3.6)
        rows[1:] = [_set([r], 1, num(float(r.split(",")[1]) * 10))[0] for r in rows[1:]]
        return rows, 2, r"speed 360 m/s is above", {}
    if case == "out of order":
        return _set(rows, BAD, num(TIMES[BAD - 4]), col=0), BAD, r"time goes backwards", {}
    if case == "duplicate time":
        return _set(rows, BAD, num(TIMES[BAD - 3]), col=0), BAD, r"time repeats", {}
    if case == "gap":
        rows = [rows[0]] + [r for k, r in enumerate(rows[1:], start=2) if k not in (BAD - 1, BAD - 2)]
        # lines BAD-1 and BAD-2 removed: the line now at BAD-2 ends a 0.3 s interval
        return rows, BAD - 2, r"1 gap\(s\) longer than 0.25 s.*0\.300 s", {"max_gap": 0.25, "gap_action": "fail"}
    if case == "zero sigma":
        return speed_lines("time[s],speed[m/s],sigma[m/s]", sigma=np.where(np.arange(N) == BAD - 2, 0.0, 0.1)), \
            BAD, r"sigma must be positive", {}
    if case == "missing column":
        rows[BAD - 1] = rows[BAD - 1].split(",")[0]
        return rows, BAD, r"expected 2 columns, found 1", {}
    if case == "decreasing distance":
        rows = distance_lines()
        return _set(rows, BAD, num(true_distance(TIMES[BAD - 4]))), BAD, r"distance decreases", {}
    if case == "negative increment":
        rows = increment_lines()
        return _set(rows, BAD, "-0.2"), BAD, r"distance increment is negative", {}
    if case == "absurd distance (mm declared m)":
        rows = distance_lines(head="time[s],distance[m]", factor=1000.0)
        return rows, 3, r"speed 10075 m/s from the distance over the interval is above 100 m/s", {}
    if case == "header only":
        return rows[:1], 1, r"empty: no data line after the header", {}
    if case == "empty file":
        return [], 1, r"empty \(no header line\)", {}
    if case == "blank then nothing":
        return ["", ""], 1, r"empty \(no header line\)", {}
    if case == "unknown column":
        rows[0] = "time[s],velocity[m/s]"
        return rows, 1, r"unknown column 'velocity'", {}
    if case == "two motion columns":
        rows = [r + ",1.0" for r in rows]
        rows[0] = "time[s],speed[m/s],distance[m]"
        return rows, 1, r"exactly one of speed, distance, distance_increment", {}
    if case == "speed in a length unit":
        rows[0] = "time[s],speed[m]"
        return rows, 1, r"column 'speed'.*velocity", {}
    if case == "no unit":
        rows[0] = "time[s],speed"
        return rows, 1, r"column 'speed' has no unit", {}
    if case == "units disagree":
        rows[0] = "time[s],speed[m/s]"
        return rows, 1, r"'m/s' in the header but units says 'km/h'", {"units": {"speed": "km/h"}}
    if case == "duplicate column":
        rows = [r + ",1.0" for r in rows]
        rows[0] = "time[s],speed[m/s],speed[m/s]"
        return rows, 1, r"appears twice", {}
    raise AssertionError(case)


CASES = ["non-numeric", "nan", "negative", "absurd", "absurd km/h declared m/s", "out of order",
         "duplicate time", "gap", "zero sigma", "missing column", "decreasing distance", "negative increment",
         "absurd distance (mm declared m)", "header only", "empty file", "blank then nothing", "unknown column",
         "two motion columns", "speed in a length unit", "no unit", "units disagree", "duplicate column"]


@pytest.mark.parametrize("case", CASES)
def test_bad_input_names_file_and_line(tmp_path, case):
    rows, line, pattern, kw = _case(case)
    p = write_lines(tmp_path / "odo.csv", rows)
    kw.setdefault("sigma", 0.1)
    with pytest.raises(DataError) as ei:
        read_odometer_csv(p, **kw)
    assert_data_error(ei, p, line, pattern)


def test_gap_warns_names_the_line_and_keeps_the_data(tmp_path):
    rows = speed_lines()
    del rows[BAD - 1]                                # one line missing: a 0.2 s interval ends at BAD
    p = write_lines(tmp_path / "odo.csv", rows)
    with pytest.warns(UserWarning, match=rf"{re.escape(str(p))}, line {BAD}: 1 gap\(s\) longer than 0.15 s"):
        od = read_odometer_csv(p, sigma=0.1, max_gap=0.15, gap_action="warn")
    assert len(od) == N - 1 and od.gaps == 1           # accepted, and counted like ImuData.gaps
    assert np.diff(od.time).max() == pytest.approx(0.2)
    assert read_odometer_csv(p, sigma=0.1, max_gap=0.25, gap_action="fail").gaps == 0  # within the limit: silent
    assert read_odometer_csv(p, sigma=0.1).gaps == 0    # no max_gap: gaps are not looked for
    del rows[BAD + 2]                                   # a second gap, in the distance form too
    rows = ["time[s],distance[m]"] + [f"{r.split(',')[0]},{k}" for k, r in enumerate(rows[1:])]
    with pytest.warns(UserWarning, match=r"2 gap\(s\)"):
        assert read_odometer_csv(write_lines(tmp_path / "d.csv", rows), sigma=0.1, max_gap=0.15).gaps == 2


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        read_odometer_csv(tmp_path / "nope.csv", sigma=0.1)


@pytest.mark.parametrize("kw, argument", [
    ({}, "sigma"),                                     # no sigma column and no argument
    ({"sigma": 0.0}, "sigma"),
    ({"sigma": float("nan")}, "sigma"),
    ({"sigma": 0.1, "gap_action": "ignore"}, "gap_action"),
    ({"sigma": 0.1, "max_gap": -1.0}, "max_gap"),
    ({"sigma": 0.1, "units": {"speed": "deg"}}, "units.speed"),
    ({"sigma": 0.1, "units": {"velocity": "m/s"}}, "units.velocity"),
])
def test_bad_arguments(tmp_path, kw, argument):
    p = write_lines(tmp_path / "odo.csv", speed_lines())
    with pytest.raises(ArgumentError) as ei:
        read_odometer_csv(p, **kw)
    assert ei.value.argument == argument


def test_max_vehicle_speed_is_the_limit(tmp_path):
    rows = ["time[s],speed[m/s]", "0,1", f"0.1,{num(MAX_VEHICLE_SPEED)}"]
    assert read_odometer_csv(write_lines(tmp_path / "a.csv", rows), sigma=0.1).speed[-1] == MAX_VEHICLE_SPEED


# ===========================================================================
# 3. comma2k19: a synthetic segment (no data needed)
# ===========================================================================

BOOT0, OFFSET, WEEK = 5000.0, 357697.849502, 2012
LAT, LON = 0.6583, -2.1376          # [rad], about 37.7 N, 122.5 W


def save(path, a):
    """A numpy array without the .npy extension, as comma2k19 stores them."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        np.save(fh, np.asarray(a))


def make_segment(root, gyro_shift=0.0, speed=10.0):
    """A car driving north at ``speed`` on boot time BOOT0.., every log of a segment."""
    seg = root / "seg"
    pl = seg / "processed_log"
    ti = BOOT0 + 0.01 * np.arange(600)
    acc = np.tile([0.2, 0.0, -9.8], (600, 1)) + np.column_stack([0.1 * np.sin(ti), np.zeros(600), np.zeros(600)])
    save(pl / "IMU/accelerometer/t", ti)
    save(pl / "IMU/accelerometer/value", acc)
    tg = ti + gyro_shift
    for name in ("gyro", "gyro_uncalibrated"):
        save(pl / f"IMU/{name}/t", tg)
        save(pl / f"IMU/{name}/value", np.column_stack([0.01 * (tg - BOOT0), -0.02 * np.ones(600), 0.03 + 0.0 * tg]))
    tc = BOOT0 + 0.0125 * np.arange(480)
    wheels = np.column_stack([np.full(480, speed + 0.1), np.full(480, speed + 0.1), np.full(480, speed - 0.1),
                              np.full(480, speed + 0.1)])
    for name, v in (("speed", wheels.mean(1)[:, None]), ("wheel_speed", wheels), ("steering_angle", np.zeros(480))):
        save(pl / f"CAN/{name}/t", tc)
        save(pl / f"CAN/{name}/value", v)
    # u-blox: fixes every 0.1 s of GPS time, logged 0.2 s later
    tfix = BOOT0 + 0.1 + 0.1 * np.arange(55)
    utc_ms = (tfix + OFFSET + WEEK * cm.WEEK_SECONDS + cm.GPS_EPOCH_UNIX - cm.GPS_UTC_LEAP_SECONDS) * 1e3
    north = speed * (tfix - BOOT0)
    lat_deg = np.degrees(LAT + north / 6.36e6)
    save(pl / "GNSS/live_gnss_ublox/t", tfix + 0.2)
    save(pl / "GNSS/live_gnss_ublox/value", np.column_stack([lat_deg, np.full(55, np.degrees(LON)), np.full(55, speed),
                                                             utc_ms, np.full(55, 30.0), np.full(55, 0.0)]))
    # pose: camera pitched down 2 deg, heading north, at 20 Hz
    tp = BOOT0 + 0.05 * np.arange(110)
    lla = np.column_stack([LAT + speed * (tp - BOOT0) / 6.36e6, np.full(110, LON), np.full(110, 30.0)])
    c_ne = dcm_ecef_to_ned(lla[:, 0], lla[:, 1])
    p = np.radians(-2.0)
    c_nc = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    c_ec = np.swapaxes(c_ne, 1, 2) @ c_nc
    save(seg / "global_pose/frame_times", tp)
    save(seg / "global_pose/frame_gps_times", np.column_stack([np.full(110, WEEK), tp + OFFSET]))
    save(seg / "global_pose/frame_positions", lla_to_ecef(lla))
    save(seg / "global_pose/frame_velocities", np.swapaxes(c_ne, 1, 2) @ np.array([speed, 0.0, 0.0]))
    save(seg / "global_pose/frame_orientations", dcm_to_quat(c_ec))
    return seg


def test_synthetic_segment_on_boot_time(tmp_path):
    seg = make_segment(tmp_path)
    s = cm.read_comma_segment(seg)
    assert s.clock.week == WEEK and s.clock.offset == pytest.approx(OFFSET, abs=1e-6)
    # IMU: N stamps -> N - 1 trapezoid increments, rates and forces as written
    assert len(s.imu) == 599 and s.imu.time[0] == pytest.approx(BOOT0 + 0.01)
    np.testing.assert_allclose(s.imu.dtheta[:, 1] / s.imu.dt, -0.02, rtol=1e-9)
    np.testing.assert_allclose(s.imu.dvel[:, 2] / s.imu.dt, -9.8, rtol=1e-9)
    # GNSS at the fix's UTC time, not at the log time 0.2 s later; degrees -> radians
    np.testing.assert_allclose(s.gnss.time, BOOT0 + 0.1 + 0.1 * np.arange(55), atol=1e-6)
    assert s.gnss.lla[0, 1] == pytest.approx(LON, abs=1e-12) and s.gnss.lla[0, 2] == 30.0
    np.testing.assert_allclose(s.gnss.pos_sigma, np.tile([2.5, 2.5, 5.0], (55, 1)))
    log = cm.read_comma_gnss(seg, fix_time="log")
    np.testing.assert_allclose(log.time - s.gnss.time, 0.2, atol=1e-6)
    # odometer: rear wheels (10 - 0.1 and 10 + 0.1) or the speed signal (mean of four)
    np.testing.assert_allclose(s.odometer.speed, 10.0, rtol=1e-12)
    np.testing.assert_allclose(cm.read_comma_odometer(seg, source="speed").speed, 10.05, rtol=1e-12)
    shifted = cm.read_comma_odometer(seg, time_offset=-0.08, sigma=0.3)
    np.testing.assert_allclose(shifted.time, s.odometer.time - 0.08)
    np.testing.assert_allclose(shifted.sigma, 0.3)
    # pose: NED velocity, camera attitude (pitch -2 deg, heading north), GPS times kept
    np.testing.assert_allclose(s.reference.v_n, np.tile([10.0, 0, 0], (110, 1)), atol=1e-9)
    np.testing.assert_allclose(np.degrees(s.reference.rpy), np.tile([0, -2.0, 0], (110, 1)), atol=1e-9)
    np.testing.assert_allclose(s.reference.lla[:, 2], 30.0, atol=1e-6)
    assert s.reference.extra["point"] == "camera"
    np.testing.assert_allclose(s.clock.gps_to_boot(s.reference.extra["gps_week"], s.reference.extra["gps_tow"]),
                               s.reference.time, atol=1e-6)


def test_gyro_on_other_stamps_is_interpolated_onto_the_accelerometer(tmp_path):
    seg = make_segment(tmp_path, gyro_shift=0.004)
    imu = cm.read_comma_imu(seg)
    # gyro x = 0.01 (t - BOOT0) is linear: interpolation is exact; the first accel stamp precedes the gyro: dropped
    assert imu.time[0] == pytest.approx(BOOT0 + 0.02)
    mid = imu.time - imu.dt / 2
    np.testing.assert_allclose(imu.dtheta[:, 0] / imu.dt, 0.01 * (mid - BOOT0), rtol=1e-9)
    assert len(imu) == 598


@pytest.mark.parametrize("edit, file, line, pattern", [
    (lambda s: (s / "processed_log/IMU/gyro/t").unlink(), "processed_log/IMU/gyro/t", None, "does not exist"),
    (lambda s: save(s / "processed_log/CAN/wheel_speed/value", np.ones((480, 3))),
     "processed_log/CAN/wheel_speed/value", None, r"expected shape \(N, 4\), got \(480, 3\)"),
    (lambda s: save(s / "processed_log/CAN/wheel_speed/value", np.where(np.arange(480)[:, None] == 9, np.nan, 5.0)
                    * np.ones((1, 4))), "processed_log/CAN/wheel_speed/value", 10, r"non-finite value .* row 10"),
    (lambda s: save(s / "processed_log/CAN/wheel_speed/value", np.where(np.arange(480)[:, None] == 4, -1.0, 5.0)
                    * np.ones((1, 4))), "processed_log/CAN/wheel_speed/value", 5, r"speed -1 m/s in row 5"),
    (lambda s: save(s / "processed_log/CAN/wheel_speed/value", np.full((480, 4), 30.0 * 3.6)),
     "processed_log/CAN/wheel_speed/value", 1, r"above 100 m/s"),
    (lambda s: save(s / "processed_log/CAN/wheel_speed/t", BOOT0 + 0.0125 * np.r_[0:7, 5, 8:480]),
     "processed_log/CAN/wheel_speed/t", 8, r"CAN wheel speeds time goes backwards"),
    (lambda s: save(s / "processed_log/CAN/wheel_speed/t", BOOT0 + 0.0125 * np.r_[0:480] + 0.5 * (np.r_[0:480] >= 100)),
     "processed_log/CAN/wheel_speed/t", 101, r"1 gap\(s\) longer than 0.1 s"),
])
def test_bad_segment_names_file_and_row(tmp_path, edit, file, line, pattern):
    seg = make_segment(tmp_path)
    edit(seg)
    with pytest.raises(DataError) as ei:
        cm.read_comma_odometer(seg, gap_action="fail") if "CAN" in file else cm.read_comma_imu(seg)
    assert ei.value.file == str(seg / file)
    assert ei.value.line == line, str(ei.value)
    assert re.search(pattern, str(ei.value)), str(ei.value)


def test_can_gaps_accepted_are_counted(tmp_path):
    seg = make_segment(tmp_path)
    assert cm.read_comma_odometer(seg).gaps == 0
    save(seg / "processed_log/CAN/wheel_speed/t", BOOT0 + 0.0125 * np.r_[0:480] + 0.5 * (np.r_[0:480] >= 100))
    with pytest.warns(UserWarning, match=r"1 gap\(s\) longer than 0.1 s"):
        assert cm.read_comma_odometer(seg).gaps == 1


def test_bad_clock_and_leap_seconds(tmp_path):
    seg = make_segment(tmp_path)
    g = np.load(seg / "global_pose/frame_gps_times")
    g[50:, 1] += 0.01                                   # GPS and boot time drift apart by 10 ms
    save(seg / "global_pose/frame_gps_times", g)
    with pytest.raises(DataError, match=r"varies by 0.01 s"):
        cm.read_comma_clock(seg)
    seg = make_segment(tmp_path / "b")
    clock = cm.read_comma_clock(seg)
    wrong = cm.CommaClock(clock.week, clock.offset, leap_seconds=0)   # UTC taken for GPS: 18 s off
    with pytest.raises(DataError, match=r"logged 18.200 s after their UTC time"):
        cm.read_comma_gnss(seg, clock=wrong)


@pytest.mark.parametrize("call, argument", [
    (lambda s: cm.read_comma_odometer(s, source="front_wheels"), "source"),
    (lambda s: cm.read_comma_odometer(s, sigma=0), "sigma"),
    (lambda s: cm.read_comma_odometer(s, time_offset=float("nan")), "time_offset"),
    (lambda s: cm.read_comma_odometer(s, gap_action="skip"), "gap_action"),
    (lambda s: cm.read_comma_imu(s, gyro="raw"), "gyro"),
    (lambda s: cm.read_comma_imu(s, max_gap=0), "max_gap"),
    (lambda s: cm.read_comma_gnss(s, pos_sigma=(1, 2)), "pos_sigma"),
    (lambda s: cm.read_comma_gnss(s, vel_sigma=-0.1), "vel_sigma"),
    (lambda s: cm.read_comma_gnss(s, fix_time="gps"), "fix_time"),
])
def test_comma_bad_arguments(tmp_path, call, argument):
    with pytest.raises(ArgumentError) as ei:
        call(make_segment(tmp_path))
    assert ei.value.argument == argument


def test_gnss_velocity_from_speed_and_bearing(tmp_path):
    seg = make_segment(tmp_path)
    v = np.load(seg / "processed_log/GNSS/live_gnss_ublox/value")
    v[:, 5] = 90.0                                           # due east
    save(seg / "processed_log/GNSS/live_gnss_ublox/value", v)
    fx = cm.read_comma_gnss(seg, pos_sigma=3.0, vel_sigma=(0.1, 0.1, 0.5))
    np.testing.assert_allclose(fx.vel_n, np.tile([0.0, 10.0, 0.0], (55, 1)), atol=1e-12)
    np.testing.assert_allclose(fx.vel_sigma[0], [0.1, 0.1, 0.5])
    np.testing.assert_allclose(fx.pos_sigma[0], [3.0, 3.0, 3.0])


# ===========================================================================
# 4. comma2k19: the example segment (skips without the data)
# ===========================================================================
@pytest.fixture(scope="module")
def comma():
    seg = data_file("comma2k19-example1", "global_pose", "frame_times").parents[1]
    return cm.read_comma_segment(seg, gnss_vel_sigma=(0.1, 0.1, 0.5)), seg


def robust(d):
    """Median |d| and 1.4826 MAD about the median."""
    return float(np.median(np.abs(d))), float(1.4826 * np.median(np.abs(d - np.median(d))))


def test_real_imu_rate_gravity_and_axes(comma):
    s, _ = comma
    imu = s.imu
    assert len(imu) > 6000 and imu.gaps == 0
    assert 100.0 < 1.0 / np.median(imu.dt) < 108.0                     # ~104 Hz
    assert np.all(np.diff(imu.time) > 0)
    f = imu.dvel / imu.dt[:, None]
    g = np.linalg.norm(f.mean(axis=0))
    assert 9.5 < g < 10.1, g                                            # 9.68 m/s^2
    assert f[:, 2].mean() < -9.0                                        # z is down: specific force is up
    # gyro z (down) turns like the pose's yaw: the axes are forward-right-down
    yaw_rate = np.gradient(np.unwrap(s.reference.rpy[:, 2]), s.reference.time)
    wz = np.interp(s.reference.time, imu.time - imu.dt / 2, imu.dtheta[:, 2] / imu.dt)
    assert np.corrcoef(wz[5:-5], yaw_rate[5:-5])[0, 1] > 0.8
    # the forward accelerometer follows the change of the wheel speed (x is forward)
    o = s.odometer
    dv = np.gradient(np.interp(imu.time, o.time, o.speed), imu.time)
    k = np.ones(51) / 51
    assert np.corrcoef(np.convolve(f[:, 0], k, "same")[60:-60], np.convolve(dv, k, "same")[60:-60])[0, 1] > 0.7


def test_real_one_time_axis(comma):
    s, seg = comma
    lo, hi = s.imu.start_time, s.imu.time[-1]
    for name, t in (("gnss", s.gnss.time), ("odometer", s.odometer.time), ("pose", s.reference.time)):
        assert np.all(np.diff(t) > 0), name
        # boot time everywhere: within the IMU span, give or take the GNSS latency of the segment cut
        assert lo - 0.25 < t[0] and t[-1] < hi + 0.1, (name, t[0] - lo, t[-1] - hi)
    assert np.sum(s.gnss.time < lo) <= 2                               # fixes valid just before the cut
    # the clock: comma's frame GPS times are one offset from boot time; leap seconds 18 in 2018
    assert s.clock.week == 2012 and s.clock.leap_seconds == 18
    assert s.clock.offset == pytest.approx(357697.8495, abs=1e-3)
    # the fixes are logged 0.18-0.25 s after their UTC time
    late = np.load(seg / "processed_log/GNSS/live_gnss_ublox/t") - s.gnss.time
    assert 0.15 < late.min() and late.max() < 0.26 and 0.19 < np.median(late) < 0.22


def test_real_odometer_agrees_with_gnss_speed(comma):
    s, _ = comma
    gspeed = np.linalg.norm(s.gnss.vel_n[:, :2], axis=1)
    inside = (s.gnss.time > s.odometer.time[0]) & (s.gnss.time < s.odometer.time[-1])
    vg = gspeed[inside]
    vo = np.interp(s.gnss.time[inside], s.odometer.time, s.odometer.speed)
    med, sig = robust(vg - vo)
    assert med < 0.25 and sig < 0.12, (med, sig)                       # 0.17, 0.076 m/s
    k = np.sum(vo * vg) / np.sum(vo * vo)                              # odometer scale factor vs GNSS
    assert 1.005 < k < 1.015, k                                        # 1.0099: the wheels read 1 % slow
    med, sig = robust(vg - k * vo)
    assert med < 0.08 and sig < 0.12, (med, sig)                       # 0.052, 0.080 m/s


def test_real_pose_speed_agrees_with_can_speed(comma):
    s, seg = comma
    can = cm.read_comma_odometer(seg, source="speed")
    pose_speed = np.linalg.norm(s.reference.v_n, axis=1)
    d = pose_speed - np.interp(s.reference.time, can.time, can.speed)
    med, sig = robust(d)
    assert med < 0.25 and sig < 0.08, (med, sig)                       # 0.151, 0.048 m/s
    assert abs(np.median(pose_speed / np.interp(s.reference.time, can.time, can.speed)) - 1.0087) < 0.003
    # the camera looks along the road: small roll and pitch, yaw near the course over ground
    rpy = np.degrees(s.reference.rpy)
    course = np.degrees(np.arctan2(s.reference.v_n[:, 1], s.reference.v_n[:, 0]))
    assert np.abs(rpy[:, :2]).max() < 8.0                               # 6.2 deg pitch at most
    assert np.abs(rpy[:, 2] - course).max() < 3.0


def test_real_gnss_positions_near_the_pose(comma):
    s, _ = comma
    p = s.reference
    inside = (s.gnss.time > p.time[0]) & (s.gnss.time < p.time[-1])
    ref = np.column_stack([np.interp(s.gnss.time[inside], p.time, p.lla[:, i]) for i in range(3)])
    d = np.array([lla_to_ned(x, r) for x, r in zip(s.gnss.lla[inside], ref)])
    assert np.median(np.hypot(d[:, 0], d[:, 1])) < 4.0                 # 2.2 m, along track
    assert abs(np.median(d[:, 2])) < 3.0                               # ellipsoidal height (MSL would be 32 m off)
