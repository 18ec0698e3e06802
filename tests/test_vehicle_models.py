"""Land-vehicle aiding models: Jacobians against finite differences of h(x), with the
error state applied exactly as the engine feeds it back (StrapdownMotion.inject)."""

import numpy as np
import pytest

from mixnav.attitude import euler_to_dcm, quat_to_dcm
from mixnav.data import OdometerData
from mixnav.errors import ArgumentError
from mixnav.ins.error_model import StateLayout
from mixnav.ins.imu_model import ImuErrorModel
from mixnav.ins.strapdown import StrapdownMotion
from mixnav.ins.mechanization import nav_vector
from mixnav.measurements.vehicle import (MOUNTING, ODOMETER_SCALE, NonHolonomic, Odometer, ZeroAngularRate,
                                         ZeroVelocity, mounting_block, odometer_scale_block)
from mixnav.attitude import euler_to_quat

LAYOUT = StateLayout("vehicle", ["gyro_scale", "accel_scale", mounting_block(0.02), odometer_scale_block(0.01)])


def _state(rng):
    q = euler_to_quat(np.array([0.05, -0.03, 1.1]))
    nav = nav_vector(q, np.array([8.0, -11.0, 0.4]), np.array([0.7, -1.9, 300.0]))
    aux = {MOUNTING: np.array([0.01, -0.02]), ODOMETER_SCALE: np.array([0.004])}
    w_b = np.array([0.02, -0.01, 0.3])
    return nav, aux, w_b


def _perturbed(nav, aux, w_b, dx):
    """The state ``x_est (+) dx`` as the engine's feedback makes it, and the body rate it implies."""
    nav2, sensor, clock = nav.copy(), np.zeros(12), np.zeros(2)
    aux2 = {k: v.copy() for k, v in aux.items()}
    StrapdownMotion(LAYOUT, ImuErrorModel()).inject(nav2, sensor, clock, aux2, dx)
    return nav2, aux2, w_b - sensor[0:3]  # w = w_meas - bg: a larger bias estimate lowers the rate


def _fd_check(model, i, nav, aux, w_b, meas_offset=0.0):
    rows = model.rows(i, nav, w_b, np.zeros(2), None, aux=aux)
    n = LAYOUT.n
    H_fd = np.zeros_like(rows.H)
    eps = 1e-6
    for j in range(n):
        dx = np.zeros(n)
        dx[j] = eps
        up = model.rows(i, *_perturbed(nav, aux, w_b, dx)[0:1], _perturbed(nav, aux, w_b, dx)[2], np.zeros(2),
                        None, aux=_perturbed(nav, aux, w_b, dx)[1])
        dx[j] = -eps
        dn = model.rows(i, *_perturbed(nav, aux, w_b, dx)[0:1], _perturbed(nav, aux, w_b, dx)[2], np.zeros(2),
                        None, aux=_perturbed(nav, aux, w_b, dx)[1])
        # z = meas - h: H = dh/dx = -dz/dx
        H_fd[:, j] = -(up.z - dn.z) / (2 * eps)
    return rows, H_fd


@pytest.mark.parametrize("which", ["nhc", "odometer", "zupt", "zaru"])
def test_jacobian_matches_finite_differences(which):
    rng = np.random.default_rng(3)
    nav, aux, w_b = _state(rng)
    lever = np.array([-1.2, 0.3, 0.8])
    mount = np.radians([1.0, -2.0, 3.0])
    if which == "nhc":
        model = NonHolonomic(np.array([1.0]), LAYOUT, mount, lever, sigma=0.1)
    elif which == "odometer":
        model = Odometer(OdometerData(np.array([1.0]), np.array([13.0]), np.array([0.05])), LAYOUT, mount, lever)
    elif which == "zupt":
        model = ZeroVelocity(np.array([1.0]), LAYOUT, max_speed=100.0)  # the test state moves
    else:
        model = ZeroAngularRate(np.array([1.0]), LAYOUT, sigma=0.01, max_speed=100.0)
    rows, H_fd = _fd_check(model, 0, nav, aux, w_b)
    scale = np.abs(H_fd).max()
    # central differences at eps = 1e-6 are good to ~1e-9 of the entries here;
    # a wrong sign or a missing term is an O(1) relative error
    np.testing.assert_allclose(rows.H, H_fd, atol=1e-6 * scale)
    assert np.abs(rows.H).max() > 0


def test_nhc_zero_for_a_vehicle_moving_along_its_axis():
    """A car driving straight along its x axis with the IMU mounted at known angles gives
    zero NHC innovations; the odometer innovation is zero at the true speed and scale."""
    mount = np.radians([2.0, -3.0, 4.0])
    C_nv = euler_to_dcm(np.array([0.0, 0.02, 0.7]))
    C_nb = C_nv @ euler_to_dcm(mount)           # C_vb = C(mount): body -> vehicle
    from mixnav.attitude import dcm_to_quat
    v_n = C_nv @ np.array([15.0, 0.0, 0.0])
    nav = nav_vector(dcm_to_quat(C_nb), v_n, np.array([0.7, -1.9, 300.0]))
    lay = StateLayout("plain")
    nhc = NonHolonomic([1.0], lay, mount)
    r = nhc.rows(0, nav, np.zeros(3))
    np.testing.assert_allclose(r.z, 0.0, atol=1e-12)
    odo = Odometer(OdometerData(np.array([1.0]), np.array([15.0 * 1.01]), np.array([0.05])), lay, mount,
                   scale=0.01)
    np.testing.assert_allclose(odo.rows(0, nav, np.zeros(3)).z, 0.0, atol=1e-12)


def test_zaru_zero_at_rest_with_earth_rate():
    from mixnav.geodesy.earth import OMEGA_EARTH
    lay = StateLayout("plain")
    q = euler_to_quat(np.array([0.01, 0.02, 0.3]))
    nav = nav_vector(q, np.zeros(3), np.array([0.7, 0.1, 10.0]))
    w_ie = OMEGA_EARTH * np.array([np.cos(0.7), 0.0, -np.sin(0.7)])
    w_b = quat_to_dcm(q).T @ w_ie
    r = ZeroAngularRate([1.0], lay, sigma=0.01).rows(0, nav, w_b)
    np.testing.assert_allclose(r.z, 0.0, atol=1e-15)


def test_bad_arguments_name_themselves():
    lay = StateLayout("plain")
    with pytest.raises(ArgumentError, match="sigma"):
        NonHolonomic([1.0], lay, sigma=0.0)
    with pytest.raises(ArgumentError, match="mounting"):
        NonHolonomic([1.0], lay, mounting=[0, 0])
    with pytest.raises(ArgumentError, match="times"):
        ZeroVelocity([2.0, 1.0], lay)
    with pytest.raises(ArgumentError, match="scale"):
        Odometer(OdometerData(np.array([1.0]), np.array([1.0]), np.array([0.1])), lay, scale=2.0)


def test_zupt_not_used_when_the_solution_moves():
    """An IMU-only detection during a smooth drive is contradicted by the navigation speed."""
    lay = StateLayout("plain")
    nav = nav_vector(euler_to_quat(np.zeros(3)), np.array([5.0, 0.0, 0.0]), np.array([0.7, 0.1, 10.0]))
    assert ZeroVelocity([1.0], lay, max_speed=1.0).rows(0, nav, np.zeros(3)) is None
    assert ZeroAngularRate([1.0], lay, sigma=0.01, max_speed=1.0).rows(0, nav, np.zeros(3)) is None
    nav[4:7] = [0.5, 0.0, 0.0]
    assert ZeroVelocity([1.0], lay, max_speed=1.0).rows(0, nav, np.zeros(3)) is not None


def test_nhc_suspension_pitch_expects_squat_times_speed():
    """With ``pitch_per_accel`` the vertical row expects ``k a_x v_x`` (the body squats when
    the car speeds up), ``a_x`` from the specific force and the attitude: a car pitched
    nose-up against its path by exactly that much gives a zero innovation; without the gain,
    or where the specific force is unknown, it is the plain constraint."""
    from mixnav.attitude import dcm_to_quat
    from mixnav.geodesy.earth import normal_gravity
    lay = StateLayout("plain")
    k, a, v = np.radians(0.33), 1.5, 14.0             # 0.33 deg per m/s^2, 1.5 m/s^2, 14 m/s
    C_nv = euler_to_dcm(np.array([0.0, np.radians(2.0), 0.4]))    # path 2 deg uphill, heading 0.4 rad
    C_nb = C_nv @ euler_to_dcm(np.array([0.0, k * a, 0.0]))        # body nose-up k a against the path
    v_n = C_nv @ np.array([v, 0.0, 0.0])
    nav = nav_vector(dcm_to_quat(C_nb), v_n, np.array([0.7, -1.9, 300.0]))
    g_n = np.array([0.0, 0.0, normal_gravity(0.7, 300.0)])
    f_b = C_nb.T @ (C_nv @ np.array([a, 0.0, 0.0]) - g_n)           # accelerating along the path
    times = np.array([1.0, 1.1])
    f = np.vstack([np.full(3, np.nan), f_b])
    nhc = NonHolonomic(times, lay, pitch_per_accel=k, specific_force=f)
    assert nhc.forward_acceleration(1, nav) == pytest.approx(a * np.cos(k * a), rel=1e-9)
    r = nhc.rows(1, nav, np.zeros(3))
    plain = NonHolonomic(times, lay).rows(1, nav, np.zeros(3))
    np.testing.assert_allclose(plain.z[1], -(C_nb.T @ v_n)[2])
    assert abs(plain.z[1]) > 0.9 * k * a * v          # the plain constraint sees the squat as a violation
    assert abs(r.z[1]) < 0.01 * k * a * v             # the gain explains it
    np.testing.assert_allclose(r.H, plain.H)
    np.testing.assert_allclose(r.z[0], plain.z[0])
    np.testing.assert_allclose(nhc.rows(0, nav, np.zeros(3)).z, plain.z)   # unknown specific force: plain row
    assert not nhc.remembers
    with pytest.raises(ArgumentError, match="pitch_per_accel"):
        NonHolonomic(times, lay, pitch_per_accel=float("nan"), specific_force=f)
    with pytest.raises(ArgumentError, match="specific_force"):
        NonHolonomic(times, lay, pitch_per_accel=k)
    with pytest.raises(ArgumentError, match="specific_force"):
        NonHolonomic(times, lay, pitch_per_accel=k, specific_force=f[:1])


def test_mean_specific_force_averages_the_increments_before_each_epoch():
    from mixnav.data import ImuData
    from mixnav.measurements.vehicle import mean_specific_force
    t = np.arange(1, 301) * 0.01                       # increments ending at 0.01 .. 3.00 s
    f = np.column_stack([np.sin(t), np.zeros_like(t), np.full_like(t, -9.8)])
    imu = ImuData(time=t, dt=np.full_like(t, 0.01), dtheta=np.zeros((300, 3)), dvel=f * 0.01)
    out = mean_specific_force(imu, [0.5, 2.0, 5.0, -1.0], 0.5)
    np.testing.assert_allclose(out[1], f[(t > 1.5 + 1e-9) & (t <= 2.0 + 1e-9)].mean(0), atol=1e-12)
    assert np.isnan(out[2]).all() and np.isnan(out[3]).all()   # no increment in the span
    np.testing.assert_allclose(out[0], f[t <= 0.5 + 1e-9].mean(0), atol=1e-12)
    with pytest.raises(ArgumentError, match="span"):
        mean_specific_force(imu, [1.0], 0.0)


def test_nhc_forward_acceleration_is_the_matrix_form_at_any_attitude_and_mounting(rng):
    """``a_x = C_vb[0] (f_b + C_bn g_n)``, the written-out row of C_nb against the whole DCM,
    at random attitudes (roll included) and a mounting that is not zero."""
    from mixnav.attitude import quat_to_dcm
    from mixnav.geodesy.earth import normal_gravity
    lay = StateLayout("plain")
    mounting = np.radians([1.5, -2.0, 3.0])
    f = rng.normal(size=(5, 3)) + [0.0, 0.0, -9.8]
    nhc = NonHolonomic(np.arange(5.0), lay, mounting=mounting, pitch_per_accel=0.005, specific_force=f)
    for i in range(5):
        nav = nav_vector(euler_to_quat(rng.uniform(-0.5, 0.5, 3) * [1, 1, 6]), rng.normal(size=3),
                         np.array([0.7, -1.9, 300.0]))
        g_n = np.array([0.0, 0.0, normal_gravity(0.7, 300.0)])
        expect = euler_to_dcm(mounting)[0] @ (f[i] + quat_to_dcm(nav[0:4]).T @ g_n)
        assert nhc.forward_acceleration(i, nav) == pytest.approx(expect, rel=1e-12, abs=1e-12)
