"""Strapdown mechanization against independent truths.

* Round trip: the ideal increments of a simulated drive (computed from the
  motion itself, not by inverting the mechanization) fly the same drive.
* Schuler: a stationary INS with a tilt error oscillates with the period
  2 pi sqrt(R/g) and the closed-form amplitude R phi0 (1 - cos w t).
"""

import numpy as np
import pytest

from mixnav.attitude import attitude_error, quat_multiply, rotvec_to_quat
from mixnav.config import load_scenario
from mixnav.geodesy import earth
from mixnav.geodesy.frames import ned_displacement
from mixnav.ins._kernels import mechanize_block
from mixnav.ins.mechanization import free_inertial, nav_vector
from mixnav.sim.scenario import truth_and_ideal_imu
from mixnav.sim.trajectory import InitialState, MotionSegment, generate


def round_trip_errors(imu_rate=100.0):
    sc, src, _ = load_scenario("loose-demo")
    truth, imu = truth_and_ideal_imu(sc, src)
    sol = free_inertial(imu, nav_vector(truth.q_nb[0], truth.v_n[0], truth.lla[0]))
    dpos = ned_displacement(sol.lla, truth.lla)
    datt = attitude_error(sol.q_nb, truth.q_nb)
    return truth, dpos, datt, sol.v_n - truth.v_n


def test_error_free_drive_stays_on_truth():
    truth, dpos, datt, dvel = round_trip_errors()
    assert truth.time[-1] == pytest.approx(600.0) and len(truth.time) == 60001
    # Issue 2 requirement: below 0.1 m and 1e-5 rad after 600 s at 100 Hz.
    # Measured: 2.0 cm and 2.2e-8 rad (see benchmarks/results/accuracy.md).
    assert np.linalg.norm(dpos[-1]) < 0.1
    assert np.abs(datt).max() < 1e-5
    assert np.abs(dvel).max() < 1e-3


def _static_ins(lat, tilt, duration, rate=10.0, hold_height=True):
    """Stationary INS with an initial tilt; height held to the truth (perfect
    altimeter), because the free-inertial vertical channel diverges."""
    seg = [MotionSegment("static", duration)]
    truth, imu = generate(seg, InitialState((lat, 0.3, 0.0), 0.0, (0.0, 0.0, 0.0)), rate)
    q0 = quat_multiply(rotvec_to_quat(-np.asarray(tilt)), truth.q_nb[0])  # dx = true - est
    nav = nav_vector(q0, truth.v_n[0], truth.lla[0])
    prev = np.zeros(6)
    out = np.empty((len(imu), 10))
    block = int(rate)
    empty = np.empty((0, 10))
    for a in range(0, len(imu), block):
        b = min(a + block, len(imu))
        mechanize_block(nav, prev, imu.dtheta[a:b], imu.dvel[a:b], imu.dt[a:b], empty)
        if hold_height:
            nav[6], nav[9] = 0.0, truth.lla[b, 2]
        out[b - 1] = nav
    keep = np.arange(block - 1, len(imu), block)
    return truth.time[keep + 1], ned_displacement(truth.lla[keep + 1], out[keep, 7:10])


def test_schuler_period_and_amplitude_at_equator():
    # At the equator a tilt about north is untouched by Earth rate, so the
    # east error follows the Schuler closed form exactly:
    # dr_E(t) = -R phi0 (1 - cos(w_s t)),  w_s = sqrt(g / R),  R = Rn(0) = a.
    phi0 = 1e-4
    t, derr = _static_ins(0.0, [phi0, 0.0, 0.0], duration=2 * 5100.0)
    g = earth.normal_gravity(0.0, 0.0)
    w_s = np.sqrt(g / earth.A_WGS84)
    period_theory = 2 * np.pi / w_s
    assert period_theory / 60 == pytest.approx(84.4, abs=0.3)
    e = derr[:, 1]  # error = truth - estimate
    expected = earth.A_WGS84 * phi0 * (1 - np.cos(w_s * t))
    # the closed form neglects only second-order terms (phi0^2 ~ 1e-8)
    assert np.abs(np.abs(e) - expected).max() < 1e-3 * expected.max()
    # period from the zero crossings of the error's derivative (peaks and troughs)
    de = np.diff(e)
    ext = np.nonzero(np.sign(de[1:]) != np.sign(de[:-1]))[0]
    measured = 2 * np.mean(np.diff(t[ext + 1]))
    assert measured == pytest.approx(period_theory, rel=2e-3)


def test_schuler_magnitude_at_mid_latitude():
    # Away from the equator Foucault precession turns the error direction at
    # Omega sin(lat), but the horizontal magnitude keeps the Schuler law.
    lat = np.deg2rad(34.4)
    phi0 = 1e-4
    t, derr = _static_ins(lat, [phi0, 0.0, 0.0], duration=5100.0)
    rm, rn = earth.radii(lat)
    w_s = np.sqrt(earth.normal_gravity(lat, 0.0) / np.sqrt(rm * rn))
    expected = np.sqrt(rm * rn) * phi0 * (1 - np.cos(w_s * t))
    mag = np.hypot(derr[:, 0], derr[:, 1])
    # 3 % of the peak: the Earth-rate (24 h) mode couples in at Omega/w_s ~ 6 %
    # of the tilt over the run; the period itself matches far better.
    assert np.abs(mag - expected).max() < 0.03 * expected.max()
    i_peak = np.argmax(mag)
    assert t[i_peak] == pytest.approx(np.pi / w_s, rel=5e-3)


@pytest.mark.parametrize("dlat,rot", [
    (2e-7, 1e-3),      # a particle metres from its reference, a small rotation: every series
    (9e-4, 0.099),     # just inside both bounds (5.7 km, 0.099 rad): the series' higher terms matter
    (2e-3, 0.3),       # beyond both bounds: the library functions
])
def test_near_mode_is_the_plain_mechanization_to_round_off(dlat, rot):
    """mechanize_core in NEAR mode (a particle: sin and cos of its latitudes by the angle
    sum with series about its reference's, recorded in RECORD mode; the rotation vectors'
    sin and cos by series) against the plain mechanize_step on the same particle, 20
    increments of 0.25 s: the same state to round-off (quaternion 1e-14, velocity 1e-12
    m/s, latitude and longitude 1e-15 rad, height 1e-9 m). A wrong term of the rotation's
    series shows here (its a^6 term is 1.5e-12 of the quaternion at 0.099 rad: tried);
    the latitude's sines enter the state only through small terms, so their series are
    checked directly (next test)."""
    from mixnav.ins._kernels import NEAR, RECORD, TRIG_POINTS, mechanize_core, mechanize_step
    rng = np.random.default_rng(11)
    ref = np.array([0.9, 0.1, 0.2, 0.3, 80.0, 20.0, -1.0, 0.6, 1.9, 400.0])
    ref[:4] /= np.linalg.norm(ref[:4])
    part = ref.copy()
    part[4:7] += [0.3, -0.2, 0.1]
    part[7] += dlat
    part[8] += 1e-6
    part[9] += 5.0
    plain = part.copy()
    prev_r, prev_p = np.zeros(6), np.zeros(6)
    trig, dvn = np.empty((TRIG_POINTS, 3)), np.empty(3)
    for _ in range(20):
        dth = rng.standard_normal(3)
        dth *= rot / np.linalg.norm(dth)
        dv = rng.standard_normal(3) * 0.5 + [0.0, 0.0, -2.45]
        mechanize_core(ref, dth, dv, prev_r[0:3], prev_r[3:6], 0.25, dvn, trig, RECORD)
        mechanize_core(part, dth, dv, prev_p[0:3], prev_p[3:6], 0.25, dvn, trig, NEAR)
        mechanize_step(plain, dth, dv, prev_p[0:3], prev_p[3:6], 0.25, dvn)
        prev_r[:3] = prev_p[:3] = dth
        prev_r[3:] = prev_p[3:] = dv
    d = np.abs(part - plain)
    assert (d[0:4] <= 1e-14).all() and (d[4:7] <= 1e-12).all(), d
    assert (d[7:9] <= 1e-15).all() and d[9] <= 1e-9, d
    assert abs(part[7] - ref[7]) > 0.5 * dlat      # the particle stayed that far from its reference


def test_the_series_trigonometry_is_the_library_s_to_round_off():
    """The NEAR mode's pieces directly: sincos_near about a reference latitude and
    _rv2q_near, against math.sin/cos and _rv2q, on both sides of their bounds (1e-3 rad,
    |a|^2 = 1e-2): within 3e-16 (a wrong series coefficient is >= 1e-12 at the bounds;
    the mechanization above would not see it, its latitudes' sines enter only through
    small terms)."""
    import math

    from mixnav.ins._kernels import _rv2q, _rv2q_near, sincos_near
    for lat0 in (-1.3, 0.0, 0.6, 1.5):
        for d in (1e-9, -3e-5, 5e-4, -9.99e-4, 1.2e-3):
            s, c = sincos_near(lat0 + d, lat0, math.sin(lat0), math.cos(lat0))
            assert abs(s - math.sin(lat0 + d)) <= 3e-16 and abs(c - math.cos(lat0 + d)) <= 3e-16, (lat0, d)
    rng = np.random.default_rng(2)
    for a in (1e-9, 1e-3, 0.05, 0.0999, 0.1001, 0.5):
        v = rng.standard_normal(3)
        v *= a / np.linalg.norm(v)
        np.testing.assert_allclose(_rv2q_near(*v), _rv2q(*v), rtol=0, atol=3e-16)
