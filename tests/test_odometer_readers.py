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

from mixnav.data import MAX_VEHICLE_SPEED, OdometerData
from mixnav.errors import ArgumentError, DataError
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
    assert len(od) == N - 1
    assert np.diff(od.time).max() == pytest.approx(0.2)
    read_odometer_csv(p, sigma=0.1, max_gap=0.25, gap_action="fail")   # within the limit: silent


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
