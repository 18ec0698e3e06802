"""Scenario files: the shipped ones load; bad input names the file and the key."""

from pathlib import Path

import pytest

from mixnav.config import list_scenarios, load_scenario
from mixnav.errors import ConfigError
from mixnav.experiment.run import run_scenario

DEMO = Path(__file__).resolve().parents[1] / "src" / "mixnav" / "config" / "scenarios" / "loose-demo.toml"


def test_shipped_scenarios_load():
    names = list_scenarios()
    assert "loose-demo" in names
    for name in names:
        sc, src, text = load_scenario(name)
        assert sc.scenario.name == name
    sc, _, _ = load_scenario("loose-demo")
    assert sc.duration == pytest.approx(600.0)
    assert sc.imu.rate == 100.0
    assert sc.gnss.outages == [(300.0, 360.0)]


def _write(tmp_path, old, new):
    text = DEMO.read_text()
    assert old in text, old
    p = tmp_path / "bad.toml"
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize("old,new,key,words", [
    ('rate = "1 Hz"', 'rate = "1 Hz"\nrat = "2 Hz"', "gnss.rat", "unknown key"),
    ('rate = "1 Hz"', 'rate = 1', "gnss.rate", "bare number"),
    ('rate = "100 Hz"', 'rate = "100"', "imu.rate", "unit"),
    ('position_sigma = ["1.5 m", "1.5 m", "3 m"]', 'position_sigma = ["1.5 m", "-1.5 m", "3 m"]',
     "gnss.position_sigma", "positive"),
    ('grade = "mems"', 'grade = "mems"\nerrors = { arw = "-0.1 deg/sqrt(h)" }', "imu.errors.arw", "non-negative"),
    ('grade = "mems"', 'grade = "mems"\nerrors = { arw = "0.1 deg/h" }', "imu.errors.arw", "dimension"),
    ('grade = "mems"', 'grade = "mems"\nerrors = { gyro_bais = "1 deg/h" }', "imu.errors.gyro_bais", "unknown"),
    ('grade = "mems"', 'grade = "navy"', "imu.grade", "unknown IMU grade"),
    ('{ type = "turn",       duration = "9 s",  angle = "90 deg" }',
     '{ type = "turn",       duration = "9 s" }', "trajectory.segments[3]", "yaw_rate"),
    ('{ type = "uniform",    duration = "30 s" }', '{ type = "hover",    duration = "30 s" }',
     "trajectory.segments[2]", "type"),
    ('outages = [["300 s", "360 s"]]', 'outages = [["300 s", "260 s"]]', "gnss.outages", "before it starts"),
    ('states = 15', 'states = 16', "methods[0].states", "15"),
])
def test_bad_scenario_names_file_and_key(tmp_path, old, new, key, words):
    p = _write(tmp_path, old, new)
    with pytest.raises(ConfigError) as exc:
        load_scenario(str(p))
    msg = str(exc.value)
    assert str(p) in msg and key in msg and words.lower() in msg.lower(), msg


@pytest.mark.parametrize("old,new,key,words", [
    # speeds up to 15 m/s then a static segment: the vehicle cannot stop instantly
    ('{ type = "uniform",    duration = "30 s" }', '{ type = "static",     duration = "30 s" }',
     "trajectory.segments[2]", "at rest"),
    # a duration that is not a whole number of 100 Hz IMU intervals
    ('{ type = "uniform",    duration = "40 s" },\n  { type = "climb"',
     '{ type = "uniform",    duration = "40.005 s" },\n  { type = "climb"', "trajectory.segments[4].duration",
     "whole number"),
    # decelerating below zero speed
    ('{ type = "accelerate", duration = "15 s", acceleration = "-1 m/s^2" }',
     '{ type = "accelerate", duration = "25 s", acceleration = "-1 m/s^2" }', "trajectory.segments[21]",
     "negative"),
])
def test_segments_that_make_no_trajectory(tmp_path, old, new, key, words):
    p = _write(tmp_path, old, new)
    sc, src, _ = load_scenario(str(p))
    with pytest.raises(ConfigError) as exc:
        run_scenario(sc, src)
    msg = str(exc.value)
    assert str(p) in msg and key in msg and words in msg, msg


def test_unknown_scenario_lists_the_shipped_ones():
    with pytest.raises(ConfigError, match="loose-demo"):
        load_scenario("no-such-scenario")


def test_invalid_toml_names_the_file(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("[scenario\nname = 1")
    with pytest.raises(ConfigError, match="broken.toml"):
        load_scenario(str(p))
