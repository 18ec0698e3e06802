"""The SIR particle filter (issue 19, first step): oracles and seeded checks.

- systematic resampling is unbiased (mean count of particle i is N w_i);
- on a linear-Gaussian model the particle filter's mean and covariance converge to
  the Kalman filter's at close to 1/sqrt(N);
- a measurement no particle can explain is a counted degeneracy, never a NaN;
- on loose-demo the PF's position error and NEES against the EKF's (measured bands);
- the same seed gives the same run, on one or two numba threads, serial or parallel
  kernels (bitwise); bad settings name their key;
- the fused propagation kernel against the first, unfused one; the compiled weights and
  moments against numpy.
"""

import numba
import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.engine.status import ABSURD, OK
from mixnav.errors import ArgumentError, ConfigError
from mixnav.experiment.run import solution_table
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.filters import _pf_kernels as K
from mixnav.ins import _particle_kernels as PK
from mixnav.filters.particle import (ParticleFilter, _sqrt_psd, linear_gaussian_particles,
                                     normalise_log_weights, systematic_resample)
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate


def test_systematic_resampling_is_unbiased():
    """Over M = 20000 seeded offsets the mean count of particle i is N w_i. A systematic
    count is floor(N w_i) or that + 1, so its standard deviation is at most 1/2 and the
    standard error of the mean count at most 0.5 / sqrt(M) = 0.0035; tolerance 5 of
    those (0.018). Each count is also checked to be floor or floor + 1."""
    rng = np.random.default_rng(11)
    N, M = 25, 20000
    w = rng.dirichlet(np.full(N, 0.3))
    counts = np.zeros((M, N))
    for k in range(M):
        counts[k] = np.bincount(systematic_resample(w, rng.random()), minlength=N)
    se = 0.5 / np.sqrt(M)
    np.testing.assert_allclose(counts.mean(axis=0), N * w, rtol=0, atol=5 * se)
    lo = np.floor(N * w)
    assert ((counts == lo) | (counts == lo + 1)).all()
    assert (counts.sum(axis=1) == N).all()


def test_the_systematic_merge_pass_equals_the_binary_search():
    """pf_systematic (one merge pass) gives the indices of searchsorted on the cumulative
    weights (last bin closed at 1), with zero weights, one dominant weight and offsets
    at 0 and just below 1."""
    rng = np.random.default_rng(2)
    for N in (1, 2, 7, 1000):
        for trial in range(20):
            w = rng.dirichlet(np.full(N, 0.2))
            if trial % 3 == 0:
                w[rng.random(N) < 0.5] = 0.0
                w = w / w.sum() if w.sum() > 0 else np.full(N, 1.0 / N)
            for u0 in (0.0, rng.random(), 1.0 - 1e-12):
                c = np.cumsum(w)
                c[-1] = 1.0
                ref = np.minimum(np.searchsorted(c, (u0 + np.arange(N)) / N, side="right"), N - 1)
                np.testing.assert_array_equal(systematic_resample(w, u0), ref)


def _linear_estimator(N, P0, rng, threshold=0.5):
    return linear_gaussian_particles(P0, N, rng, resample_threshold=threshold)


def _linear_run(N, seed, data):
    F, Q, H, r, P0, ys = data
    est = _linear_estimator(N, P0, np.random.default_rng(seed))
    for y in ys:
        est.propagate_linear_noise(F, Q)
        corr = est.weigh(y, np.ascontiguousarray(est.D @ H.T), r)
        assert corr.status == OK
    return est.mean().copy(), est.covariance().copy()


def _kalman(data):
    F, Q, H, r, P0, ys = data
    x, P = np.zeros(len(P0)), P0.copy()
    for y in ys:
        x, P = F @ x, F @ P @ F.T + Q
        S = H @ P @ H.T + np.diag(r)
        K = np.linalg.solve(S, H @ P).T
        x, P = x + K @ (y - H @ x), P - K @ S @ K.T
    return x, P


def test_on_a_linear_gaussian_model_the_pf_converges_to_the_kalman_filter():
    """Constant velocity in 1-D (position measured, 8 epochs), the estimator's own
    propagation noise, weights, resampling and moments. Error per run: the Mahalanobis
    distance of the mean from the KF's plus the Frobenius norm of P_kf^-1/2 P P_kf^-1/2 - I;
    its RMS over 24 seeds at N = 250, 1000, 4000. Monte Carlo error falls as 1/sqrt(N):
    the fitted log-log slope must be in [-0.7, -0.3] and the error at 4000 below 0.1."""
    rng = np.random.default_rng(5)
    T = 1.0
    F = np.array([[1.0, T], [0.0, 1.0]])
    Q = np.array([[T ** 3 / 3, T ** 2 / 2], [T ** 2 / 2, T]]) * 0.05
    H = np.array([[1.0, 0.0]])
    r = np.array([0.5])
    P0 = np.diag([4.0, 1.0])
    truth = rng.multivariate_normal(np.zeros(2), P0)
    ys = []
    for _ in range(8):
        truth = F @ truth + rng.multivariate_normal(np.zeros(2), Q)
        ys.append(H @ truth + rng.standard_normal(1) * np.sqrt(r))
    data = (F, Q, H, r, P0, ys)
    xk, Pk = _kalman(data)
    Li = np.linalg.inv(np.linalg.cholesky(Pk))
    Ns = np.array([250, 1000, 4000])
    err = []
    for N in Ns:
        e = []
        for seed in range(24):
            x, P = _linear_run(int(N), 100 + seed, data)
            d = Li @ (x - xk)
            e.append(d @ d + np.sum((Li @ P @ Li.T - np.eye(2)) ** 2))
        err.append(np.sqrt(np.mean(e)))
    slope = np.polyfit(np.log(Ns), np.log(err), 1)[0]
    assert -0.7 <= slope <= -0.3, (slope, err)
    assert err[-1] < 0.1, err


def test_a_measurement_no_particle_can_explain_is_a_counted_degeneracy():
    rng = np.random.default_rng(3)
    est = _linear_estimator(200, np.eye(2), rng)
    H = np.array([[1.0, 0.0]])
    for y in (np.array([1e200]), np.array([1e6]), np.array([np.nan])):
        corr = est.weigh(y, np.ascontiguousarray(est.D @ H.T), np.array([1.0]))
        assert corr.status == ABSURD and not np.isfinite(corr.nis)
        assert np.isfinite(corr.dx).all() and (corr.dx == 0).all()
    assert est.counts["pf_degenerate"] == 3
    assert np.isfinite(est.D).all() and np.allclose(est.w, 1 / 200)
    assert np.isfinite(est.covariance()).all()
    # spread doubled each time (about the mean): 8 x the initial 1-sigma
    assert 5 < np.sqrt(est.covariance()[0, 0]) < 12
    # and a sensible measurement afterwards is used again
    corr = est.weigh(np.array([0.3]), np.ascontiguousarray(est.D @ H.T), np.array([1.0]))
    assert corr.status == OK and np.isfinite(corr.dx).all()


@pytest.fixture(scope="module")
def demo():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    return sim, lever


def _run(filt, sim, lever, seed=0):
    return filt.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, filt.layout)], rng=seed)


def _rms_pos(tab):
    return float(np.sqrt((tab[["err_n_m", "err_e_m", "err_d_m"]].to_numpy() ** 2).sum(axis=1).mean()))


@pytest.mark.parametrize("particles,seed,rms_band,nees_band", [
    (5000, 0, 1.3, 8.0),
    pytest.param(5000, 1, 1.3, 8.0, marks=pytest.mark.slow),
    pytest.param(5000, 2, 1.3, 8.0, marks=pytest.mark.slow)])
def test_pf_on_loose_demo_against_the_ekf(demo, particles, seed, rms_band, nees_band):    # -m slow: seeds 1, 2
    """Roughening 0.9 (the default), 5000 particles: position RMS 1.12, 1.09 and 0.96 x the
    EKF's 2.56 m and position NEES 4.2, 4.2 and 4.7 (the EKF's 3.8) for seeds 0, 1, 2
    (benchmarks/results/pf.md); band RMS <= 1.3 x, NEES in [1.5, 8]. The bands are a
    regression check on these fixed seeds, not a claim for every seed: a bootstrap filter
    in 15 states under-represents the attitude and sensor-bias spread (the static-parameter
    collapse), and its runs are seed-sensitive. Measured with this stop's draws: seed 3 at
    5000 particles gives 1.42 x and NEES 30; at 2000 particles seeds 0-7 span 0.88-2.51 x
    and NEES 4.8 to 8e11 (one of eight collapsed), so 2000 particles are not tested here
    (docs/particle.md)."""
    sim, lever = demo
    lay = get_layout(15)
    te = solution_table(_run(ErrorStateEkf(lay, sim.imu_model), sim, lever), sim.truth)
    f = ParticleFilter(lay, sim.imu_model, particles=particles)
    r = _run(f, sim, lever, seed)
    tp = solution_table(r, sim.truth)
    assert _rms_pos(tp) <= rms_band * _rms_pos(te), (_rms_pos(tp), _rms_pos(te))
    assert 1.5 < tp["nees_pos"].mean() < nees_band, tp["nees_pos"].mean()
    assert np.isfinite(r.nav).all() and f.estimator.counts["pf_degenerate"] == 0
    assert f.estimator.counts["pf_resampled"] > 0


def test_the_same_seed_gives_the_same_run(demo):
    """Serial kernels (no numba parallel): a seed fixes every draw."""
    sim, lever = demo
    lay = get_layout(15)
    a = _run(ParticleFilter(lay, sim.imu_model, particles=300), sim, lever, seed=7)
    b = _run(ParticleFilter(lay, sim.imu_model, particles=300), sim, lever, seed=7)
    c = _run(ParticleFilter(lay, sim.imu_model, particles=300), sim, lever, seed=8)
    np.testing.assert_array_equal(a.nav, b.nav)
    np.testing.assert_array_equal(a.sigma, b.sigma)
    assert not np.array_equal(a.nav, c.nav)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_one_or_two_threads_give_the_same_particles(demo):
    """parallel=True on 1 and on 2 numba threads, and the serial kernels: bitwise the same
    run (the random numbers are drawn outside the kernels, each particle's arithmetic
    reads only its own row, the sums over particles are in fixed chunks added in order).
    The first 120 s of loose-demo, 400 particles (resamplings and jitter included)."""
    sim, lever = demo
    lay = get_layout(15)
    old = numba.get_num_threads()
    runs = []
    try:
        for parallel, threads in ((True, 1), (True, 2), (False, 2)):
            numba.set_num_threads(threads)
            f = ParticleFilter(lay, sim.imu_model, particles=400, parallel=parallel)
            eng = f.engine([LooseGnss(sim.fixes, lever, lay)], rng=5)
            eng.start(sim.imu, sim.init)
            for _ in range(120):
                eng.step()
            runs.append((eng.nav.copy(), f.estimator.D.copy(), f.estimator.w.copy(),
                         f.estimator.counts["pf_resampled"]))
    finally:
        numba.set_num_threads(old)
    assert runs[0][3] > 0
    for other in runs[1:]:
        np.testing.assert_array_equal(runs[0][0], other[0])
        np.testing.assert_array_equal(runs[0][1], other[1])
        np.testing.assert_array_equal(runs[0][2], other[2])


def _ins_particles(N, seed=1):
    """Particles about a moving nominal over a 1 s, 100-increment block (17 states: clock)."""
    lay = get_layout(17)
    n = lay.n
    rng = np.random.default_rng(seed)
    nav0 = np.array([0.9, 0.1, 0.2, 0.3, 10.0, 2.0, -0.1, 0.6, 0.2, 100.0])
    nav0[:4] /= np.linalg.norm(nav0[:4])
    D = rng.standard_normal((N, n)) * np.r_[[1e-3] * 3, [0.1] * 3, [2.0] * 3, [1e-4] * 3, [1e-2] * 3, 5.0, 0.5]
    A = rng.standard_normal((n, n)) * 0.01
    SQ = _sqrt_psd(A @ A.T)
    Z = rng.standard_normal((N, n))
    dth = rng.standard_normal((100, 3)) * 1e-3
    dv = rng.standard_normal((100, 3)) * 0.01 + np.array([0.0, 0.0, -0.098])
    return (nav0, np.zeros(6), rng.standard_normal(12) * 1e-4, D, SQ, Z, dth, dv, np.full(100, 0.01),
            lay.as_array(), np.array([3600.0, 1800.0, np.inf, np.inf]))


@pytest.mark.parametrize("substeps", [0, 1, 4])
def test_the_fused_propagation_equals_the_first_kernel(substeps):
    """pf_step (fused per particle; serial and parallel) against pf_propagate (the UKF's
    member propagation, then the noise as a second loop): the same maps in a different
    loop order, so equal to round-off (the noise sum's order differs: 1e-12 relative to
    the deviations' scale)."""
    nav0, prev0, s0, D, SQ, Z, dth, dv, dt, la, tau = _ins_particles(257)
    N, n = D.shape
    ref = np.empty((N, n))
    PK.pf_propagate(nav0, prev0, s0, D, SQ, Z, dth, dv, dt, substeps, la, tau, 1.0, np.empty((N + 1, 10)),
                   np.empty((N + 1, 6)), np.empty((N + 1, 12)), ref)
    scale = np.abs(ref).max(axis=0)
    for step in (PK.pf_step, PK.pf_step_serial):
        g = np.empty((120, 7))
        out = np.empty((N, n))
        step(nav0, prev0, s0, D, np.ascontiguousarray(SQ.T), Z, dth, dv, dt, substeps, la, tau, 1.0,
             np.empty((N + 1, 10)), np.empty((N + 1, 6)), np.empty((N + 1, 12)), np.empty((N + 1, PK.SCRATCH)),
             g[:, 0:3], g[:, 3:6], g[:, 6], np.empty(4), out)
        assert (np.abs(out - ref) <= 1e-12 * scale).all(), np.abs(out - ref).max(axis=0) / scale


def test_compiled_weights_and_moments_against_numpy():
    """pf_log_weights against the log-likelihood and normalise_log_weights in numpy (with
    a particle of -inf prior weight, which must weigh 0) and its one-pass prior-weighted
    moments of the predictions (offset by 40: far from zero); pf_moments (both twins)
    against numpy's weighted average and covariance. Round-off only: 1e-12 (1e-11 for
    the covariances)."""
    rng = np.random.default_rng(4)
    N, m, n = 1001, 4, 6
    Y = rng.standard_normal((N, m)) * 3
    y, r = rng.standard_normal(m), rng.uniform(0.5, 2.0, m)
    logw0 = rng.standard_normal(N)
    logw0[7] = -np.inf
    logw, w = np.empty(N), np.empty(N)
    w0 = rng.dirichlet(np.ones(N))
    ym, Pyy = np.empty(m), np.empty((m, m))
    best, ess, nis = K.pf_log_weights(logw0, w0, y, Y + 40.0, r, logw, w, ym, Pyy)
    Y = Y + 40.0
    ym_np = np.average(Y, axis=0, weights=w0)
    np.testing.assert_allclose(ym, ym_np, rtol=1e-12)
    Pyy_np = (w0[:, None] * (Y - ym_np)).T @ (Y - ym_np)
    np.testing.assert_allclose(Pyy, Pyy_np, rtol=1e-11)
    e = y - ym_np
    assert nis == pytest.approx(e @ np.linalg.solve(Pyy_np + np.diag(r), e), rel=1e-10)
    q = (((y - Y) ** 2) / r).sum(axis=1)
    np.testing.assert_allclose(logw, logw0 - 0.5 * q, rtol=1e-12)
    wn, essn = normalise_log_weights(logw0 - 0.5 * q)
    np.testing.assert_allclose(w, wn, rtol=1e-12, atol=1e-300)
    assert w[7] == 0.0 and best == q.min() and ess == pytest.approx(essn, rel=1e-12)
    D = rng.standard_normal((N, n)) @ rng.standard_normal((n, n)) + 5.0
    xm = np.average(D, axis=0, weights=w)
    Pm = (w[:, None] * (D - xm)).T @ (D - xm)
    for mom in (K.pf_moments, K.pf_moments_serial):
        x, P = np.empty(n), np.empty((n, n))
        mom(D, w, x, P, np.empty((K.CHUNKS, n + n * n)))
        np.testing.assert_allclose(x, xm, rtol=1e-12)
        np.testing.assert_allclose(P, Pm, rtol=1e-11)


@pytest.mark.parametrize("kw,key", [(dict(particles=1), "particles"), (dict(particles=0), "particles"),
                                    (dict(resample_threshold=0.0), "resample_threshold"),
                                    (dict(resample_threshold=1.5), "resample_threshold"),
                                    (dict(roughening=1.0), "roughening"), (dict(roughening=-0.1), "roughening"),
                                    (dict(substeps=-1), "substeps")])
def test_bad_particle_settings_name_the_key(kw, key):
    with pytest.raises(ArgumentError) as e:
        ParticleFilter(get_layout(15), _imu(), **kw)
    assert e.value.argument == key


@pytest.mark.parametrize("line,key", [("particles = 1", "particles"), ("resample_threshold = 0.0", "resample_threshold"),
                                      ("roughening = 1.5", "roughening"), ("particls = 10", "particls")])
def test_pf_options_in_a_scenario_file_are_checked(tmp_path, line, key):
    base = load_scenario("loose-demo")[2]
    text = base[:base.index("[[methods]]")] + ('[[methods]]\nname = "m"\ntype = "loose-ekf"\nestimator = "pf"\n'
                                               f'[methods.options]\n{line}\n')
    p = tmp_path / "sc.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_scenario(str(p))
    assert key in str(e.value)


def test_pf_from_a_scenario_file(tmp_path):
    from mixnav.experiment import methods
    base = load_scenario("loose-demo")[2]
    text = base[:base.index("[[methods]]")] + ('[[methods]]\nname = "m"\ntype = "loose-ekf"\nestimator = "pf"\n'
                                               '[methods.options]\nparticles = 64\nroughening = 0.5\nparallel = true\n')
    p = tmp_path / "sc.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    sim = simulate(sc, 1, src)
    filt, _ = methods.build(sc.methods[0], sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0)
    assert filt.name == "pf" and filt.options.particles == 64 and filt.options.roughening == 0.5
    assert filt.options.parallel is True and filt.make_estimator().N == 64


def _imu():
    from mixnav.ins.imu_model import ImuErrorModel
    return ImuErrorModel()
