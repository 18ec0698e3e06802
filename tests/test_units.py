"""mixnav.units: hand-computed conversions, round trips and errors that say what is wrong."""

import math
import re
import zlib

import numpy as np
import pytest

from mixnav import units as u
from mixnav.units import UnitError

D = math.pi / 180  # written out here rather than u.DEG: the tests check the module
G = 9.80665


# ---------------------------------------------------------------- constants
def test_constants():
    assert u.DEG == math.pi / 180
    assert u.ARCMIN == pytest.approx(math.pi / 180 / 60, rel=1e-15)
    assert u.ARCSEC == pytest.approx(math.pi / 180 / 3600, rel=1e-15)
    assert u.G0 == 9.80665
    assert u.HOUR == 3600.0


def test_named_dimensions_have_the_documented_exponents():
    assert u.DIMENSIONLESS == (0, 0, 0)
    assert u.ANGLE == (1, 0, 0)
    assert u.LENGTH == (0, 1, 0)
    assert u.TIME == (0, 0, 1)
    assert u.FREQUENCY == (0, 0, -1)
    assert u.ANGULAR_RATE == (1, 0, -1)
    assert u.ANGLE_RANDOM_WALK == (1, 0, -0.5)
    assert u.VELOCITY == (0, 1, -1)
    assert u.ACCELERATION == (0, 1, -2)
    assert u.VELOCITY_RANDOM_WALK == (0, 1, -1.5)
    assert u.GYRO_BIAS_DRIFT == (1, 0, -1.5)
    assert u.ACCEL_BIAS_DRIFT == (0, 1, -2.5)
    assert all(isinstance(e, float) for e in u.ANGLE_RANDOM_WALK)


# -------------------------------------------------------------- conversions
@pytest.mark.parametrize("text,dim,si", [
    # the datasheet values the brief asks for, against hand-computed SI
    ("2 deg/h", u.ANGULAR_RATE, 2 * D / 3600),
    ("0.1 deg/sqrt(h)", u.ANGLE_RANDOM_WALK, 0.1 * D / 60),
    ("0.0038 deg/s/sqrt(Hz)", u.ANGLE_RANDOM_WALK, 0.0038 * D),
    ("30 ug/sqrt(Hz)", u.VELOCITY_RANDOM_WALK, 30e-6 * G),
    ("0.1 m/s/sqrt(h)", u.VELOCITY_RANDOM_WALK, 0.1 / 60),
    ("300 ppm", u.DIMENSIONLESS, 3e-4),
    ("0.3 %", u.DIMENSIONLESS, 3e-3),
    ("0.1 mg", u.ACCELERATION, 0.1e-3 * G),
    ("20 arcsec", u.ANGLE, 20 * D / 3600),
    ("0.2 arcmin", u.ANGLE, 0.2 * D / 60),
    ("3.8e-5 deg/s^2/sqrt(Hz)", u.GYRO_BIAS_DRIFT, 3.8e-5 * D),
    ("0.01 deg/h/sqrt(h)", u.GYRO_BIAS_DRIFT, 0.01 * D / 3600 / 60),
    ("7 ug/s/sqrt(Hz)", u.ACCEL_BIAS_DRIFT, 7e-6 * G),
    ("2e-4 m/s^3/sqrt(Hz)", u.ACCEL_BIAS_DRIFT, 2e-4),
    ("100 Hz", u.FREQUENCY, 100.0),
    ("10 ms", u.TIME, 0.01),
    ("1.5 km", u.LENGTH, 1500.0),
    ("36 km/h", u.VELOCITY, 10.0),
    # signs, scientific notation, spacing
    ("-1.5e-3 m/s^2", u.ACCELERATION, -1.5e-3),
    ("+2 deg", u.ANGLE, 2 * D),
    (".5 deg", u.ANGLE, 0.5 * D),
    ("1E3 m", u.LENGTH, 1000.0),
    ("30ug/sqrt(Hz)", u.VELOCITY_RANDOM_WALK, 30e-6 * G),
    ("2 deg / h", u.ANGULAR_RATE, 2 * D / 3600),
    ("  2   deg / sqrt ( h )  ", u.ANGLE_RANDOM_WALK, 2 * D / 60),
    # every base unit at least once
    ("1 rad", u.ANGLE, 1.0),
    ("1 mrad", u.ANGLE, 1e-3),
    ("1 urad", u.ANGLE, 1e-6),
    ("90°", u.ANGLE, math.pi / 2),
    ("1 cm", u.LENGTH, 0.01),
    ("1 mm", u.LENGTH, 0.001),
    ("1 ft", u.LENGTH, 0.3048),
    ("1 s", u.TIME, 1.0),
    ("5 us", u.TIME, 5e-6),
    ("2 min", u.TIME, 120.0),
    ("1 h", u.TIME, 3600.0),
    ("1 hr", u.TIME, 3600.0),
    ("1 day", u.TIME, 86400.0),
    ("1 g", u.ACCELERATION, G),          # standard gravity, not gram
    ("1 µg", u.ACCELERATION, 1e-6 * G),  # U+00B5 micro sign
    ("1 μg", u.ACCELERATION, 1e-6 * G),  # U+03BC Greek mu
    ("1 Gal", u.ACCELERATION, 0.01),
    ("1 mGal", u.ACCELERATION, 1e-5),
    # powers, products, grouping
    ("2 deg/hr", u.ANGULAR_RATE, 2 * D / 3600),
    ("1 m*s^-2", u.ACCELERATION, 1.0),
    ("1 m/s^2", u.ACCELERATION, 1.0),
    ("1 m/(s*s)", u.ACCELERATION, 1.0),
    ("1 m*Hz^2", u.ACCELERATION, 1.0),
    ("1 deg/h^0.5", u.ANGLE_RANDOM_WALK, D / 60),
    ("1 deg*h^-0.5", u.ANGLE_RANDOM_WALK, D / 60),
    ("1 deg*h^(-1/2)", u.ANGLE_RANDOM_WALK, D / 60),
    ("1 deg/sqrt(h)", u.ANGLE_RANDOM_WALK, D / 60),
    ("1 sqrt(deg^2/h)", u.ANGLE_RANDOM_WALK, D / 60),
    ("1 deg/s*h", u.ANGLE, 3600 * D),    # left to right: (deg/s)*h
    ("1 m/s/s", u.ACCELERATION, 1.0),
    ("50 %/h", u.FREQUENCY, 0.5 / 3600),
])
def test_conversions_match_hand_computed_si(text, dim, si):
    assert u.parse_quantity(text, dim) == pytest.approx(si, rel=1e-13, abs=0.0)


def test_returns_a_python_float():
    assert type(u.parse_quantity("2 deg/h", u.ANGULAR_RATE)) is float


def test_datasheet_forms_of_one_dimension_agree():
    # deg/s/sqrt(Hz) and deg/sqrt(h) are both angle random walk: 1 deg/sqrt(h) = 1/60 deg/s/sqrt(Hz)
    a = u.parse_quantity("1 deg/sqrt(h)", u.ANGLE_RANDOM_WALK)
    b = u.parse_quantity(f"{1 / 60!r} deg/s/sqrt(Hz)", u.ANGLE_RANDOM_WALK)
    assert a == pytest.approx(b, rel=1e-14)
    # ug/sqrt(Hz) is velocity random walk, NOT accelerometer bias drift
    assert u.parse_unit("ug/sqrt(Hz)")[1] == u.VELOCITY_RANDOM_WALK
    assert u.parse_unit("ug/s/sqrt(Hz)")[1] == u.ACCEL_BIAS_DRIFT
    assert u.parse_unit("deg/h/sqrt(h)")[1] == u.GYRO_BIAS_DRIFT
    assert u.parse_unit("deg/s^2/sqrt(Hz)")[1] == u.GYRO_BIAS_DRIFT


@pytest.mark.parametrize("text,si", [("0.5", 0.5), ("300 ppm", 3e-4), ("-1e-3", -1e-3)])
def test_dimensionless_may_omit_the_unit(text, si):
    assert u.parse_quantity(text, u.DIMENSIONLESS) == pytest.approx(si, rel=1e-15)


@pytest.mark.parametrize("value", [0.5, 2, np.float64(0.25), np.int64(3)])
def test_dimensionless_accepts_plain_numbers(value):
    assert u.parse_quantity(value, u.DIMENSIONLESS) == float(value)


# ---------------------------------------------------------------- parse_unit
@pytest.mark.parametrize("unit,factor,dim", [
    ("deg/sqrt(h)", D / 60, u.ANGLE_RANDOM_WALK),
    ("deg/s/sqrt(Hz)", D, u.ANGLE_RANDOM_WALK),
    ("ug/sqrt(Hz)", 1e-6 * G, u.VELOCITY_RANDOM_WALK),
    ("Hz", 1.0, u.FREQUENCY),
    ("", 1.0, u.DIMENSIONLESS),
    ("ppm", 1e-6, u.DIMENSIONLESS),
])
def test_parse_unit(unit, factor, dim):
    f, d = u.parse_unit(unit)
    assert f == pytest.approx(factor, rel=1e-14)
    assert isinstance(d, u.Dimension) and d.matches(dim)


def test_parse_unit_is_cached():
    assert u.parse_unit("deg/h/sqrt(h)") is u.parse_unit("deg/h/sqrt(h)")


def test_dimension_comparison_tolerates_float_rounding():
    # ^0.3333... three times is not exactly 1.0 in floats, yet is length
    f, d = u.parse_unit("m^0.3333333333333333*m^0.3333333333333333*m^0.3333333333333333")
    assert d.matches(u.LENGTH)
    assert u.parse_quantity("2 m^0.3333333333333333*m^0.3333333333333333*m^0.3333333333333333",
                            u.LENGTH) == pytest.approx(2.0)
    assert not u.Dimension(1.0, 0.0, -0.5 + 1e-6).matches(u.ANGLE_RANDOM_WALK)


@pytest.mark.parametrize("dim,words", [
    (u.DIMENSIONLESS, "dimensionless"),
    (u.ANGULAR_RATE, "angle/time"),
    (u.ANGLE_RANDOM_WALK, "angle/time^0.5"),
    (u.FREQUENCY, "1/time"),
    (u.ACCEL_BIAS_DRIFT, "length/time^2.5"),
    (u.Dimension(1.0, 1.0, 0.0), "angle*length"),
])
def test_dimension_words(dim, words):
    assert dim.words() == words


def test_accepted_spellings_in_messages_all_parse():
    # the spellings offered in error messages must themselves be valid
    for dim, _, spellings in u._NAMED:
        for unit in spellings:
            assert u.parse_unit(unit)[1].matches(dim), unit


# ----------------------------------------------------------------- to_unit
ROUND_TRIP_UNITS = [
    ("deg/h", u.ANGULAR_RATE), ("deg/s", u.ANGULAR_RATE), ("rad/s", u.ANGULAR_RATE),
    ("deg/sqrt(h)", u.ANGLE_RANDOM_WALK), ("deg/s/sqrt(Hz)", u.ANGLE_RANDOM_WALK),
    ("ug/sqrt(Hz)", u.VELOCITY_RANDOM_WALK), ("m/s/sqrt(h)", u.VELOCITY_RANDOM_WALK),
    ("deg/h/sqrt(h)", u.GYRO_BIAS_DRIFT), ("deg/s^2/sqrt(Hz)", u.GYRO_BIAS_DRIFT),
    ("ug/s/sqrt(Hz)", u.ACCEL_BIAS_DRIFT), ("m/s^3/sqrt(Hz)", u.ACCEL_BIAS_DRIFT),
    ("ppm", u.DIMENSIONLESS), ("%", u.DIMENSIONLESS),
    ("arcsec", u.ANGLE), ("arcmin", u.ANGLE), ("deg", u.ANGLE), ("mrad", u.ANGLE),
    ("mg", u.ACCELERATION), ("ug", u.ACCELERATION), ("g", u.ACCELERATION), ("mGal", u.ACCELERATION),
    ("km", u.LENGTH), ("ft", u.LENGTH), ("ms", u.TIME), ("h", u.TIME), ("day", u.TIME),
    ("Hz", u.FREQUENCY), ("km/h", u.VELOCITY),
]


@pytest.mark.parametrize("unit,dim", ROUND_TRIP_UNITS)
def test_round_trip(unit, dim):
    rng = np.random.default_rng(zlib.crc32(unit.encode()))  # hash() is salted per run
    # values across many decades and both signs, as repr so no digits are lost
    xs = rng.uniform(-1, 1, 25) * 10.0 ** rng.integers(-8, 8, 25)
    for x in xs:
        si = u.parse_quantity(f"{float(x)!r} {unit}", dim)
        assert u.to_unit(si, unit) == pytest.approx(x, rel=1e-13)


def test_to_unit_keeps_type_and_shape():
    assert isinstance(u.to_unit(1.0, "deg"), float)
    assert u.to_unit(math.pi, "deg") == pytest.approx(180.0, rel=1e-15)
    arr = np.array([[1.0, 2.0], [3.0, 4.0]]) * D / 3600
    out = u.to_unit(arr, "deg/h")
    assert isinstance(out, np.ndarray) and out.shape == (2, 2)
    np.testing.assert_allclose(out, [[1, 2], [3, 4]], rtol=1e-14)
    assert isinstance(u.to_unit([0.01, 0.02], "%"), np.ndarray)


def test_to_unit_checks_only_the_factor():
    # no dimension check: 1 deg (an angle) "in deg/h" is just D / (D/3600)
    assert u.to_unit(D, "deg/h") == pytest.approx(3600.0, rel=1e-14)


# ------------------------------------------------------------------ errors
def test_missing_unit_names_the_problem_and_shows_an_example():
    with pytest.raises(UnitError, match=r"'2' is missing its unit.*angular rate \(angle/time\).*'2 deg/h'"):
        u.parse_quantity("2", u.ANGULAR_RATE)


@pytest.mark.parametrize("value", [2, 2.0, np.float64(2.0)])
def test_bare_number_is_rejected_for_a_value_with_units(value):
    with pytest.raises(UnitError, match=r"a bare number .* is not allowed for a value with units.*'2 deg/h'"):
        u.parse_quantity(value, u.ANGULAR_RATE)


@pytest.mark.parametrize("value", [True, None, [2, "deg"]])
def test_non_text_non_number_is_rejected(value):
    with pytest.raises(UnitError, match=r"expected a quantity written as text, e\.g\. '2 deg/h'"):
        u.parse_quantity(value, u.ANGULAR_RATE)


def test_bool_is_not_a_dimensionless_number():
    with pytest.raises(UnitError, match="expected a quantity written as text"):
        u.parse_quantity(True, u.DIMENSIONLESS)


def test_unknown_unit_is_named_and_known_units_listed():
    with pytest.raises(UnitError, match=r"cannot read '2 furlong' as length: .*unknown unit 'furlong'; "
                                        r"known units: rad, .*ppm, %; accepted spellings include '2 m'"):
        u.parse_quantity("2 furlong", u.LENGTH)


def test_unknown_unit_suggests_a_spelling():
    with pytest.raises(UnitError, match=r"unknown unit 'hz' \(did you mean 'Hz'\?\)"):
        u.parse_quantity("100 hz", u.FREQUENCY)
    with pytest.raises(UnitError, match=r"unknown unit 'G' \(did you mean 'g'\?\)"):
        u.parse_quantity("1 G", u.ACCELERATION)


def test_parse_unit_error_lists_the_unknown_token():
    with pytest.raises(UnitError, match=r"cannot read unit 'deg/fortnight': unknown unit 'fortnight'"):
        u.parse_unit("deg/fortnight")


@pytest.mark.parametrize("text,dim,pattern", [
    ("2 deg//h", u.ANGULAR_RATE,
     r"cannot read '2 deg//h' as angular rate \(angle/time\).*expected a unit after '/' but found '/'"),
    ("2 deg/sqrt(h", u.ANGLE_RANDOM_WALK, r"missing '\)' to close 'sqrt\('"),
    ("2 deg/sqrt h", u.ANGLE_RANDOM_WALK, r"expected '\(' after 'sqrt'"),
    ("2 deg/h)", u.ANGULAR_RATE, r"unexpected '\)'"),
    ("2 deg h", u.ANGULAR_RATE, r"unexpected 'h'.*join units with '\*' or '/'"),
    ("2 m/s^", u.ACCELERATION, r"expected a number after '\^' but found the end"),
    ("2 m/s^x", u.ACCELERATION, r"expected a number after '\^' but found 'x'"),
    ("2 m/s^1.2.3", u.ACCELERATION, r"'1\.2\.3' .* is not a number"),
    ("2 m/", u.LENGTH, r"expected a unit after '/' but found the end"),
    ("2 m*", u.LENGTH, r"expected a unit after '\*'"),
    ("2 m,5", u.LENGTH, r"unexpected character ','"),
    ("2 5 m", u.LENGTH, r"expected a unit but found '5'"),
    ("2 s^(1/0)", u.TIME, r"exponent divides by zero"),
])
def test_bad_syntax_says_where(text, dim, pattern):
    with pytest.raises(UnitError, match=pattern) as exc:
        u.parse_quantity(text, dim)
    # every syntax error also offers accepted spellings for the expected dimension
    assert "accepted spellings include" in str(exc.value)


@pytest.mark.parametrize("text", ["deg/h", "", "   ", "- 2 deg/h", "e5 deg/h", "two deg/h"])
def test_no_number(text):
    with pytest.raises(UnitError, match=r"does not start with a number.*e\.g\. '2 deg/h'"):
        u.parse_quantity(text, u.ANGULAR_RATE)


@pytest.mark.parametrize("text,dim,got,want", [
    ("2 deg/h", u.ANGLE_RANDOM_WALK, "angular rate (angle/time)", "angle random walk (angle/time^0.5)"),
    ("30 ug/sqrt(Hz)", u.ACCEL_BIAS_DRIFT, "velocity random walk (length/time^1.5)",
     "accelerometer bias drift (length/time^2.5)"),
    ("2 m/s", u.ANGULAR_RATE, "velocity (length/time)", "angular rate (angle/time)"),
    ("300 ppm", u.ANGLE, "dimensionless", "angle"),
    ("1 deg", u.DIMENSIONLESS, "angle", "dimensionless"),
    ("2 deg/s", u.Dimension(1.0, 1.0, -1.0), "angular rate (angle/time)", "angle*length/time"),
])
def test_dimension_mismatch_names_both_dimensions(text, dim, got, want):
    with pytest.raises(UnitError, match=rf"'{re.escape(text)}' has dimension {re.escape(got)}, "
                                        rf"but {re.escape(want)} is expected; write e\.g\. "):
        u.parse_quantity(text, dim)


def test_mismatch_example_uses_the_given_number():
    with pytest.raises(UnitError, match=r"write e\.g\. '0\.1 deg/sqrt\(h\)'"):
        u.parse_quantity("0.1 deg/h", u.ANGLE_RANDOM_WALK)


def test_unnamed_dimension_example_is_valid_si():
    with pytest.raises(UnitError, match=r"write e\.g\. '2 rad\*m/s'"):
        u.parse_quantity("2 deg/s", u.Dimension(1.0, 1.0, -1.0))
    # and that spelling indeed parses to the dimension
    assert u.parse_unit("rad*m/s")[1].matches(u.Dimension(1.0, 1.0, -1.0))


@pytest.mark.parametrize("text", ["nan deg", "NaN deg", "inf m", "-inf m", "+Infinity m", "1e999 m"])
def test_non_finite_text_is_rejected(text):
    dim = u.ANGLE if "deg" in text else u.LENGTH
    with pytest.raises(UnitError, match=r"value must be a finite number, got '"):
        u.parse_quantity(text, dim)


@pytest.mark.parametrize("value", [float("nan"), float("inf"), "nan"])
def test_non_finite_dimensionless_is_rejected(value):
    with pytest.raises(UnitError, match=r"value must be a finite number"):
        u.parse_quantity(value, u.DIMENSIONLESS)


def test_unit_error_is_a_value_error():
    # so pydantic validators and callers catching ValueError see it
    assert issubclass(UnitError, ValueError)
    with pytest.raises(ValueError):
        u.parse_quantity("2", u.ANGULAR_RATE)


def test_parse_unit_rejects_non_text():
    with pytest.raises(UnitError, match=r"a unit must be text such as 'deg/h', got 3"):
        u.parse_unit(3)
