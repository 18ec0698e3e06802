"""Motion models beside the strapdown INS (mixnav.motion): dead reckoning and constant
velocity on the one engine, and the multi-system pseudorange model they use."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mixnav.data import ImuData, InitialState
from mixnav.engine.engine import Engine
from mixnav.engine.smoother import rts_smooth
from mixnav.errors import ArgumentError, DataError
from mixnav.filters.ekf import KalmanEstimator
from mixnav.geodesy.frames import dcm_ecef_to_ned, lla_to_ecef, lla_to_ned
from mixnav.gnss.geometry import C_LIGHT, earth_rotation_correction
from mixnav.gnss.pseudoranges import PseudorangeEpochs
from mixnav.ins.error_model import get_layout
from mixnav.measurements.pseudorange import PseudorangeGnss
from mixnav.motion import ConstantVelocityMotion, DeadReckoningMotion, clock_ticks, odometry_increments
from mixnav.motion.constant_velocity import constant_velocity_layout
from mixnav.motion.dead_reckoning import DeadReckoningNoise, dead_reckoning_layout, heading_of, set_heading

LLA0 = np.array([math.radians(52.5), math.radians(13.4), 40.0])


def _nav(psi=0.3, speed=8.0):
    nav = np.zeros(10)
    set_heading(nav, psi)
    nav[4:6] = speed * math.cos(psi), speed * math.sin(psi)
    nav[7:10] = LLA0
    return nav


def _true_state(motion, nav, sensor, clock, aux, dx):
    """The nominal with the error ``dx`` injected (copies)."""
    nav, sensor, clock = nav.copy(), sensor.copy(), clock.copy()
    aux = {k: v.copy() for k, v in aux.items()}
    motion.inject(nav, sensor, clock, aux, dx)
    return nav, sensor, clock, aux


def _error(motion, nav_a, sensor_a, clock_a, nav_b, sensor_b, clock_b):
    """``x_b - x_a`` in the layout's error coordinates (position NED m, heading, scale, bias, clock)."""
    lay = motion.layout
    e = np.zeros(lay.n)
    e[lay.pos] = lla_to_ned(nav_b[None, 7:10], nav_a[7:10])[0]
    if lay.has("heading"):
        e[lay.slice("heading")] = (heading_of(nav_b) - heading_of(nav_a) + math.pi) % (2 * math.pi) - math.pi
        e[lay.slice("speed_scale")] = sensor_b[0] - sensor_a[0]
        e[lay.slice("yaw_rate_bias")] = sensor_b[1] - sensor_a[1]
    if lay.vel is not None:
        e[lay.vel] = nav_b[4:7] - nav_a[4:7]
    if lay.clk >= 0:
        e[lay.clk:lay.clk + 2] = clock_b - clock_a
    return e


@pytest.mark.parametrize("kind", ["dr", "cv"])
def test_transition_matches_finite_differences(kind):
    """Phi of one block equals the derivative of the propagated error with respect to the
    initial error (central differences through the nominal propagation and the feedback)."""
    if kind == "dr":
        lay = dead_reckoning_layout(clock=True)
        motion = DeadReckoningMotion(lay, DeadReckoningNoise())
        K = 5
        dt = np.full(K, 0.2)
        dtheta = np.zeros((K, 3))
        dtheta[:, 2] = np.linspace(0.05, 0.12, K) * dt      # turning
        dvel = np.zeros((K, 3))
        dvel[:, 0] = np.linspace(9.0, 11.0, K) * dt
        sensor0 = np.zeros(12)
        sensor0[0], sensor0[1] = 0.01, 0.002
        # steps large enough that the positions' ECEF round-off (~1e-9 m) is negligible,
        # small enough that the second-order terms are (the map is smooth)
        steps = [1e-2, 1e-2, 1e-2, 1e-4, 1e-4, 1e-5, 1e-2, 1e-3]
    else:
        lay = constant_velocity_layout(clock=True)
        motion = ConstantVelocityMotion(lay)
        K = 3
        dt = np.full(K, 0.4)
        dtheta = np.zeros((K, 3))
        dvel = np.zeros((K, 3))
        sensor0 = np.zeros(12)
        steps = [1e-3] * 3 + [1e-4] * 3 + [1e-3, 1e-4]
    n = lay.n
    nav0 = _nav()
    clock0 = np.array([100.0, -3.0])
    work = np.empty((4, n, n))

    def run(nav, sensor, clock):
        nav, sensor, clock = nav.copy(), sensor.copy(), clock.copy()
        motion.propagate(nav, np.zeros(6), sensor, dtheta, dvel, dt, np.zeros((n, n)), work)
        clock[0] += clock[1] * dt.sum()      # the engine advances the clock bias
        return nav, sensor, clock

    nav_n, sens_n, clk_n = run(nav0, sensor0, clock0)
    Phi = work[1].copy()
    J = np.zeros((n, n))
    for j in range(n):
        cols = []
        for sgn in (1.0, -1.0):
            dx = np.zeros(n)
            dx[j] = sgn * steps[j]
            nav_t, sens_t, clk_t, _ = _true_state(motion, nav0, sensor0, clock0, {}, dx)
            nav_p, sens_p, clk_p = run(nav_t, sens_t, clk_t)
            cols.append(_error(motion, nav_n, sens_n, clk_n, nav_p, sens_p, clk_p))
        J[:, j] = (cols[0] - cols[1]) / (2 * steps[j])
    assert np.abs(Phi - J).max() < 2e-5 * np.abs(J).max(), np.abs(Phi - J).round(7)


def test_dead_reckoning_follows_a_circle():
    """Constant speed and yaw rate: the dead-reckoned path closes a circle of radius v / w."""
    v, w, T = 10.0, 0.1, 2 * math.pi / 0.1
    t = np.arange(0.0, T + 1e-9, 0.05)
    inc = odometry_increments(t, np.full(len(t), v), np.full(len(t), w))
    lay = dead_reckoning_layout(clock=False)
    motion = DeadReckoningMotion(lay)
    nav = _nav(psi=0.0, speed=v)
    motion.propagate(nav, np.zeros(6), np.zeros(12), inc.dtheta, inc.dvel, inc.dt, np.zeros((lay.n, lay.n)),
                     np.empty((4, lay.n, lay.n)))
    closure = np.linalg.norm(lla_to_ned(nav[None, 7:10], LLA0)[0])
    assert closure < 0.01 * (v / w)           # back at the start (mid-point rule: O(dt^2))
    assert abs((heading_of(nav) - w * t[-1] + math.pi) % (2 * math.pi) - math.pi) < 1e-9


def test_odometry_increments_validate():
    with pytest.raises(ArgumentError, match="increase"):
        odometry_increments([0.0, 0.2, 0.1], [1, 1, 1], [0, 0, 0])
    with pytest.raises(ArgumentError, match="non-finite"):
        odometry_increments([0.0, 0.2, 0.4], [1, np.nan, 1], [0, 0, 0])


def test_engine_refuses_the_wrong_increments():
    lay = dead_reckoning_layout(clock=False)
    imu = ImuData(time=np.array([0.1, 0.2]), dt=np.full(2, 0.1), dtheta=np.zeros((2, 3)), dvel=np.zeros((2, 3)))
    init = InitialState(time=0.0, nav=_nav(), sigma_att=np.full(3, 0.01), sigma_vel=np.ones(3),
                        sigma_pos=np.ones(3))
    with pytest.raises(ArgumentError, match="OdometryIncrements"):
        Engine(DeadReckoningMotion(lay), KalmanEstimator()).run(imu, init)
    from mixnav.ins.imu_model import ImuErrorModel
    from mixnav.ins.strapdown import StrapdownMotion
    odo = odometry_increments([0.0, 0.1, 0.2], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    with pytest.raises(ArgumentError, match="strapdown INS"):
        Engine(StrapdownMotion(get_layout(15), ImuErrorModel()), KalmanEstimator()).run(odo, init)


# --- simulated pseudoranges ---------------------------------------------------------------
def _constellation(n_gps=7, n_glo=6, seed=1):
    """Fixed satellites spread over the sky, 20 000 / 19 100 km from the receiver (a static
    sky is enough for a few minutes: the geometry, not the orbits, is under test)."""
    rng = np.random.default_rng(seed)
    C_ne = dcm_ecef_to_ned(LLA0[0], LLA0[1])
    r0 = lla_to_ecef(LLA0)
    sats, systems, ids = [], [], []
    for k, (n_s, sysc, dist) in enumerate(((n_gps, 1, 2.02e7), (n_glo, 4, 1.91e7))):
        az = rng.uniform(0, 2 * math.pi, n_s)
        el = rng.uniform(math.radians(15), math.radians(80), n_s)
        u_n = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], axis=1)
        sats.append(r0 + (u_n @ C_ne) * dist)
        systems += [sysc] * n_s
        ids += list(range(1 + 100 * k, n_s + 1 + 100 * k))
    return np.vstack(sats), np.array(systems), np.array(ids)


def _simulate(truth_lla, times, clock, offset, sigma, seed=0, bias=None):
    """Pseudorange rows at ``times`` from the true positions (satellite positions given at the
    transmit time in that time's ECEF frame, as smartLoc gives them)."""
    rng = np.random.default_rng(seed)
    sats, systems, ids = _constellation()
    rows = {k: [] for k in ("t", "pr", "var", "sat", "id", "sys")}
    for t, lla, c in zip(times, truth_lla, clock):
        r = lla_to_ecef(lla)
        # the satellite position in the transmit-time frame that rotates onto the fixed one
        tau = np.linalg.norm(sats - r, axis=1) / C_LIGHT
        s_tx = earth_rotation_correction(sats, -tau)
        rho = np.linalg.norm(earth_rotation_correction(s_tx, tau) - r, axis=1)
        pr = rho + c + offset * (systems == 4) + sigma * rng.standard_normal(len(rho))
        if bias is not None:
            pr = pr + bias(t, ids)
        for k, v in (("t", np.full(len(pr), t)), ("pr", pr), ("var", np.full(len(pr), sigma ** 2)),
                     ("sat", s_tx), ("id", ids), ("sys", systems)):
            rows[k].append(v)
    cat = {k: np.concatenate(v) if k != "sat" else np.vstack(v) for k, v in rows.items()}
    return PseudorangeEpochs.from_rows(cat["t"], cat["pr"], cat["var"], cat["sat"], cat["id"], cat["sys"],
                                       elevation=np.full(len(cat["pr"]), 0.5), cn0=np.full(len(cat["pr"]), 45.0))


def test_pseudorange_jacobian_matches_finite_differences():
    lay = constant_velocity_layout(clock=True, system_offsets=1)
    ep = _simulate([LLA0], [1.0], [50.0], 30.0, 1e-9)
    model = PseudorangeGnss(ep, lay, systems=(1, 4))
    nav = _nav()
    motion = ConstantVelocityMotion(lay)
    aux = {"system_offset": np.array([25.0])}
    clock = np.array([40.0, 0.0])
    rows = model.rows(0, nav, np.zeros(3), clock, aux=aux)
    J = np.zeros_like(rows.H)
    for j in range(lay.n):
        zs = []
        for sgn in (1.0, -1.0):
            dx = np.zeros(lay.n)
            dx[j] = sgn * 1e-2
            nav_t, _, clk_t, aux_t = _true_state(motion, nav, np.zeros(12), clock, aux, dx)
            zs.append(model.rows(0, nav_t, np.zeros(3), clk_t, aux=aux_t).z)
        # z = measured - h(x): dz/dx = -dh/dx = -H
        J[:, j] = -(zs[0] - zs[1]) / 2e-2
    assert np.abs(J - rows.H).max() < 1e-6
    # at the truth (clock 50, offset 30) the innovations vanish (no noise): the Sagnac turn is right
    nav_truth = nav.copy()
    z = model.rows(0, nav_truth, np.zeros(3), np.array([50.0, 0.0]), aux={"system_offset": np.array([30.0])}).z
    assert np.abs(z).max() < 1e-3


def test_unknown_systems_are_counted_and_layout_checked():
    ep = _simulate([LLA0], [1.0], [0.0], 0.0, 1.0)
    lay1 = constant_velocity_layout(clock=True)
    m = PseudorangeGnss(ep, lay1, systems=(1,))
    assert m.skipped_rows["unknown_system"] == 6
    assert len(m.rows(0, _nav(), np.zeros(3), np.zeros(2)).z) == 7
    with pytest.raises(ArgumentError, match="system_offset"):
        PseudorangeGnss(ep, lay1, systems=(1, 4))


def _straight_drive(T=120.0, rate=5.0, v=10.0, w=0.02):
    t = np.arange(0.0, T + 1e-9, 1 / rate)
    psi = 0.4 + w * t
    dn = np.cumsum(np.r_[0.0, v * np.cos(0.5 * (psi[1:] + psi[:-1])) * np.diff(t)])
    de = np.cumsum(np.r_[0.0, v * np.sin(0.5 * (psi[1:] + psi[:-1])) * np.diff(t)])
    from mixnav.geodesy.frames import ned_to_lla
    lla = ned_to_lla(np.stack([dn, de, np.zeros_like(dn)], axis=1), LLA0)
    return t, psi, lla


def _dr_run(ep, t, psi, lla, estimator, seed=0, history=False, layout_offsets=1):
    rng = np.random.default_rng(seed)
    speed = 10.0 * 1.02 + 0.05 * rng.standard_normal(len(t))   # 2 % scale error
    yaw = 0.02 + 0.001 + 0.002 * rng.standard_normal(len(t))    # 0.001 rad/s bias
    inc = odometry_increments(t, speed, yaw)
    lay = dead_reckoning_layout(clock=True, system_offsets=layout_offsets)
    # the filter told the simulation's noise: no slip, no vertical motion
    motion = DeadReckoningMotion(lay, DeadReckoningNoise(sample_interval=t[1] - t[0], lateral_sigma=0.0,
                                                         vertical_sigma=0.0))
    nav = _nav(psi=psi[0] + 0.02, speed=10.0)
    nav[7:10] = lla[0]
    init = InitialState(time=0.0, nav=nav, sigma_att=np.array([0, 0, 0.05]), sigma_vel=np.ones(3),
                        sigma_pos=np.full(3, 5.0), sigma_clock=np.array([1e3, 10.0]))
    model = PseudorangeGnss(ep, lay, systems=(1, 4))
    res = Engine(motion, estimator, [model], history=history).run(inc, init, output_times=t[1:])
    err = lla_to_ned(res.nav[:, 7:10], LLA0) - lla_to_ned(lla[1:], LLA0)
    return res, err, lay


def test_inter_system_offset_and_odometer_errors_are_recovered():
    """Simulated drive, GPS + GLONASS with a 37 m GLONASS offset, a drifting clock, odometer
    scale +2 % and yaw-rate bias 1e-3 rad/s: the filter recovers all of them, with NEES of
    the position in the chi-square band (20 seeds pooled: mean of 3 dof within +-0.6)."""
    t, psi, lla = _straight_drive()
    nees, isb, scale, bias = [], [], [], []
    for seed in range(20):
        clock = 200.0 - 3.0 * t
        ep = _simulate(lla[1:], t[1:], clock[1:], 37.0, 3.0, seed=seed)
        res, err, lay = _dr_run(ep, t, psi, lla, KalmanEstimator(), seed=seed)
        P = res.pv_cov[:, 3:, 3:]
        k = len(t) // 2
        nees += [float(e @ np.linalg.solve(Pk, e)) for e, Pk in zip(err[k:], P[k:])]
        isb.append(res.estimates["system_offset"][-1, 0])
        scale.append(res.estimates["speed_scale"][-1, 0])
        bias.append(res.estimates["yaw_rate_bias"][-1, 0])
    assert abs(np.mean(isb) - 37.0) < 0.5
    # the odometer reads 2 % high: the scale estimate (true = est + dk, v = (1 + k) s) is -1.96 %
    assert abs(np.mean(scale) - (1 / 1.02 - 1)) < 0.002
    assert abs(np.mean(bias) - 0.001) < 3e-4
    assert 2.4 < np.mean(nees) < 3.6, np.mean(nees)


def test_smoother_on_dead_reckoning_beats_the_filter():
    """The RTS smoother runs on a non-INS layout (the motion model's own feedback) and lowers
    the horizontal RMSE of the forward filter on the simulated drive."""
    t, psi, lla = _straight_drive(T=80.0)
    clock = 200.0 - 3.0 * t
    ep = _simulate(lla[1:], t[1:], clock[1:], 37.0, 8.0, seed=3)
    res, err, lay = _dr_run(ep, t, psi, lla, KalmanEstimator(), seed=3, history=True)
    sm = rts_smooth(res)
    err_s = lla_to_ned(sm.nav[:, 7:10], LLA0) - lla_to_ned(lla[1:], LLA0)
    rms = lambda e: float(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)))  # noqa: E731
    assert rms(err_s) < 0.8 * rms(err)
    assert np.isfinite(sm.sigma).all() and (sm.sigma[:, 0] <= res.sigma[:, 0] + 1e-9).all()


def test_constant_velocity_gnss_only_filter():
    """GNSS-only: the constant-velocity model with pseudoranges tracks a straight drive and
    recovers the velocity (no odometry, no IMU)."""
    t, psi, lla = _straight_drive(T=60.0, rate=1.0, w=0.0)
    clock = 100.0 + 2.0 * t
    ep = _simulate(lla[1:], t[1:], clock[1:], 37.0, 3.0, seed=5)
    lay = constant_velocity_layout(clock=True, system_offsets=1)
    nav = _nav(psi=psi[0], speed=0.0)
    nav[7:10] = lla[0]
    init = InitialState(time=0.0, nav=nav, sigma_att=np.zeros(3), sigma_vel=np.full(3, 20.0),
                        sigma_pos=np.full(3, 10.0), sigma_clock=np.array([1e3, 10.0]))
    res = Engine(ConstantVelocityMotion(lay), KalmanEstimator(), [PseudorangeGnss(ep, lay)]).run(
        clock_ticks(0.0, 60.0, 0.5), init, output_times=t[1:])
    v_true = 10.0 * np.array([math.cos(psi[0]), math.sin(psi[0])])
    assert np.abs(res.nav[-20:, 4:6].mean(axis=0) - v_true).max() < 0.5   # 1 m/s^2/sqrt(Hz): noisy per epoch
    err = lla_to_ned(res.nav[:, 7:10], LLA0) - lla_to_ned(lla[1:], LLA0)
    assert np.sqrt(np.mean(err[20:, :2] ** 2)) < 3.0


def test_smartloc_odometry_bad_rows(tmp_path):
    from mixnav.io.smartloc import read_odometry
    good = "odom3 0 5.85 0 0 0 0 -0.0059 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06\n"
    for bad, what in (("odom3 0.2 250 0 0 0 0 0.01 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06\n", "speed"),
                      ("odom3 0.2 5 0 0 0 0 45.0 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06\n", "yaw rate"),
                      ("odom3 0.2 5 0 0 0 0 0.01 0 0.0009 0.0009 4e-06 4e-06 4e-06\n", "variances"),
                      ("odom3 0.0 5 0 0 0 0 0.01 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06\n", "repeats")):
        p = tmp_path / "x_Input.txt"
        p.write_text(good + bad)
        with pytest.raises(DataError, match=what) as exc:
            read_odometry(p)
        assert exc.value.line == 2 and str(p) in str(exc.value)
