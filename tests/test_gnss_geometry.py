"""Line-of-sight geometry: closed forms for zenith, horizon and the Sagnac rotation."""

import numpy as np

from mixnav.geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from mixnav.gnss.geometry import (OMEGA_E_GPS, above_mask, earth_rotation_correction,
                                  elevation_azimuth)


def test_zenith_and_horizon_directions():
    lla = np.array([np.radians(37.4), np.radians(-122.1), 30.0])
    rx = lla_to_ecef(lla)
    C_ne = dcm_ecef_to_ned(lla[0], lla[1])
    # directions given in NED, turned to ECEF: up, north horizon, east at 30 deg elevation
    dirs_n = np.array([[0, 0, -1.0], [1.0, 0, 0],
                       [0, np.cos(np.radians(30)), -np.sin(np.radians(30))]])
    sats = rx + 2.0e7 * dirs_n @ C_ne  # C_en = C_ne.T
    el, az = elevation_azimuth(rx, sats)
    np.testing.assert_allclose(np.degrees(el), [90, 0, 30], atol=1e-9)
    np.testing.assert_allclose(np.degrees(az[1:]), [0, 90], atol=1e-9)
    assert list(above_mask(rx, sats, np.radians(10))) == [True, False, True]


def test_earth_rotation_is_a_rotation_about_z():
    p = np.array([[2.0e7, 1.0e7, 5.0e6]])
    tau = 0.075
    q = earth_rotation_correction(p, tau)
    a = OMEGA_E_GPS * tau
    # a point fixed in inertial space appears turned by -a in the later ECEF frame
    expect = np.array([p[0, 0] * np.cos(a) + p[0, 1] * np.sin(a),
                       -p[0, 0] * np.sin(a) + p[0, 1] * np.cos(a), p[0, 2]])
    np.testing.assert_allclose(q[0], expect, rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(q), np.linalg.norm(p), rtol=1e-15)
    rho = np.hypot(p[0, 0], p[0, 1])  # chord of the turn about z
    np.testing.assert_allclose(np.linalg.norm(q - p), 2 * rho * np.sin(a / 2), rtol=1e-9)
