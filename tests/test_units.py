"""Units: hand-computed conversions, round trips and located errors."""

import math

import numpy as np
import pytest

from mixnav import units as u

D = math.pi / 180


@pytest.mark.parametrize("text,dim,si", [
    ("2 deg/h", u.ANGULAR_RATE, 2 * D / 3600),
    ("0.1 deg/sqrt(h)", u.ANGLE_RANDOM_WALK, 0.1 * D / 60),
    ("0.0038 deg/s/sqrt(Hz)", u.ANGLE_RANDOM_WALK, 0.0038 * D),
    ("30 ug/sqrt(Hz)", u.VELOCITY_RANDOM_WALK, 30e-6 * 9.80665),
    ("0.1 m/s/sqrt(h)", u.VELOCITY_RANDOM_WALK, 0.1 / 60),
    ("300 ppm", u.DIMENSIONLESS, 3e-4),
    ("0.3 %", u.DIMENSIONLESS, 3e-3),
    ("0.1 mg", u.ACCELERATION, 0.1e-3 * 9.80665),
    ("20 arcsec", u.ANGLE, 20 * D / 3600),
    ("0.2 arcmin", u.ANGLE, 0.2 * D / 60),
    ("3.8e-5 deg/s^2/sqrt(Hz)", u.GYRO_BIAS_DRIFT, 3.8e-5 * D),
    ("0.01 deg/h/sqrt(h)", u.GYRO_BIAS_DRIFT, 0.01 * D / 3600 / 60),
    ("7 ug/s/sqrt(Hz)", u.ACCEL_BIAS_DRIFT, 7e-6 * 9.80665),
    ("100 Hz", u.FREQUENCY, 100.0),
    ("10 ms", u.TIME, 0.01),
    ("1.5 km", u.LENGTH, 1500.0),
    ("36 km/h", u.VELOCITY, 10.0),
    ("-1.5e-3 m/s^2", u.ACCELERATION, -1.5e-3),
    ("30ug/sqrt(Hz)", u.VELOCITY_RANDOM_WALK, 30e-6 * 9.80665),
    ("2 deg / h", u.ANGULAR_RATE, 2 * D / 3600),
])
def test_conversions(text, dim, si):
    assert u.parse_quantity(text, dim) == pytest.approx(si, rel=1e-14)


@pytest.mark.parametrize("unit,dim", [("deg/h", u.ANGULAR_RATE), ("deg/sqrt(h)", u.ANGLE_RANDOM_WALK),
                                      ("ug/sqrt(Hz)", u.VELOCITY_RANDOM_WALK), ("ppm", u.DIMENSIONLESS),
                                      ("arcsec", u.ANGLE), ("mg", u.ACCELERATION)])
def test_round_trip(unit, dim, rng):
    for x in rng.uniform(-100, 100, 20):
        si = u.parse_quantity(f"{float(x)!r} {unit}", dim)
        assert u.to_unit(si, unit) == pytest.approx(x, rel=1e-12)
    arr = np.array([1.0, 2.0])
    np.testing.assert_allclose(u.to_unit(arr * u.parse_unit(unit)[0], unit), arr)


@pytest.mark.parametrize("value,dim,words", [
    ("2", u.ANGULAR_RATE, "no unit"),
    (2.0, u.ANGULAR_RATE, "bare number"),
    (True, u.DIMENSIONLESS, "quantity"),
    ("2 furlong", u.LENGTH, "unknown unit 'furlong'"),
    ("2 deg//h", u.ANGULAR_RATE, "unknown unit '/'"),
    ("deg/h", u.ANGULAR_RATE, "does not start with a number"),
    ("2 deg/sqrt(h", u.ANGLE_RANDOM_WALK, "ends too early"),
    ("2 deg/h", u.ANGLE_RANDOM_WALK, "angle/time, expected angle/time^0.5"),
    ("nan deg", u.ANGLE, "finite"),
    ("inf m", u.LENGTH, "finite"),
])
def test_errors_say_what_is_wrong(value, dim, words):
    with pytest.raises(u.UnitError) as exc:
        u.parse_quantity(value, dim)
    assert words in str(exc.value)


def test_dimensionless_accepts_plain_numbers():
    assert u.parse_quantity(0.5, u.DIMENSIONLESS) == 0.5
    assert u.parse_quantity("0.5", u.DIMENSIONLESS) == 0.5
