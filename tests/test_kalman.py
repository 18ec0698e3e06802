"""The Kalman correction against filterpy, and its failure mode."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from mixnav.filters.kalman import OK, S_NOT_POSITIVE_DEFINITE, kalman_update


@pytest.mark.parametrize("n,m", [(15, 6), (17, 12), (21, 3)])
def test_matches_filterpy(rng, n, m):
    a = rng.normal(size=(n, n))
    P = a @ a.T + np.eye(n)
    H = rng.normal(size=(m, n))
    b = rng.normal(size=(m, m))
    R = b @ b.T + 0.1 * np.eye(m)
    x, z = rng.normal(size=n), rng.normal(size=m)
    xp, Pp, nis, status = kalman_update(x, P, z, H, R)
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x, kf.P, kf.H, kf.R = x.copy(), P.copy(), H, R
    kf.update(z)
    assert status == OK
    np.testing.assert_allclose(xp, kf.x, atol=1e-10)
    np.testing.assert_allclose(Pp, kf.P, atol=1e-10)
    y = z - H @ x
    np.testing.assert_allclose(nis, y @ np.linalg.solve(H @ P @ H.T + R, y), rtol=1e-10)
    np.testing.assert_allclose(Pp, Pp.T, atol=0)


def test_not_positive_definite_innovation_is_reported_not_applied():
    P = np.eye(3)
    H = np.eye(3)
    R = -2.0 * np.eye(3)  # S = P + R is negative definite
    x = np.zeros(3)
    xp, Pp, nis, status = kalman_update(x, P, np.ones(3), H, R)
    assert status == S_NOT_POSITIVE_DEFINITE
    np.testing.assert_array_equal(Pp, P)
    np.testing.assert_array_equal(xp, x)


@pytest.mark.parametrize("n,m,full_r", [(15, 6, False), (17, 3, True), (21, 1, False)])
def test_innovation_logdet_matches_slogdet(rng, n, m, full_r):
    from mixnav.filters.kalman import innovation_logdet
    a = rng.normal(size=(n, n))
    P = a @ a.T + np.eye(n)
    H = rng.normal(size=(m, n)) * (rng.random((m, n)) < 0.3)     # sparse, as the models' H are
    b = rng.normal(size=(m, m))
    r = b @ b.T + 0.1 * np.eye(m) if full_r else rng.random(m) + 0.01
    R = r if full_r else np.diag(r)
    sign, expect = np.linalg.slogdet(H @ P @ H.T + R)
    assert sign > 0
    assert innovation_logdet(P, H, r) == pytest.approx(expect, rel=1e-12, abs=1e-12)


def test_innovation_logdet_is_nan_when_s_is_not_positive_definite():
    from mixnav.filters.kalman import innovation_logdet
    P, H = np.zeros((3, 3)), np.eye(2, 3)
    assert np.isnan(innovation_logdet(P, H, np.array([1.0, -0.5])))
