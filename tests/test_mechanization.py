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
