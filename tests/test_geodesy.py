"""Earth model and frames: closed forms, known values, round trips."""

import numpy as np

from mixnav.geodesy import earth
from mixnav.geodesy.frames import (dcm_ecef_to_ned, ecef_to_lla, lla_to_ecef, lla_to_ned,
                                   ned_displacement, ned_to_lla)


def test_radii_at_equator_and_pole():
    rm, rn = earth.radii(np.array([0.0, np.pi / 2]))
    b = earth.A_WGS84 * (1 - earth.F_WGS84)
    # Closed forms: Rn(0) = a, Rm(0) = b^2/a, Rm(90) = Rn(90) = a^2/b.
    np.testing.assert_allclose(rn, [earth.A_WGS84, earth.A_WGS84 ** 2 / b], rtol=1e-14)
    np.testing.assert_allclose(rm, [b ** 2 / earth.A_WGS84, earth.A_WGS84 ** 2 / b], rtol=1e-14)


def test_normal_gravity_known_values():
    # WGS-84 normal gravity: 9.7803253359 at the equator, 9.8321849378 at the poles.
    g = earth.normal_gravity(np.array([0.0, np.pi / 2]), 0.0)
    np.testing.assert_allclose(g, [9.7803253359, 9.8321849378], atol=1e-7)
    # free-air gradient about 3.086e-6 s^-2
    assert abs(earth.normal_gravity_dh(0.6, 0.0) + 3.086e-6) < 5e-9
    h = 500.0
    fd = (earth.normal_gravity(0.6, h + 1) - earth.normal_gravity(0.6, h - 1)) / 2
    np.testing.assert_allclose(earth.normal_gravity_dh(0.6, h), fd, rtol=1e-9)


def test_ecef_known_points():
    np.testing.assert_allclose(lla_to_ecef([0.0, 0.0, 0.0]), [earth.A_WGS84, 0, 0], atol=1e-9)
    b = earth.A_WGS84 * (1 - earth.F_WGS84)
    np.testing.assert_allclose(lla_to_ecef([np.pi / 2, 0.3, 100.0]), [0, 0, b + 100.0], atol=1e-8)


def test_ecef_round_trip(rng):
    lla = np.column_stack([rng.uniform(-1.55, 1.55, 1000), rng.uniform(-np.pi, np.pi, 1000),
                           rng.uniform(-500, 30_000_000, 1000)])
    back = ecef_to_lla(lla_to_ecef(lla))
    np.testing.assert_allclose(back[:, :2], lla[:, :2], atol=1e-13)
    np.testing.assert_allclose(back[:, 2], lla[:, 2], atol=1e-6)


def test_ned_frame_is_orthonormal_and_down_is_minus_normal(rng):
    lat, lon = rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)
    c = dcm_ecef_to_ned(lat, lon)
    np.testing.assert_allclose(c @ np.swapaxes(c, -1, -2), np.broadcast_to(np.eye(3), c.shape), atol=1e-15)
    # "up" = ellipsoid normal: moving 1 m up changes ECEF by -C_en[2]
    p0 = lla_to_ecef(np.column_stack([lat, lon, np.zeros(50)]))
    p1 = lla_to_ecef(np.column_stack([lat, lon, np.ones(50)]))
    np.testing.assert_allclose(p1 - p0, -c[:, 2, :], atol=1e-8)


def test_ned_round_trip_and_small_displacement():
    ref = np.array([0.6, 2.0, 120.0])
    p = np.array([120.0, -340.0, 15.0])
    np.testing.assert_allclose(lla_to_ned(ned_to_lla(p, ref), ref), p, atol=1e-7)
    # the curvilinear displacement agrees with the exact one for small offsets
    d = np.array([3.0, -2.0, 1.0])
    np.testing.assert_allclose(ned_displacement(ned_to_lla(d, ref), ref), d, atol=1e-5)


def test_displace_inverts_ned_displacement(rng):
    from mixnav.geodesy.frames import displace
    lla = np.column_stack([rng.uniform(-1.4, 1.4, 100), rng.uniform(-3, 3, 100), rng.uniform(-100, 5000, 100)])
    d = rng.normal(scale=50.0, size=(100, 3))
    np.testing.assert_allclose(ned_displacement(displace(lla, d), lla), d, atol=1e-9)
