"""Levelling at rest, then the heading from GNSS once moving (alignment method
``level-then-gnss``): a simulated car parked on a slope with an off-axis IMU, the
config errors naming their keys, and drive-0708."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mixnav.alignment import align_from_gnss_velocity, align_level_then_gnss
from mixnav.attitude import attitude_error, euler_to_dcm, quat_to_dcm, quat_to_euler, wrap_angle
from mixnav.config import load_dataset
from mixnav.data import GnssFixes, ImuData
from mixnav.errors import ArgumentError, ConfigError
from mixnav.experiment.process import initial_state
from mixnav.geodesy import earth
from mixnav.geodesy.frames import displace, ned_displacement
from mixnav.sim.trajectory import InitialState, MotionSegment, generate, mount

from .conftest import DATA_DIR

D = np.deg2rad
G = 9.80665
LEVER = np.array([0.3, -0.1, -0.6])        # antenna from the IMU, body frame [m]
MOUNTING = D([0.5, 1.0, 4.0])              # IMU in the vehicle: C_vb = euler_to_dcm(MOUNTING)
VEHICLE_RPY = D([3.0, -2.0, 50.0])         # the car parked across a slope
REST, CARRY_MAX = 30.0, 8.0                # [s]


def _drive(rest=REST, still_until=None):
    """A car at rest for ``rest`` s (or ``still_until``), then pulling away at 1 m/s^2 while it
    turns 3 deg/s and rolls and pitches (-0.3, +0.4 deg/s: the slope changes): truth of the
    IMU (mounted at MOUNTING), its ideal increments, and 4 Hz antenna fixes with velocity."""
    rest = rest if still_until is None else still_until
    segs = [MotionSegment("static", rest),
            MotionSegment("accelerate", CARRY_MAX, acceleration=1.0, roll_rate=D(-0.3), pitch_rate=D(0.4),
                          yaw_rate=D(3.0))]
    truth, imu = generate(segs, InitialState((D(39.9), D(-105.2), 1650.0), 0.0, tuple(VEHICLE_RPY)), 100.0)
    truth, imu = mount(truth, imu, euler_to_dcm(MOUNTING))
    k = np.arange(0, len(truth.time), 25)
    ant = displace(truth.lla[k], np.einsum("kij,j->ki", quat_to_dcm(truth.q_nb[k]), LEVER))
    fixes = GnssFixes(truth.time[k], ant, np.full((len(k), 3), 0.02), truth.v_n[k].copy(),
                      np.full((len(k), 3), 0.02), source="sim.pos")
    return truth, imu, fixes


def _corrupt(imu, rng, accel_bias, gyro_bias, vrw, arw):
    """Constant biases [m/s^2], [rad/s] and white noise [m/s/sqrt(s)], [rad/sqrt(s)]."""
    dt = imu.dt[:, None]
    n = (len(imu), 3)
    return ImuData(imu.time, imu.dt, imu.dtheta + gyro_bias * dt + arw * np.sqrt(dt) * rng.standard_normal(n),
                   imu.dvel + accel_bias * dt + vrw * np.sqrt(dt) * rng.standard_normal(n), source="sim.imu")


def _forward():
    return euler_to_dcm(MOUNTING)[0]   # C_vb^T e_x: the vehicle's x axis in the body frame


def _truth_at(truth, t):
    k = int(np.argmin(np.abs(truth.time - t)))
    assert abs(truth.time[k] - t) < 1e-6
    return k


def test_pairwise_product_keeps_the_order_of_the_increments(rng):
    # oracle: the sequential product; large random rotations do not commute, so a
    # reversed or shuffled order fails by tens of degrees
    from mixnav.alignment.level_gnss import _product
    for n in (0, 1, 2, 7, 64, 1001):
        rv = rng.normal(scale=0.5, size=(n, 3))
        c = np.eye(3)
        for r in rv:
            c = c @ Rotation.from_rotvec(r).as_matrix()
        np.testing.assert_allclose(_product(rv), c, atol=1e-10)


def test_ideal_imu_recovers_the_tilted_attitude_within_the_earth_rate_bound():
    truth, imu, fixes = _drive()
    a = align_level_then_gnss(imu, fixes, LEVER, REST, 5.0, forward_b=_forward())
    k = _truth_at(truth, a.time)
    assert REST < a.time <= REST + CARRY_MAX
    # Error-free sensors: what is left is the Earth rate the rest-window bias removed in the
    # parked body axes while the car turned (at most 2 Omega_ie per second of carry).
    bound = 2 * earth.OMEGA_EARTH * (a.time - a.rest_end)
    err = attitude_error(a.q_nb, truth.q_nb[k])
    assert np.all(np.abs(err) < bound), (np.degrees(err), np.degrees(bound))
    # the rest window levels the parked IMU and reads the Earth rate as the "bias"
    rest_truth = quat_to_euler(truth.q_nb[_truth_at(truth, a.rest_end)])
    np.testing.assert_allclose(a.rest_rpy, rest_truth[:2], atol=1e-9)
    assert np.linalg.norm(a.gyro_bias) == pytest.approx(earth.OMEGA_EARTH, rel=1e-6)
    # the IMU position from the antenna through the lever arm, and the fix velocity
    assert np.abs(ned_displacement(a.lla, truth.lla[k])).max() < 1e-3
    np.testing.assert_allclose(a.v_n, truth.v_n[k], atol=1e-9)
    assert a.disturbed_blocks == 0 and a.rest_blocks == 30


def test_noisy_mems_imu_beats_the_gnss_velocity_alignment(rng):
    truth, ideal, fixes = _drive()
    ba = np.array([1.0, -1.5, 2.0]) * 1e-3 * G           # accelerometer bias [m/s^2]
    bg = D(np.array([0.05, -0.03, 0.04]))                # gyro bias [rad/s]
    vrw, arw = 100e-6 * G, D(0.01)                       # 100 ug/sqrt(Hz), 0.01 deg/s/sqrt(Hz)
    imu = _corrupt(ideal, rng, ba, bg, vrw, arw)
    a = align_level_then_gnss(imu, fixes, LEVER, REST, 5.0, forward_b=_forward())
    k = _truth_at(truth, a.time)
    rpy_true = quat_to_euler(truth.q_nb[k])
    err = np.degrees(wrap_angle(a.rpy - rpy_true))
    carry = a.time - a.rest_end
    # Tolerance: levelling takes the accelerometer bias as tilt, |b_horizontal| / g
    # (0.1 deg here, the level frame's horizontal part of b, bounded by |b|); the gyro
    # bias is known to arw / sqrt(T_rest) and its error grows over the carry, the
    # carry adds arw sqrt(T_carry); the white accelerometer noise averages to
    # vrw / sqrt(T_rest) / g. Four sigma of those plus the Earth-rate bound.
    c_bn_rest = quat_to_dcm(truth.q_nb[_truth_at(truth, a.rest_end)]).T
    b_level = np.linalg.norm((c_bn_rest.T @ ba)[:2]) / G
    sigma = np.sqrt((arw / np.sqrt(REST) * carry) ** 2 + arw ** 2 * carry + (vrw / np.sqrt(REST) / G) ** 2)
    tol = np.degrees(b_level + 4 * sigma + 2 * earth.OMEGA_EARTH * carry)
    assert np.all(np.abs(err[:2]) < tol), (err, tol)      # tol = 0.2 deg
    # heading: the mounting yaw (4 deg) is taken out; tilt errors couple in little
    assert abs(err[2]) < 2 * tol, (err, tol)
    # gyro bias from the rest window: bias plus the Earth rate, to arw / sqrt(T_rest)
    w_ie_b = c_bn_rest @ earth.earth_rate_ned(truth.lla[0, 0])
    assert np.all(np.abs(a.gyro_bias - bg - w_ie_b) < 4 * arw / np.sqrt(REST))
    # The gnss-velocity mode puts roll at zero and pitch and yaw on the path: its error is
    # the tilt of the IMU (several degrees here) and the mounting yaw.
    m = align_from_gnss_velocity(fixes, LEVER, 5.0)
    err_v = np.degrees(wrap_angle(quat_to_euler(m.q_nb) - quat_to_euler(truth.q_nb[m.index * 25])))
    assert m.index == a.index
    assert np.hypot(*err[:2]) < 0.2 * np.hypot(*err_v[:2]), (err, err_v)
    assert abs(err[2]) < 0.2 * abs(err_v[2]), (err, err_v)
    # without the mounting the body x axis is taken as forward: the heading is off by about
    # the mounting yaw, roll and pitch stay right
    b = align_level_then_gnss(imu, fixes, LEVER, REST, 5.0)
    assert abs(np.degrees(wrap_angle(b.rpy[2] - rpy_true[2]))) > 3.0
    np.testing.assert_allclose(b.rpy[:2], a.rpy[:2], atol=1e-12)


def test_rest_checks_and_library_errors():
    truth, imu, fixes = _drive(still_until=20.0)     # pulls away at 20 s
    with pytest.raises(ArgumentError, match="rest_duration.*not at rest over the first 25 s.*accelerating"):
        align_level_then_gnss(imu, fixes, LEVER, 25.0, 5.0)
    # a window ending before the car moves is fine
    a = align_level_then_gnss(imu, fixes, LEVER, 19.0, 5.0, forward_b=_forward())
    assert a.time == pytest.approx(25.0)   # 5 m/s after 5 s at 1 m/s^2
    with pytest.raises(ArgumentError, match="rest_duration.*holds \\d+ IMU samples"):
        align_level_then_gnss(imu, fixes, LEVER, 0.05, 5.0)
    with pytest.raises(ArgumentError, match="min_speed.*sim.pos.*reaches 50 m/s"):
        align_level_then_gnss(imu, fixes, LEVER, 19.0, 50.0)
    with pytest.raises(ArgumentError, match="forward_b.*vertical"):
        align_level_then_gnss(imu, fixes, LEVER, 19.0, 5.0, forward_b=[0.0, 0.0, 1.0])
    # brief jolts (a door closing) in up to a fifth of the blocks are tolerated
    dv = imu.dvel.copy()
    t = imu.time
    jolt = (t > 5.0) & (t < 7.0)
    dv[jolt, 2] += 0.5 * np.sin(2 * np.pi * 5 * t[jolt]) * imu.dt[jolt]
    jolted = ImuData(t, imu.dt, imu.dtheta, dv, source="sim.imu")
    assert align_level_then_gnss(jolted, fixes, LEVER, 19.0, 5.0).disturbed_blocks == 2
    dv[(t > 2.0) & (t < 8.0), 2] += 0.5 * np.sin(2 * np.pi * 5 * t[(t > 2.0) & (t < 8.0)]) * 0.01
    with pytest.raises(ArgumentError, match="rest_duration.*blocks move"):
        align_level_then_gnss(ImuData(t, imu.dt, imu.dtheta, dv, source="sim.imu"), fixes, LEVER, 19.0, 5.0)


def _dataset(tmp_path, alignment: str, aiding: str = ""):
    text = (Path(__file__).resolve().parents[1] / "src/mixnav/config/datasets/drive-0708-plain.toml").read_text()
    start = text.index("[alignment]")
    end = text.index("[[methods]]")
    text = text[:start] + "[alignment]\n" + alignment + '''
attitude_sigma = ["1 deg", "1 deg", "3 deg"]
velocity_sigma = ["0.1 m/s", "0.1 m/s", "0.1 m/s"]
position_sigma = ["0.05 m", "0.05 m", "0.05 m"]
''' + aiding + "\n" + text[end:]
    p = tmp_path / "ds.toml"
    p.write_text(text)
    return load_dataset(str(p))[0]


def test_initial_state_uses_the_mounting_and_starts_the_gyro_bias(tmp_path):
    truth, imu, fixes = _drive()
    mount_deg = ", ".join(f'"{x} deg"' for x in np.degrees(MOUNTING))
    ds = _dataset(tmp_path, 'method = "level-then-gnss"\nstatic_duration = "30 s"\nmin_speed = "5 m/s"',
                  f"[aiding]\nvehicle_mounting = [{mount_deg}]")
    init = initial_state(ds, imu, fixes, LEVER)
    a = align_level_then_gnss(imu, fixes, LEVER, REST, 5.0, forward_b=_forward())
    assert init.time == a.time
    np.testing.assert_allclose(init.nav[:4], a.q_nb, atol=1e-12)   # the mounting read from text
    np.testing.assert_array_equal(init.sensor0[:3], a.gyro_bias)
    assert not np.any(init.sensor0[3:])


@pytest.mark.parametrize("alignment, aiding, key, match", [
    ('static_duration = "0.05 s"', "", "alignment.static_duration", "holds \\d+ IMU samples"),
    ('static_duration = "35 s"', "", "alignment.static_duration", "not at rest over the first 35 s"),
    ('min_speed = "50 m/s"', "", "alignment.min_speed", "reaches 50 m/s"),
    ("", '[aiding]\nvehicle_mounting = ["0 deg", "90 deg", "0 deg"]', "aiding.vehicle_mounting", "vertical"),
])
def test_config_errors_name_their_key(tmp_path, alignment, aiding, key, match):
    truth, imu, fixes = _drive()
    ds = _dataset(tmp_path, 'method = "level-then-gnss"\n' + alignment, aiding)
    with pytest.raises(ConfigError, match=match) as exc:
        initial_state(ds, imu, fixes, LEVER)
    assert exc.value.key == key and f"key '{key}'" in str(exc.value)


def _carry(c_nb, imu, bias, t0, t1):
    """Attitude ``c_nb`` at ``t0`` carried to ``t1`` by the bias-compensated increments."""
    s = (imu.time > t0) & (imu.time <= t1)
    for rv in imu.dtheta[s] - bias * imu.dt[s][:, None]:
        c_nb = c_nb @ Rotation.from_rotvec(rv).as_matrix()
    return c_nb


def test_drive0708_roll_and_pitch_agree_with_the_smoothed_attitude():
    """drive-0708 (parked 34 s, then off): the aided filter's RTS-smoothed attitude does not
    depend on the alignment (it is the same with either method), so it judges the aligned
    roll and pitch. Measured (both carried with the gyros to the smoother's first epochs):
    level-then-gnss 0.73 / 0.11 deg off in roll / pitch, gnss-velocity 2.04 / -2.29 deg."""
    if not (DATA_DIR / "drive-0708" / "imu_1934.csv").exists():
        pytest.skip(f"real data not found under {DATA_DIR}")
    from mixnav.attitude import dcm_to_euler
    from mixnav.experiment.process import process
    ds, src, _ = load_dataset("drive-0708-aided")
    ds = ds.model_copy(update={"alignment": ds.alignment.model_copy(update={"method": "level-then-gnss"})})
    po = process(ds, src, str(DATA_DIR / "drive-0708"))
    smoothed = po.results["aided-smoothed"]
    init = po.init
    m = align_from_gnss_velocity(po.fixes, po.lever, ds.alignment.min_speed, after=po.imu.start_time)
    assert m.time == init.time
    bias = init.sensor0[:3]
    for j in range(4):    # the first second after the alignment
        ref = quat_to_euler(smoothed.nav[j, :4])
        new = dcm_to_euler(_carry(quat_to_dcm(init.nav[:4]), po.imu, bias, init.time, smoothed.time[j]))
        old = dcm_to_euler(_carry(quat_to_dcm(m.q_nb), po.imu, bias, init.time, smoothed.time[j]))
        e_new, e_old = np.degrees(new - ref)[:2], np.degrees(old - ref)[:2]
        # Tolerance 1 deg per axis: the 10 mg accelerometer bias sigma of this unit is
        # 0.57 deg of levelling error, and the 22 s carry with its noisy pitch gyro
        # (0.04-0.07 deg/s/sqrt(Hz), bias wander ~0.01 deg/s) adds a few tenths.
        assert np.all(np.abs(e_new) < 1.0), (j, e_new)
        assert np.hypot(*e_new) < 0.5 * np.hypot(*e_old), (j, e_new, e_old)
