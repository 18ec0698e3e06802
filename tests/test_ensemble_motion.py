"""The ensemble filters on the motion-model seam (issue 33).

- every motion model's member maps round-trip: the difference of members injected
  about a nominal returns their error states (strapdown INS, dead reckoning,
  constant velocity);
- a member at zero error propagates to zero error (the reference is the nominal);
- on each non-INS motion model with a linear-Gaussian setup (position fixes, errors
  small against the curvature of the Earth and of the heading) the UKF and the DD2
  filter give the EKF's mean and covariance (closed form: on a linear model the
  unscented and divided-difference moments are exact).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mixnav.data import InitialState
from mixnav.engine.engine import Engine
from mixnav.engine.protocols import StepInputs
from mixnav.filters.dd2 import Dd2Estimator
from mixnav.filters.ekf import KalmanEstimator
from mixnav.filters.ukf import UnscentedEstimator
from mixnav.ins.error_model import get_layout
from mixnav.ins.imu_model import ImuErrorModel
from mixnav.ins.strapdown import StrapdownMotion
from mixnav.measurements.base import MeasurementModel, Rows
from mixnav.measurements.kinds import POSITION
from mixnav.motion import ConstantVelocityMotion, DeadReckoningMotion, clock_ticks, odometry_increments
from mixnav.motion._common import move_position, position_difference
from mixnav.motion.constant_velocity import ConstantVelocityNoise, constant_velocity_layout
from mixnav.motion.dead_reckoning import DeadReckoningNoise, dead_reckoning_layout, set_heading

LLA0 = np.array([math.radians(52.5), math.radians(13.4), 40.0])


def _nav(psi=0.3, speed=8.0):
    nav = np.zeros(10)
    set_heading(nav, psi)
    nav[4:6] = speed * math.cos(psi), speed * math.sin(psi)
    nav[7:10] = LLA0
    return nav


def _motions():
    return {"strapdown": StrapdownMotion(get_layout(17), ImuErrorModel()),
            "dead-reckoning": DeadReckoningMotion(dead_reckoning_layout(clock=True, system_offsets=1)),
            "constant-velocity": ConstantVelocityMotion(constant_velocity_layout(clock=True, system_offsets=1))}


@pytest.mark.parametrize("name", ["strapdown", "dead-reckoning", "constant-velocity"])
def test_member_maps_round_trip(name):
    """``difference(member_states(nav, D), nav) == D`` for errors up to ~0.3 rad and 100 m."""
    motion = _motions()[name]
    lay = motion.layout
    rng = np.random.default_rng(7)
    N = 40
    D = rng.standard_normal((N, lay.n)) * 0.05
    D[:, lay.pos] = rng.standard_normal((N, 3)) * 100.0
    if lay.att is not None:
        D[:, lay.att] = rng.standard_normal((N, 3)) * 0.3
    if lay.vel is not None:
        D[:, lay.vel] = rng.standard_normal((N, 3)) * 5.0
    if lay.has("heading"):
        D[:, lay.slice("heading")] = rng.uniform(-3.0, 3.0, (N, 1))
    nav = _nav()
    navs = np.empty((N, 10))
    motion.member_states(nav, np.zeros(12), D, navs)
    Dn = np.empty_like(D)
    motion.difference_members(navs, nav, D, Dn)
    np.testing.assert_allclose(Dn, D, rtol=0, atol=1e-7)
    # and the members really moved (the map is not the identity on copies of nav)
    assert np.abs(position_difference(navs, nav) - D[:, lay.pos]).max() < 1e-7
    assert np.abs(navs[:, 7] - nav[7]).max() > 1e-6


@pytest.mark.parametrize("name", ["dead-reckoning", "constant-velocity"])
def test_a_member_at_zero_error_stays_at_zero(name):
    """The reference of ``propagate_members`` is the nominal: a zero member stays zero, and on
    the constant-velocity model a velocity error ``dv`` moves the position by ``dv T``."""
    motion = _motions()[name]
    lay = motion.layout
    nav0 = _nav()
    t = np.arange(0.0, 2.01, 0.2)
    inc = odometry_increments(t, np.full(len(t), 8.0), np.full(len(t), 0.05))
    T = float(inc.dt.sum())
    D = np.zeros((2, lay.n))
    if lay.vel is not None:
        D[1, lay.vel] = [0.5, -0.2, 0.1]
    else:
        D[1, lay.pos] = [3.0, -2.0, 1.0]
    inputs = StepInputs(nav0, np.zeros(6), np.zeros(2), np.zeros(12), inc.dtheta, inc.dvel, inc.dt, nav0)
    Dn = np.empty_like(D)
    motion.propagate_members(inputs, D, 0, T, Dn)
    np.testing.assert_allclose(Dn[0], 0.0, atol=1e-9)
    if lay.vel is not None:
        np.testing.assert_allclose(Dn[1, lay.pos], D[1, lay.vel] * T, atol=1e-5)   # curvature over 16 m
    else:   # straight-ish drive: a position offset is carried (to the curvature's order)
        np.testing.assert_allclose(Dn[1, lay.pos], D[1, lay.pos], atol=1e-4)


class PositionFixes(MeasurementModel):
    """A test model: position fixes as NED metres about ``LLA0`` (the rows and the batch ``h``
    written independently of the motion models)."""

    kinds = ("position",)

    def __init__(self, times, ned, sigma, layout):
        self._t = np.asarray(times, float)
        self.ned = np.asarray(ned, float)
        self.sigma = float(sigma)
        self.p = layout.pos.start
        self.n = layout.n
        self.code = POSITION

    @property
    def times(self):
        return self._t

    def _h(self, navs):
        return position_difference(np.atleast_2d(navs), np.r_[np.zeros(7), LLA0])

    def rows(self, i, nav, w_b, clock, memory=None, aux=None):
        z = self.ned[i] - self._h(nav)[0]
        H = np.zeros((3, self.n))
        eps = 1e-3   # the Jacobian of h in the layout's NED error metres (numerically: ~1 - 1e-6)
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            a, b = nav.copy(), nav.copy()
            move_position(a, *d)
            move_position(b, *(-d))
            H[:, self.p + k] = (self._h(a)[0] - self._h(b)[0]) / (2 * eps)
        return Rows(z, H, np.full(3, self.sigma ** 2), np.full(3, self.code, dtype=np.int64))

    def predict_batch(self, i, navs, w_b, clocks=None):
        return self.ned[i].copy(), self._h(navs), np.full(3, self.sigma ** 2)


def _setup(kind):
    rng = np.random.default_rng(11)
    nav = _nav(psi=0.3, speed=8.0)
    if kind == "cv":
        lay = constant_velocity_layout(clock=False)
        motion = ConstantVelocityMotion(lay, ConstantVelocityNoise(accel_sigma=0.5, vertical_accel_sigma=0.1))
        inc = clock_ticks(0.0, 30.0, 0.5)
        init = InitialState(time=0.0, nav=nav, sigma_att=np.zeros(3), sigma_vel=np.full(3, 1.0),
                            sigma_pos=np.full(3, 5.0), sigma_clock=np.array([1.0, 1.0]))
    else:
        lay = dead_reckoning_layout(clock=False)
        # heading, yaw rate and bias all but known: the model is linear in position and scale
        motion = DeadReckoningMotion(lay, DeadReckoningNoise(yaw_rate_sigma=1e-9, bias_sigma0=1e-9, bias_walk=0.0,
                                                             sample_interval=0.2))
        t = np.arange(0.0, 30.01, 0.2)
        inc = odometry_increments(t, np.full(len(t), 8.0), np.zeros(len(t)))
        init = InitialState(time=0.0, nav=nav, sigma_att=np.array([0.0, 0.0, 1e-7]), sigma_vel=np.ones(3),
                            sigma_pos=np.full(3, 5.0), sigma_clock=np.array([1.0, 1.0]))
    times = np.arange(1.0, 30.01, 1.0)
    truth = np.stack([8 * math.cos(0.3) * times, 8 * math.sin(0.3) * times, np.zeros_like(times)], axis=1)
    model = PositionFixes(times, truth + 2.0 * rng.standard_normal(truth.shape), 2.0, lay)
    return motion, model, inc, init, times


@pytest.mark.parametrize("kind", ["cv", "dr"])
@pytest.mark.parametrize("estimator", ["ukf", "dd2"])
def test_ukf_and_dd2_equal_the_ekf_on_a_linear_model(kind, estimator):
    """Closed form: the unscented and DD2 moments of a linear model are exact, so with the
    same Qd and R both filters give the EKF's mean and covariance. What is left is the
    curvature of the Earth over metres (relative 1e-6) and of the heading over 1e-7 rad."""
    motion, model, inc, init, times = _setup(kind)
    ekf = Engine(motion, KalmanEstimator(), [model]).run(inc, init, output_times=times)
    est = UnscentedEstimator(alpha=1.0) if estimator == "ukf" else Dd2Estimator()
    ens = Engine(motion, est, [model]).run(inc, init, output_times=times)
    ned_e = position_difference(ekf.nav, np.r_[np.zeros(7), LLA0])
    ned_u = position_difference(ens.nav, np.r_[np.zeros(7), LLA0])
    np.testing.assert_allclose(ned_u, ned_e, rtol=0, atol=1e-4)
    # relative 1e-4: the NED metres of the layout are taken at the moving nominal, so over the
    # 240 m drive an offset turns by the meridians' convergence (distance / R tan(lat), ~5e-5)
    np.testing.assert_allclose(ens.sigma, ekf.sigma, rtol=1e-4, atol=1e-9)
    # not trivially equal: the filter moved the position off dead reckoning and shrank it
    assert ekf.sigma[-1, 0] < 0.5 * 5.0 and np.abs(ned_e[-1] - ned_e[0]).max() > 100.0


@pytest.mark.parametrize("kind", ["cv", "dr"])
def test_gmpf_tracks_the_kalman_filter_within_monte_carlo_error(kind):
    """On the same linear setups the GMPF's importance density (the DD2 update) is the Kalman
    posterior, so its particle mean is the EKF's mean up to Monte Carlo error: 2000 particles,
    sigma / sqrt(N) ~ 0.02 sigma per epoch; 5 sigma / sqrt(N) with room for the mixture refit."""
    from mixnav.filters.gmpf import GmpfEstimator
    motion, model, inc, init, times = _setup(kind)
    ekf = Engine(motion, KalmanEstimator(), [model]).run(inc, init, output_times=times)
    N = 2000
    gm = Engine(motion, GmpfEstimator(particles=N, components=2), [model]).run(inc, init, output_times=times)
    origin = np.r_[np.zeros(7), LLA0]
    d = position_difference(gm.nav, origin) - position_difference(ekf.nav, origin)
    ratio = np.abs(d) / (ekf.sigma[:, 0:3] / math.sqrt(N))
    assert ratio.max() < 5.0, ratio.max()
    np.testing.assert_allclose(gm.sigma[-5:, 0:3], ekf.sigma[-5:, 0:3], rtol=0.05)


@pytest.mark.parametrize("kind", ["cv", "dr"])
def test_particle_filter_converges_to_the_kalman_filter(kind):
    """The SIR filter on the other motion models (their seam, noise added after): with 5000
    particles its mean is the EKF's to Monte Carlo error and its spread the EKF's sigma.
    Bounds: an effective sample of >= 1000 gives sigma / sqrt(1000) ~ 0.03 sigma per epoch;
    0.2 sigma leaves room for the resampling's and the jitter's own noise; sigma within 10 %."""
    from mixnav.filters.particle import ParticleEstimator
    motion, model, inc, init, times = _setup(kind)
    ekf = Engine(motion, KalmanEstimator(), [model]).run(inc, init, output_times=times)
    pf = Engine(motion, ParticleEstimator(particles=5000), [model]).run(inc, init, output_times=times)
    origin = np.r_[np.zeros(7), LLA0]
    d = position_difference(pf.nav, origin) - position_difference(ekf.nav, origin)
    ratio = np.abs(d[5:, :2]) / ekf.sigma[5:, 0:2]
    assert ratio.max() < 0.2, ratio.max()
    np.testing.assert_allclose(pf.sigma[-10:, 0:2], ekf.sigma[-10:, 0:2], rtol=0.1)
