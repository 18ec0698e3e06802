"""Attitude conversions: oracle (scipy Rotation) and round trips."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mixnav import attitude as att


@pytest.fixture
def rpy(rng):
    a = rng.uniform(-1.0, 1.0, (500, 3)) * [np.pi, 1.5, np.pi]
    return a


def test_euler_to_dcm_matches_scipy_zyx(rpy):
    ref = Rotation.from_euler("ZYX", rpy[:, ::-1]).as_matrix()
    np.testing.assert_allclose(att.euler_to_dcm(rpy), ref, atol=1e-14)


def test_quaternion_matches_scipy_scalar_last(rpy):
    ref = Rotation.from_euler("ZYX", rpy[:, ::-1]).as_quat()  # x, y, z, w
    ref = np.roll(ref, 1, axis=-1)
    ref *= np.sign(ref[:, :1])
    np.testing.assert_allclose(att.euler_to_quat(rpy), ref, atol=1e-14)


def test_rotvec_matches_scipy(rng):
    rv = rng.normal(size=(500, 3))
    np.testing.assert_allclose(att.rotvec_to_dcm(rv), Rotation.from_rotvec(rv).as_matrix(), atol=1e-14)


def test_round_trips(rpy, rng):
    c = att.euler_to_dcm(rpy)
    np.testing.assert_allclose(att.dcm_to_euler(c), rpy, atol=1e-12)
    np.testing.assert_allclose(att.quat_to_dcm(att.dcm_to_quat(c)), c, atol=1e-14)
    np.testing.assert_allclose(att.quat_to_euler(att.euler_to_quat(rpy)), rpy, atol=1e-12)
    rv = rng.normal(size=(500, 3))
    rv *= np.minimum(1.0, 3.0 / np.linalg.norm(rv, axis=1))[:, None]  # angles below pi
    np.testing.assert_allclose(att.quat_to_rotvec(att.rotvec_to_quat(rv)), rv, atol=1e-12)


def test_small_rotation_vectors_are_exact():
    rv = np.array([[1e-12, -2e-12, 3e-12], [0.0, 0.0, 0.0]])
    q = att.rotvec_to_quat(rv)
    np.testing.assert_allclose(q[:, 1:], rv / 2, atol=1e-24)
    np.testing.assert_allclose(att.quat_to_rotvec(q), rv, atol=1e-24)


def test_quaternion_product_composes_rotations(rng):
    p, q = att.rotvec_to_quat(rng.normal(size=(2, 100, 3)))
    np.testing.assert_allclose(att.quat_to_dcm(att.quat_multiply(p, q)),
                               att.quat_to_dcm(p) @ att.quat_to_dcm(q), atol=1e-14)


def test_attitude_error_is_the_rotation_from_estimate_to_truth(rng):
    q_true = att.rotvec_to_quat(rng.normal(size=3))
    phi = np.array([1e-3, -2e-3, 5e-4])
    q_est = att.quat_multiply(att.rotvec_to_quat(-phi), q_true)
    np.testing.assert_allclose(att.attitude_error(q_est, q_true), phi, atol=1e-15)


def test_skew_is_cross_product(rng):
    a, b = rng.normal(size=(2, 10, 3))
    np.testing.assert_allclose(att.skew(a) @ b[..., None], np.cross(a, b)[..., None], atol=1e-15)
