"""Nominal constellation: Kepler's laws, velocity as the derivative, visibility."""

import numpy as np
import pytest

from mixnav.geodesy.frames import lla_to_ecef
from mixnav.gnss.constellation import NominalConstellation
from mixnav.gnss.geometry import GM_GPS, OMEGA_E_GPS, above_mask


@pytest.fixture(scope="module")
def gps():
    return NominalConstellation.gps()


def test_orbits_are_circular_with_the_gps_period(gps):
    period = 2 * np.pi / gps.mean_motion
    # half a sidereal day: 11 h 58 min
    assert period == pytest.approx(86164.0905 / 2, rel=2e-4)
    for t in (0.0, 1234.5, period / 3):
        s = gps.states(t)
        np.testing.assert_allclose(np.linalg.norm(s.pos_ecef, axis=1), gps.semi_major_axis, rtol=1e-14)
        # inertial speed sqrt(GM/a): add back the frame's rotation
        v_i = s.vel_ecef + np.cross([0, 0, OMEGA_E_GPS], s.pos_ecef)
        np.testing.assert_allclose(np.linalg.norm(v_i, axis=1), np.sqrt(GM_GPS / gps.semi_major_axis),
                                   rtol=1e-12)
    # after one period each satellite is back in inertial space: ECEF turned by w_e T
    p0, p1 = gps.states(0.0).pos_ecef, gps.states(period).pos_ecef
    a = OMEGA_E_GPS * period
    R = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])
    np.testing.assert_allclose(p1, p0 @ R.T, atol=1e-6)


def test_velocity_is_the_derivative_of_position(gps):
    t, h = 5000.0, 0.01
    fd = (gps.states(t + h).pos_ecef - gps.states(t - h).pos_ecef) / (2 * h)
    np.testing.assert_allclose(gps.states(t).vel_ecef, fd, atol=1e-6)


def test_inclination_and_plane_spacing(gps):
    s = gps.states(0.0)
    # highest latitude reached is the inclination: |z| <= a sin(i), attained at u = 90 deg
    assert np.max(np.abs(s.pos_ecef[:, 2])) == pytest.approx(gps.semi_major_axis * np.sin(np.radians(55)),
                                                             rel=1e-12)
    assert len(np.unique(np.round(np.degrees(gps.raan) % 360, 6))) == 6


@pytest.mark.parametrize("k, lo, hi", [(4, 6, 8), (5, 7, 11)])
def test_mid_latitude_receiver_sees_enough_satellites(k, lo, hi):
    # The fraction of a GPS orbit shell above a 10 deg mask is about 0.3 at mid latitude,
    # so 24 satellites show ~7 and 30 show ~9; every epoch of a day stays in [lo, hi].
    sats = NominalConstellation.gps(k)
    rx = lla_to_ecef(np.array([np.radians(34.4), np.radians(113.5), 100.0]))
    counts = np.array([int(above_mask(rx, sats.states(t).pos_ecef, np.radians(10)).sum())
                       for t in np.arange(0, 86400, 300)])
    assert lo <= counts.min() and counts.max() <= hi
    assert np.mean(counts) == pytest.approx(0.3 * 6 * k, rel=0.15)


def test_fewer_than_24_satellites_is_refused():
    with pytest.raises(ValueError, match="at least 4"):
        NominalConstellation.gps(3)
