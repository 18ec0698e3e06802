"""The particle filter's fused loose GNSS update (the loose model's member_update:
measurements/_loose_members.pf_loose_update) against the generic path.

The generic path builds every particle's full state (pf_member_navs), asks the loose
model's predict_batch for the predictions and weighs them (pf_log_weights, pf_moments).
The fused kernel computes the same predictions from the particle array (Rodrigues on the
lever arm in place of the quaternion product and its DCM, sin/cos of the particles'
latitudes from the nominal's by the angle sum and series) and the weights and moments
in chunked passes: equal to round-off. Round-off here: the predictions' absolute
latitudes carry ~1e-16 rad (0.7 nm), so differences of ~1e-15 relative to each
quantity's scale are round-off; the tolerances (1e-12 relative) leave three orders of
margin and would catch any modelling difference (a dropped lever-arm term is >= 1e-4 m).
"""

import numba
import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.data import GnssFixes
from mixnav.filters import _pf_kernels as K
from mixnav.ins import _particle_kernels as PK
from mixnav.measurements import _loose_members as LM
from mixnav.filters.particle import ParticleFilter, linear_gaussian_particles
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate


def _case(N, att_sigma, pos_sigma, lever, use_vel, seed=0):
    """Particles about a nominal 100 m off a fix, the fix and its loose model."""
    lay = get_layout(15)
    n = lay.n
    rng = np.random.default_rng(seed)
    nav = np.array([0.9, 0.1, 0.2, 0.3, 10.0, 2.0, -0.1, 0.6, 0.2, 100.0])
    nav[:4] /= np.linalg.norm(nav[:4])
    scale = np.r_[[att_sigma] * 3, [0.5] * 3, [pos_sigma] * 3, [1e-4] * 3, [1e-2] * 3]
    D = rng.standard_normal((N, n)) * scale + rng.standard_normal(n) * scale * 0.3
    lla = nav[7:10] + np.array([100.0 / 6.4e6, -50.0 / 5e6, 3.0])
    fixes = GnssFixes(time=np.array([0.0]), lla=lla[None], pos_sigma=np.array([[1.5, 2.0, 3.0]]),
                      vel_n=np.array([[10.1, 1.9, 0.0]]) if use_vel else None,
                      vel_sigma=np.array([[0.1, 0.1, 0.2]]) if use_vel else None)
    model = LooseGnss(fixes, lever, lay)
    logw0 = rng.standard_normal(N) * 0.5
    w0 = np.exp(logw0 - logw0.max())
    w0 /= w0.sum()
    w_b = np.array([0.02, -0.01, 0.3])
    return lay, D, nav, model, logw0, w0, w_b


def _generic(lay, D, nav, model, logw0, w0, w_b):
    N, n = D.shape
    navs = np.empty((N, 10))
    PK.pf_member_navs_serial(nav, D, lay.as_array(), navs, np.empty((N, 12)), np.empty((N, PK.SCRATCH)))
    y, Y, r = model.predict_batch(0, navs, w_b - D[:, 9:12])
    m = len(y)
    logw, w, ym, Pyy = np.empty(N), np.empty(N), np.empty(m), np.empty((m, m))
    best, ess, nis = K.pf_log_weights(logw0, w0, y, np.ascontiguousarray(Y), r, logw, w, ym, Pyy)
    x, P = np.empty(n), np.empty((n, n))
    K.pf_moments_serial(D, w, x, P, np.empty((K.CHUNKS, n + n * n)))
    return dict(Y=Y, logw=logw, w=w, x=x, P=P, best=best, ess=ess, nis=nis)


def _fused(parallel, lay, D, nav, model, logw0, w0, w_b, threshold=1e30, w=None):
    """The model's fused member update (serial or parallel twin) called as the estimator does."""
    N, n = D.shape
    u = model.member_update(0, lay, parallel)
    m = u.rows
    out = dict(Y=np.empty((m, N)), logw=np.empty(N), w=np.empty(N) if w is None else w, x=np.empty(n),
               P=np.empty((n, n)))
    out["best"], out["ess"], out["nis"] = u.kernel(
        D, nav, w_b, logw0, w0, threshold, out["Y"], out["logw"], out["w"], np.empty(m), np.empty((m, m)), out["x"],
        out["P"], np.empty((K.CHUNKS, 2 + m + m * m)), np.empty((K.CHUNKS, 2 + n)), np.empty((K.CHUNKS, n + n * n)),
        np.empty((n + 1, N)), *u.constants)
    out["Y"] = out["Y"].T
    return out


@pytest.mark.parametrize("att_sigma,pos_sigma,lever,use_vel", [
    (1e-3, 2.0, (0.5, 0.2, -1.0), True),       # loose-demo's lever arm and spread
    (1e-3, 2.0, (0.5, 0.2, -1.0), False),      # position only
    (0.3, 2.0, (2.0, -1.5, 3.0), True),        # large attitude spread: both Rodrigues branches
    (0.02, 3000.0, (2.0, -1.5, 3.0), True),    # km spread: both latitude branches (bound 6.4 km)
    (1e-3, 2.0, (0.0, 0.0, 0.0), True),        # no lever arm
])
def test_the_fused_loose_update_equals_the_generic_path(att_sigma, pos_sigma, lever, use_vel):
    """Predictions, log-weights, weights, mean, covariance, ESS, NIS and the smallest
    squared innovation of the fused kernel (serial and parallel twins) against the generic
    path, 3000 particles: 1e-12 relative to each quantity's scale (module docstring). The
    weights are compared where they matter (absolute 1e-12 of the largest: a log-weight of
    -1e6 carries ~1e-10 of absolute round-off, and its weight is 0 either way). The twins
    are bitwise equal."""
    case = _case(3000, att_sigma, pos_sigma, np.array(lever, dtype=float), use_vel)
    a = np.abs(case[1][:, 0:3]).max()
    if att_sigma > 0.1:
        assert a > 0.1 and (np.sqrt((case[1][:, 0:3] ** 2).sum(axis=1)) < 0.1).any()  # both branches
    if pos_sigma > 1000:
        assert np.abs(case[1][:, 6]).max() > 6.4e3 > np.abs(case[1][:, 6]).min()
    g = _generic(*case)
    f = _fused(False, *case)
    for key in ("Y", "logw", "x", "P"):
        scale = np.abs(g[key]).max(axis=0) if key == "Y" else np.abs(g[key]).max()
        assert (np.abs(f[key] - g[key]) <= 1e-12 * scale).all(), (key, np.abs(f[key] - g[key]).max() / scale)
    assert np.abs(f["w"] - g["w"]).max() <= 1e-12 * g["w"].max()
    for key in ("best", "ess", "nis"):
        assert f[key] == pytest.approx(g[key], rel=1e-12), key
    p = _fused(True, *case)
    for key in f:
        np.testing.assert_array_equal(np.asarray(p[key]), np.asarray(f[key]))
    lay, D, nav, model, _, _, w_b = case
    YT = np.empty_like(f["Y"].T)
    la, lev, fix = model.member_update(0, lay).constants
    LM.pf_loose_predict(D, la, nav, w_b, lev, fix, YT)   # the predictions alone
    np.testing.assert_array_equal(YT.T, f["Y"])


def test_the_fused_update_detects_a_degenerate_epoch_like_the_generic_one():
    """A fix 10 km away with 1.5 m sigmas: the smallest squared innovation exceeds the
    absurd threshold; the fused kernel returns the same ``best`` and ess 0 (the estimator
    then rejects the epoch) and leaves the weights alone."""
    lay, D, nav, model, logw0, w0, w_b = _case(500, 1e-3, 2.0, np.array([0.5, 0.2, -1.0]), True)
    model._rows[0, 0] += 1e4 / 6.4e6
    g = _generic(lay, D, nav, model, logw0, w0, w_b)
    w = np.full(D.shape[0], -1.0)
    f = _fused(False, lay, D, nav, model, logw0, w0, w_b, threshold=6 * 1e4 ** 2 / 1e3, w=w)
    best, ess = f["best"], f["ess"]
    assert best == pytest.approx(g["best"], rel=1e-12) and best > 6 * 1e4 ** 2 / 1e3
    assert ess == 0.0 and (w == -1.0).all()


@pytest.fixture(scope="module")
def demo():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    return sim, np.asarray(sc.gnss.lever_arm, dtype=float)


def _first_seconds(sim, lever, fused, parallel=False, particles=400, seconds=60.0, roughening=0.9):
    lay = get_layout(15)
    f = ParticleFilter(lay, sim.imu_model, particles=particles, parallel=parallel, roughening=roughening)
    eng = f.engine([LooseGnss(sim.fixes, lever, lay)], rng=3)
    f.estimator.fused = fused
    eng.start(sim.imu, sim.init)
    while eng.time < sim.init.time + seconds:
        eng.step()
    est = f.estimator
    return eng.nav.copy(), est.D.copy(), est.w.copy(), est.covariance().copy(), dict(est.counts), len(est.ess_history)


@pytest.mark.parametrize("roughening", [0.9, 0.0])
def test_a_seeded_run_is_the_same_with_the_fused_update(demo, roughening):
    """loose-demo's first 60 s (60 loose epochs), 400 particles, seed 3, with the fused
    update and with the generic path: the same resamplings and, round-off apart, the same
    nominal, particles, weights and covariance (1e-8 relative to each one's scale: the
    round-off of 1e-15 per epoch is fed back 60 times through the nominal and the
    weights' exponentials; 8e-10 measured with the jitter); the nominal to 1e-8 absolute
    (m, m/s, rad; its height differed by 1.3e-9 m). With and without the
    Liu-West jitter. A modelling difference fails it (the particle's attitude dropped
    from the velocity lever term: 1e-4 m/s, tried)."""
    sim, lever = demo
    a = _first_seconds(sim, lever, True, roughening=roughening)
    b = _first_seconds(sim, lever, False, roughening=roughening)
    assert a[4] == b[4] and a[5] == b[5] == 60 and a[4]["pf_resampled"] > 5
    np.testing.assert_allclose(a[0], b[0], rtol=1e-12, atol=1e-8)
    for u, v in zip(a[1:4], b[1:4]):
        assert np.abs(u - v).max() <= 1e-8 * np.abs(v).max()


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_the_fused_update_is_bitwise_the_same_on_one_or_two_threads(demo):
    """The fused loose update's parallel twin on 1 and 2 numba threads and the serial
    twin: bitwise the same run (fixed chunks added in order; loose-demo, 30 s)."""
    sim, lever = demo
    old = numba.get_num_threads()
    runs = []
    try:
        for parallel, threads in ((True, 1), (True, 2), (False, 2)):
            numba.set_num_threads(threads)
            runs.append(_first_seconds(sim, lever, True, parallel=parallel, particles=300, seconds=30.0))
    finally:
        numba.set_num_threads(old)
    for other in runs[1:]:
        for u, v in zip(runs[0][:4], other[:4]):
            np.testing.assert_array_equal(u, v)


def test_the_jitter_with_a_singular_covariance_uses_a_triangular_root():
    """A weighted covariance with a zero direction (the third state never spread): its
    Cholesky factor fails, the jitter takes R^T of the QR of the symmetric root (counted in
    pf_jitter_root) and leaves that direction exactly unspread (|D| < 1e-12); on a
    positive definite one the kernel equals a D[idx] + (1 - a) x + Z (h L)^T in numpy
    (1e-12)."""
    est = linear_gaussian_particles(np.diag([1.0, 4.0, 0.0]), 2000, rng=3, resample_threshold=1.0,
                                    roughening=0.5)
    H = np.array([[1.0, 0.0, 0.0]])
    est.weigh(np.array([0.5]), np.ascontiguousarray(est.D @ H.T), np.array([0.5]))
    assert est.counts["pf_resampled"] == 1 and est.counts["pf_jitter_root"] == 1
    assert np.abs(est.D[:, 2]).max() < 1e-12 and est.D[:, 1].std() > 1.0
    rng = np.random.default_rng(1)
    N, n = 300, 5
    D, Z = rng.standard_normal((N, n)), rng.standard_normal((N, n))
    idx = np.sort(rng.integers(0, N, N))
    x = rng.standard_normal(n)
    hL = np.tril(rng.standard_normal((n, n)))
    ref = 0.6 * D[idx] + 0.4 * x + Z @ hL.T
    for jitter in (K.pf_jitter, K.pf_jitter_serial):
        out = np.empty((N, n))
        jitter(D, idx, 0.6, 0.8, x, hL + np.triu(np.ones((n, n)), 1), Z.T.copy(), out)   # upper part unread
        np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-12)


def test_a_non_finite_particle_weighs_nothing_and_leaves_the_moments_finite():
    """A particle whose row is NaN (or inf) gets weight 0 and adds 0 to the weighted mean
    and covariance (0 x NaN would be NaN): the fused update (both twins) and the generic
    moments (pf_moments) against numpy's weighted moments of the finite rows (1e-12)."""
    lay, D, nav, model, logw0, w0, w_b = _case(600, 1e-3, 2.0, np.array([0.5, 0.2, -1.0]), True)
    D = D.copy()
    D[7] = np.nan
    D[300, 4] = np.inf
    for parallel in (False, True):
        f = _fused(parallel, lay, D, nav, model, logw0, w0, w_b)
        assert f["w"][7] == 0.0 and f["w"][300] == 0.0 and np.isfinite(f["w"]).all()
        ok = np.isfinite(D).all(axis=1)
        xm = np.average(D[ok], axis=0, weights=f["w"][ok])
        Pm = np.cov(D[ok].T, aweights=f["w"][ok], bias=True)
        np.testing.assert_allclose(f["x"], xm, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(f["P"], Pm, rtol=1e-10, atol=1e-14 * np.abs(Pm).max())
        x, P = np.empty(D.shape[1]), np.empty((D.shape[1],) * 2)
        for moments in (K.pf_moments_serial, K.pf_moments):
            moments(D, f["w"], x, P, np.empty((K.CHUNKS, D.shape[1] * (D.shape[1] + 1))))
            np.testing.assert_allclose(x, xm, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(P, Pm, rtol=1e-10, atol=1e-14 * np.abs(Pm).max())


def test_the_one_loose_prediction_agrees_across_its_trig_modes_and_wraps_the_longitude():
    """_loose_kernel.antenna_from_fix, the per-state loose prediction the EKF rows, predict_batch
    and the fused update share: with the latitudes' sines by series about a reference
    (TRIG_SERIES, TRIG_NEAR) it equals the library-function mode (TRIG_PLAIN) to 1e-9 m
    (round-off on Earth-radius products); a fix 30 m north-east and 2 m above the antenna
    gives (-30, -30, 2) m to 0.05 m (the NED frame's curvature over 30 m); beyond
    SMALL_DLAT from the reference TRIG_SERIES says it did not hold and TRIG_NEAR still equals
    TRIG_PLAIN; across the antimeridian the east offset is the short way round (~2 m, not
    40000 km) in TRIG_PLAIN and TRIG_NEAR, and TRIG_SERIES says it did not hold."""
    from mixnav.geodesy.earth import radii
    from mixnav.measurements._loose_kernel import TRIG_NEAR, TRIG_PLAIN, TRIG_SERIES, antenna_from_fix

    lat0 = 0.6
    s0, c0 = np.sin(lat0), np.cos(lat0)
    lat, lon, h = lat0 + 2e-5, 0.2, 100.0
    cl = (0.5, -0.3, 1.2)
    rm, rn = radii(lat)
    a_lat, a_lon, a_h = lat + cl[0] / (rm + h), lon + cl[1] / ((rn + h) * np.cos(lat)), h - cl[2]
    ra_m, ra_n = radii(a_lat)
    fix = (a_lat + 30.0 / (ra_m + a_h), a_lon + 30.0 / ((ra_n + a_h) * np.cos(a_lat)), a_h + 2.0)
    plain = antenna_from_fix(lat, lon, h, *cl, *fix, TRIG_PLAIN, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(plain[:3], (-30.0, -30.0, 2.0), atol=0.05)
    for mode in (TRIG_SERIES, TRIG_NEAR):
        y = antenna_from_fix(lat, lon, h, *cl, *fix, mode, lat0, s0, c0)
        assert y[3]
        np.testing.assert_allclose(y[:3], plain[:3], rtol=0, atol=1e-9)
    far = lat0 + 3e-3      # beyond SMALL_DLAT (1e-3) from the reference
    plain = antenna_from_fix(far, lon, h, *cl, *fix, TRIG_PLAIN, 0.0, 0.0, 0.0)
    assert not antenna_from_fix(far, lon, h, *cl, *fix, TRIG_SERIES, lat0, s0, c0)[3]
    near = antenna_from_fix(far, lon, h, *cl, *fix, TRIG_NEAR, lat0, s0, c0)
    assert not near[3]
    np.testing.assert_allclose(near[:3], plain[:3], rtol=1e-12)
    # the antimeridian: the state just west of it, the fix just east
    e = 1e-7
    plain = antenna_from_fix(lat, np.pi - e, h, 0.0, 0.0, 0.0, lat, -np.pi + e, h, TRIG_PLAIN, 0.0, 0.0, 0.0)
    near = antenna_from_fix(lat, np.pi - e, h, 0.0, 0.0, 0.0, lat, -np.pi + e, h, TRIG_NEAR, lat0, s0, c0)
    short = -2 * e * (rn + h) * np.cos(lat)        # the antenna is west of the fix: east offset < 0
    assert plain[1] == pytest.approx(short, rel=1e-6) and near[1] == pytest.approx(short, rel=1e-6)
    assert not antenna_from_fix(lat, np.pi - e, h, 0.0, 0.0, 0.0, lat, -np.pi + e, h, TRIG_SERIES, lat0, s0,
                                c0)[3]


def test_member_update_is_offered_only_for_members_the_model_can_read():
    """member_update is a capability: the protocol's default answers None (the tight model
    today), the loose model answers None for a layout other than its own INS one and for an
    estimated lever arm, and hands out the serial or the parallel twin as asked."""
    from mixnav.ins.error_model import StateLayout
    from mixnav.measurements.base import MeasurementModel
    from mixnav.measurements.loose import gnss_lever_block

    lay, D, nav, model, logw0, w0, w_b = _case(50, 1e-3, 2.0, np.array([0.5, 0.2, -1.0]), True)
    assert MeasurementModel().member_update(0, lay) is None
    assert model.member_update(0, get_layout(17)) is None
    u = model.member_update(0, lay)
    assert u.rows == 6 and u.kernel is LM.pf_loose_update_serial and model.member_update(0, lay, True).kernel is \
        LM.pf_loose_update
    lever_lay = StateLayout("lever", [gnss_lever_block(0.1)])
    assert LooseGnss(model.fixes, model.lever, lever_lay).member_update(0, lever_lay) is None


def test_the_estimators_warm_up_reaches_every_model_class_that_offers_a_member_update():
    """warm_member_updates walks the measurement-model classes (subclasses of subclasses too)
    and calls each one's own warm_up_members once, with the layout and the twin asked: the
    particle filter's warm-up compiles the loose model's kernel without naming it."""
    from mixnav.measurements.base import MeasurementModel, warm_member_updates

    calls = []

    class Offering(MeasurementModel):
        @classmethod
        def warm_up_members(cls, layout, parallel=False):
            calls.append((cls.__name__, layout, parallel))

    class Inheriting(Offering):      # inherits the warm-up: not called twice
        pass

    class Deeper(Inheriting):
        @classmethod
        def warm_up_members(cls, layout, parallel=False):
            calls.append((cls.__name__, layout, parallel))

    warm_member_updates("L", True)
    assert [c for c in calls if c[0] in ("Offering", "Inheriting", "Deeper")] == [("Offering", "L", True),
                                                                                ("Deeper", "L", True)]
