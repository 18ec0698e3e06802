"""The unscented Kalman filter (M7): oracles, invariants and a seeded consistency check.

- the unscented transform of a linear map is exact (mean and covariance);
- on a linear-Gaussian model the UKF's kernels give the Kalman filter to round-off;
- the difference map inverts the engine's feedback map;
- on the INS with small errors the UKF and the EKF agree;
- the UKF's position NEES is in its band on a simulated drive;
- bad unscented parameters are refused naming the key; a covariance that is not
  positive definite is repaired and counted.
"""

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.errors import ArgumentError
from mixnav.experiment.run import solution_table
from mixnav.filters._ukf_kernels import (measurement_moments, sigma_deviations, ukf_moments, ukf_sigma, vb_correct,
                                         weighted_moments)
from mixnav.ins._batch_kernels import nav_difference, propagate_members
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.filters.ukf import UnscentedEstimator, UnscentedKalmanFilter, ut_weights
from mixnav.ins._error_kernels import apply_feedback
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate

PARAMS = [(1.0, 2.0, 0.0), (0.6, 2.0, 0.0), (1.0, 0.0, 3.0), (0.8, 2.0, 1.0)]


def _spd(rng, n):
    A = rng.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


@pytest.mark.parametrize("alpha,beta,kappa", PARAMS)
def test_the_unscented_transform_of_a_linear_map_is_exact(alpha, beta, kappa):
    rng = np.random.default_rng(1)
    n, m = 7, 4
    x = rng.standard_normal(n)
    P = _spd(rng, n)
    A = rng.standard_normal((m, n))
    b = rng.standard_normal(m)
    wm, wc, c = ut_weights(n, alpha, beta, kappa)
    D = np.empty((2 * n + 1, n))
    sigma_deviations(x, np.linalg.cholesky(P), c, D)
    Y = D @ A.T + b
    mean, cov = np.empty(m), np.empty((m, m))
    weighted_moments(np.ascontiguousarray(Y), wm, wc, mean, cov)
    # the centre's extra covariance weight (1 - alpha^2 + beta) multiplies (y_0 - mean) = 0
    np.testing.assert_allclose(mean, A @ x + b, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cov, A @ P @ A.T, rtol=1e-11, atol=1e-11)


def test_on_a_linear_gaussian_model_the_ukf_is_the_kalman_filter():
    """Constant velocity in 2-D, position measured: the UKF built from the module's
    kernels (sigma points, moments, correction) against the textbook KF."""
    rng = np.random.default_rng(2)
    T = 0.5
    F = np.eye(4)
    F[0, 2] = F[1, 3] = T
    Q = np.diag([1e-3, 1e-3, 1e-2, 1e-2])
    H = np.zeros((2, 4))
    H[0, 0] = H[1, 1] = 1.0
    r = np.array([0.5, 0.8])
    n = 4
    wm, wc, c = ut_weights(n, 0.9, 2.0, 0.5)
    x_k, P_k = np.zeros(n), np.diag([4.0, 4.0, 1.0, 1.0])
    x_u, P_u = x_k.copy(), P_k.copy()
    D = np.empty((2 * n + 1, n))
    truth = np.array([1.0, -2.0, 0.3, 0.1])
    worst = 0.0
    for k in range(60):
        truth = F @ truth + rng.multivariate_normal(np.zeros(n), Q)
        y = H @ truth + rng.standard_normal(2) * np.sqrt(r)
        # Kalman filter
        x_k, P_k = F @ x_k, F @ P_k @ F.T + Q
        S = H @ P_k @ H.T + np.diag(r)
        K = np.linalg.solve(S, H @ P_k).T
        x_k = x_k + K @ (y - H @ x_k)
        P_k = P_k - K @ S @ K.T
        # UKF
        sigma_deviations(x_u, np.linalg.cholesky(P_u), c, D)
        Dp = np.ascontiguousarray(D @ F.T)
        weighted_moments(Dp, wm, wc, x_u, P_u)
        P_u += Q
        sigma_deviations(x_u, np.linalg.cholesky(P_u), c, D)
        innov, Pyy, Pxy = measurement_moments(D, np.ascontiguousarray(D @ H.T), y, wm, wc)
        x_u, P_u, nis, status, *_ = vb_correct(x_u, P_u, Pxy, Pyy, Pyy, innov, r, r, r, False, 1, 0.0, 1e4)
        assert status == 0
        worst = max(worst, np.abs(x_u - x_k).max(), np.abs(P_u - P_k).max())
    assert worst < 1e-10, worst


def test_the_difference_map_inverts_the_feedback():
    rng = np.random.default_rng(3)
    lay = get_layout(15).as_array()
    for _ in range(50):
        nav = np.empty(10)
        q = rng.standard_normal(4)
        nav[0:4] = q / np.linalg.norm(q) * np.sign(q[0])
        nav[4:7] = rng.standard_normal(3) * 50
        nav[7], nav[8], nav[9] = rng.uniform(-1.3, 1.3), rng.uniform(-3, 3), rng.uniform(-100, 9000)
        d = np.zeros(15)
        d[0:3] = rng.standard_normal(3) * 0.3      # up to about a radian
        d[3:6] = rng.standard_normal(3) * 5
        d[6:9] = rng.standard_normal(3) * 100
        moved = nav.copy()
        apply_feedback(moved, np.zeros(12), np.zeros(2), d, lay)
        out = np.empty(9)
        nav_difference(moved, nav, out)
        np.testing.assert_allclose(out, d[:9], rtol=0, atol=1e-9)


def test_a_linear_propagation_of_the_sensor_block_through_the_kernel():
    """With no IMU motion to speak of, the sensor deviations only decay (Gauss-Markov):
    the kernel's mean and covariance of the bias block are exp(-T/tau) x and f^2 P."""
    lay = get_layout(15)
    n = lay.n
    N = 2 * n + 1
    wm, wc, c = ut_weights(n)
    nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.7, 0.2, 100.0])
    x = np.zeros(n)
    x[9:15] = 1e-5
    P = np.eye(n) * 1e-8
    tau = np.array([100.0, 200.0, np.inf, np.inf])
    K = 10
    dth, dv, dt = np.zeros((K, 3)), np.zeros((K, 3)), np.full(K, 0.01)
    dv[:, 2] = -9.8 * 0.01
    xo, Po = np.empty(n), np.empty((n, n))
    D, Dn = np.empty((N, n)), np.empty((N, n))
    assert ukf_sigma(x, P, c, np.empty((n, n)), D)
    propagate_members(nav, np.zeros(6), np.zeros(12), D, dth, dv, dt, 0, lay.as_array(), tau, 0.1,
                      np.empty((N + 1, 10)), np.empty((N + 1, 6)), np.empty((N + 1, 12)), Dn)
    ukf_moments(Dn, wm, wc, np.zeros((n, n)), xo, Po)
    f = np.r_[np.full(3, np.exp(-0.1 / 100)), np.full(3, np.exp(-0.1 / 200))]
    np.testing.assert_allclose(xo[9:15], 1e-5 * f, rtol=1e-12)
    np.testing.assert_allclose(np.diag(Po)[9:15], 1e-8 * f ** 2, rtol=1e-9)


@pytest.fixture(scope="module")
def demo():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    return sc, sim, lever


def _run(filt, sim, lever):
    return filt.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, filt.layout)])


@pytest.fixture(scope="module")
def runs(demo):
    sc, sim, lever = demo
    lay = get_layout(15)
    out = {"ekf": _run(ErrorStateEkf(lay, sim.imu_model), sim, lever),
           "ukf": _run(UnscentedKalmanFilter(lay, sim.imu_model), sim, lever),
           "ukf-full-rate": _run(UnscentedKalmanFilter(lay, sim.imu_model, substeps=0), sim, lever)}
    return {k: (r, solution_table(r, sim.truth)) for k, r in out.items()}


def test_on_the_ins_with_small_errors_the_ukf_and_the_ekf_agree(runs):
    """loose-demo's errors are small (0.1-1 deg, metres): both filters linearise well, so
    they should give the same solution up to the second-order terms the UKF keeps.
    Tolerances: 5 cm between the two position solutions (the GNSS noise is 1.5 m),
    3 mm/s in velocity (0.05 m/s noise), 2 % in every state's 1-sigma after the first
    60 s (the transient from the 5 deg initial heading is where they may differ).
    Measured: 2.0 cm, 0.7 mm/s, 0.2 %."""
    (re, te), (ru, tu) = runs["ekf"], runs["ukf"]
    dpos = np.abs(tu[["err_n_m", "err_e_m", "err_d_m"]].to_numpy() - te[["err_n_m", "err_e_m", "err_d_m"]].to_numpy())
    dvel = np.abs(tu[["err_vn_mps", "err_ve_mps", "err_vd_mps"]].to_numpy()
                  - te[["err_vn_mps", "err_ve_mps", "err_vd_mps"]].to_numpy())
    assert dpos.max() < 0.05, dpos.max()
    assert dvel.max() < 0.003, dvel.max()
    late = re.time > re.time[0] + 60
    ratio = ru.sigma[late] / re.sigma[late]
    assert np.abs(ratio - 1).max() < 0.02, np.abs(ratio - 1).max(axis=0)


def test_merged_substeps_agree_with_the_full_rate_sigma_points(runs):
    """The sigma points mechanized over 4 merged sub-intervals (the default) against
    every IMU increment: the merging error is common to the points and the reference
    and cancels in the difference (docs/ukf.md); 5 mm, 0.1 % of each 1-sigma
    (measured: 1 mm, 0.02 %; 0.1 mm with 10 sub-intervals)."""
    (r0, t0), (r1, t1) = runs["ukf-full-rate"], runs["ukf"]
    cols = ["err_n_m", "err_e_m", "err_d_m"]
    assert np.abs(t0[cols].to_numpy() - t1[cols].to_numpy()).max() < 0.005
    assert np.abs(r1.sigma / r0.sigma - 1).max() < 0.001


def test_ukf_nees_is_in_band_on_a_simulated_drive(runs):
    """Position NEES averaged over the run's N epochs: for a consistent filter its mean
    is 3 with a standard error of about sqrt(2*3/N_eff); with N = 600 epochs of strongly
    correlated errors (N_eff ~ 30) the 95 % band is about [2, 4.2]: we take [1.5, 4.5]."""
    r, t = runs["ukf"]
    nees = float(t["nees_pos"].mean())
    assert 1.5 < nees < 4.5, nees
    assert r.recoveries["sigma_repair"] == 0


def test_the_ukf_reports_through_the_engine(runs):
    r, _ = runs["ukf"]
    assert np.isfinite(r.nis).all() and len(r.nis) > 500
    assert r.recoveries["rejected_absurd"] == 0


@pytest.mark.parametrize("kw,key", [(dict(alpha=0.3), "alpha"), (dict(alpha=0.0), "alpha"),
                                    (dict(kappa=-30.0), "kappa"), (dict(beta=float("nan")), "beta"),
                                    (dict(substeps=-1), "substeps"), (dict(absurd_sigma=0.0), "absurd_sigma")])
def test_bad_unscented_parameters_name_the_key(kw, key):
    with pytest.raises(ArgumentError) as e:
        UnscentedKalmanFilter(get_layout(21), _imu(), **kw)
    assert e.value.argument == key


def test_the_centre_weight_rule():
    # alpha = 1, beta = 2, kappa = 0: lambda = 0, wm0 = 0, wc0 = 2
    wm, wc, c = ut_weights(21, 1.0)
    assert wm[0] == 0.0 and wc[0] == 2.0 and c == np.sqrt(21)
    assert abs(wm.sum() - 1.0) < 1e-14
    # alpha^2 = 0.268 is the edge of wc0 >= 0 with beta = 2, kappa = 0 (4 - a^2 - 1/a^2 = 0)
    ut_weights(21, 0.52)
    with pytest.raises(ArgumentError):
        ut_weights(21, 0.51)


def test_a_covariance_that_is_not_positive_definite_is_repaired_and_counted(demo):
    sc, sim, lever = demo
    lay = get_layout(15)
    est = UnscentedEstimator()
    from mixnav.ins.strapdown import StrapdownMotion
    motion = StrapdownMotion(lay, sim.imu_model)
    P0 = motion.initial_covariance(sim.init)
    est.init(motion, P0, 0, np.random.default_rng(0))
    est.P[0, 1] = est.P[1, 0] = 2 * np.sqrt(est.P[0, 0] * est.P[1, 1])   # correlation 2: indefinite
    D, navs = est.sigma_points(sim.init.nav)
    assert est.counts["sigma_repair"] == 1
    assert np.isfinite(D).all() and np.linalg.eigvalsh(est.P).min() > 0


def _imu():
    from mixnav.ins.imu_model import ImuErrorModel
    return ImuErrorModel()


# --- tight coupling ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def tight_runs(tmp_path_factory):
    """tight-demo with its tight EKF and the same method as a UKF."""
    from mixnav.config.loader import resolve
    from mixnav.experiment.run import run_scenario
    text, _ = resolve("tight-demo")
    text = text[:text.index("[[methods]]")] + """
[[methods]]
name = "tight"
type = "tight-ekf"
states = 17

[[methods]]
name = "tight-ukf"
type = "tight-ekf"
estimator = "ukf"
states = 17
"""
    p = tmp_path_factory.mktemp("tight") / "t.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    out = run_scenario(sc, src, seed=2)
    return out, {k: solution_table(r, out.sim.truth) for k, r in out.results.items()}


def test_tight_batched_h_matches_the_rows_and_their_jacobian(tight_runs):
    """The tight model's predict_batch: y - h(x) at the nominal is the rows' innovation,
    and a small error dx (clock included) moves h by H dx."""
    from mixnav.attitude import quat_multiply, rotvec_to_quat
    from mixnav.geodesy.frames import displace
    from mixnav.measurements.tight import TightGnss
    out, _ = tight_runs
    lay = get_layout(17)
    model = TightGnss(out.sim.observations, np.array([0.5, 0.2, -1.0]), lay)
    i = 150
    kt = int(np.searchsorted(out.sim.truth.time, model.times[i] - 1e-9))
    tr = out.sim.truth
    nav = np.concatenate([tr.q_nb[kt], tr.v_n[kt], tr.lla[kt]])
    w, clock = np.array([0.01, -0.02, 0.3]), np.array([3.0, 0.2])
    rows = model.rows(i, nav, w, clock)
    y, Y, R = model.predict_batch(i, nav[None], w, clock)
    np.testing.assert_allclose(y - Y[0], rows.z, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(R, rows.R)
    steps = {**{k: 1e-4 for k in range(3)}, **{k: 1e-3 for k in range(3, 9)},
             **{k: 1e-5 for k in range(9, 12)}, 15: 1e-3, 16: 1e-3}
    for k, eps in steps.items():
        dx = np.zeros(17)
        dx[k] = eps
        q = quat_multiply(rotvec_to_quat(dx[0:3]), nav[0:4])
        true = np.concatenate([q, nav[4:7] + dx[3:6], displace(nav[7:10], dx[6:9])])
        _, Yt, _ = model.predict_batch(i, true[None], w - dx[9:12], clock + dx[15:17])
        fd = (Yt[0] - Y[0]) / eps
        np.testing.assert_allclose(fd, rows.H[:, k], rtol=2e-3, atol=2e-3 * max(1.0, np.abs(fd).max()))


def test_the_tight_ukf_agrees_with_the_tight_ekf(tight_runs):
    """Pseudorange + Doppler, 17 states (clock propagated linearly by the kernel, each
    sigma point's clock in h): the UKF and the EKF agree as on the loose model. Tolerances:
    10 cm in position (3 m pseudorange noise; the 60 s with 3 satellites included), 5 mm/s,
    2 % in every 1-sigma after the first minute (measured: 3.7 cm, 1.4 mm/s, 0.3 %). NEES
    as the loose test (measured 2.53, the EKF's 2.53)."""
    out, tabs = tight_runs
    te, tu = tabs["tight"], tabs["tight-ukf"]
    cols = ["err_n_m", "err_e_m", "err_d_m"]
    vcols = ["err_vn_mps", "err_ve_mps", "err_vd_mps"]
    assert np.abs(tu[cols].to_numpy() - te[cols].to_numpy()).max() < 0.10
    assert np.abs(tu[vcols].to_numpy() - te[vcols].to_numpy()).max() < 0.005
    re, ru = out.results["tight"], out.results["tight-ukf"]
    late = re.time > re.time[0] + 60
    assert np.abs(ru.sigma[late] / re.sigma[late] - 1).max() < 0.02
    assert 1.5 < tu["nees_pos"].mean() < 4.5
