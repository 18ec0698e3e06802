"""The engine's seams: step API, stateless models shared by two filters, the
smoother history, auxiliary state blocks, registered kinds."""

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.engine import Engine
from mixnav.errors import ArgumentError
from mixnav.filters.ekf import ErrorStateEkf, KalmanEstimator
from mixnav.ins.error_model import ClockModel, StateBlock, StateLayout, get_layout
from mixnav.ins.strapdown import StrapdownMotion
from mixnav.measurements.base import MeasurementModel, Rows
from mixnav.measurements.kinds import kind_code, register_kind
from mixnav.measurements.loose import LooseGnss
from mixnav.measurements.tdcp import TdcpGnss
from mixnav.sim.scenario import simulate


@pytest.fixture(scope="module")
def loose():
    sc, src, _ = load_scenario("loose-demo")
    return sc, simulate(sc, 2, src)


@pytest.fixture(scope="module")
def tdcp():
    sc, src, _ = load_scenario("tdcp-demo")
    sim = simulate(sc, 2, src)
    s = sc.gnss.satellites
    return sc, sim, ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)


def _same(a, b):
    np.testing.assert_array_equal(a.nav, b.nav)
    np.testing.assert_array_equal(a.sigma, b.sigma)
    np.testing.assert_array_equal(a.nis, b.nis)


def test_step_api_equals_run(loose):
    sc, sim = loose
    lay = get_layout(15)
    f = ErrorStateEkf(lay, sim.imu_model)
    meas = [LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)]
    ref = f.run(sim.imu, sim.init, meas)
    eng = f.engine(meas)
    eng.start(sim.imu, sim.init)
    steps = 0
    while eng.step():
        steps += 1
        if steps == 100:  # a partial result is a prefix of the whole one
            part = eng.result()
            np.testing.assert_array_equal(part.nav, ref.nav[:len(part.nav)])
    assert steps == len(eng._times) and not eng.step()
    _same(eng.result(), ref)


def test_one_tdcp_model_serves_two_filters_at_once(tdcp):
    """Models keep no state: two engines stepping alternately through one TdcpGnss
    object (its clone memory held by each engine) give exactly the separate runs."""
    sc, sim, clock = tdcp
    lay = get_layout(17)
    lever = np.asarray(sc.gnss.lever_arm, float)
    shared = TdcpGnss(sim.observations, lever, lay, clone=True)
    fa = ErrorStateEkf(lay, sim.imu_model, clock=clock)
    fb = ErrorStateEkf(lay, sim.imu_model, clock=clock, absurd_sigma=50.0)
    ref_a = fa.run(sim.imu, sim.init, [TdcpGnss(sim.observations, lever, lay)])
    ref_b = fb.run(sim.imu, sim.init, [TdcpGnss(sim.observations, lever, lay)])
    ea, eb = fa.engine([shared]), fb.engine([shared])
    ea.start(sim.imu, sim.init)
    eb.start(sim.imu, sim.init)
    while ea.step() | eb.step():
        pass
    _same(ea.result(), ref_a)
    _same(eb.result(), ref_b)
    assert len(ref_a.nis) > 100 and ref_a.nis_kind[-1] == "pseudorange+tdcp"


def test_history_holds_what_a_smoother_needs(loose):
    sc, sim = loose
    lay = get_layout(21)  # scale factors: constant states, no process noise
    f = ErrorStateEkf(lay, sim.imu_model)
    meas = [LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)]
    res = f.run(sim.imu, sim.init, meas, history=True)
    h = res.history
    E = len(h.time)
    assert h.Phi.shape == (E, 21, 21) and h.P_pred.shape == h.P_filt.shape == (E, 21, 21)
    # no update: the filtered covariance is the predicted one; an update shrinks it
    np.testing.assert_array_equal(h.P_filt[~h.updated], h.P_pred[~h.updated])
    assert np.all(np.trace(h.P_filt[h.updated], axis1=1, axis2=2) < np.trace(h.P_pred[h.updated], axis1=1, axis2=2))
    assert np.all(np.any(h.dx[h.updated] != 0, axis=1)) and not np.any(h.dx[~h.updated])
    # P_pred(k) = Phi_k P_filt(k-1) Phi_k^T + Qd_k: the remainder is a covariance (PSD) and
    # zero on the scale factors, which have no process noise.
    for k in range(1, E, 37):
        Qd = h.P_pred[k] - h.Phi[k] @ h.P_filt[k - 1] @ h.Phi[k].T
        assert np.linalg.eigvalsh(0.5 * (Qd + Qd.T)).min() > -1e-12 * np.abs(Qd).max()
        assert np.abs(Qd[15:21, 15:21]).max() < 1e-15
    # the output record is the history at the output epochs
    k = np.searchsorted(h.time, res.time)
    np.testing.assert_array_equal(res.sigma, np.sqrt(np.diagonal(h.P_filt[k], axis1=1, axis2=2)))
    np.testing.assert_array_equal(res.nav, h.nav[k])


class _DirectAux(MeasurementModel):
    """A made-up sensor that measures an auxiliary state directly (the user's own model)."""

    kinds = ("aux_direct",)

    def __init__(self, times, truth, sigma, layout, rng):
        register_kind("aux_direct")
        self._t = np.asarray(times)
        self._z = truth + sigma * rng.standard_normal(len(times))
        self.sigma = sigma
        self.sl = layout.slice("odo_scale")
        self.layout = layout
        self.code = kind_code("aux_direct")

    @property
    def times(self):
        return self._t

    def rows(self, i, nav, w_b, clock, memory=None, aux=None):
        H = np.zeros((1, self.layout.n))
        H[0, self.sl] = 1.0
        z = np.array([self._z[i] - aux["odo_scale"][0]])
        return Rows(z, H, np.array([self.sigma ** 2]), np.array([self.code]))


def test_an_auxiliary_block_is_carried_fed_back_and_reported(loose):
    """A random-walk block added by name: its variance grows as sigma0^2 + walk^2 t
    without measurements, and a measurement of it is fed back into the engine's
    estimate of the block (a scalar Kalman filter: the posterior mean is known)."""
    sc, sim = loose
    walk, s0 = 1e-3, 0.02
    lay = StateLayout("ins15+odo", [StateBlock("odo_scale", 1, "random_walk", "aux", sigma0=s0, walk=walk)])
    assert lay.n == 16 and lay.aux[0][0] == "odo_scale"
    motion = StrapdownMotion(lay, sim.imu_model)
    res = Engine(motion, KalmanEstimator()).run(sim.imu, sim.init)
    t = res.time - sim.init.time
    np.testing.assert_allclose(res.sigma[:, 15] ** 2, s0 ** 2 + walk ** 2 * t, rtol=1e-9)
    assert not res.estimates["odo_scale"].any()
    # measured directly 10 times at 1 Hz: the estimate is the scalar filter's posterior mean
    times = sim.init.time + np.arange(1.0, 11.0)
    model = _DirectAux(times, 0.05, 0.01, lay, np.random.default_rng(0))
    out = Engine(motion, KalmanEstimator(), [model]).run(sim.imu, sim.init, output_times=times)
    x, P = 0.0, s0 ** 2
    for i in range(10):  # the oracle: scalar random walk + direct measurement
        P += walk ** 2 * 1.0
        K = P / (P + 0.01 ** 2)
        x += K * (model._z[i] - x)
        P *= 1 - K
    assert out.estimates["odo_scale"][-1, 0] == pytest.approx(x, abs=1e-9)
    assert out.sigma[-1, 15] ** 2 == pytest.approx(P, rel=1e-6)
    assert set(out.nis_kind) == {"aux_direct"}


def test_unknown_kinds_and_non_models_are_errors(loose):
    sc, sim = loose

    class Bad(MeasurementModel):
        kinds = ("no_such_kind",)
        times = np.array([1.0])

    lay = get_layout(15)
    with pytest.raises(ArgumentError, match="unknown observable 'no_such_kind'"):
        Engine(StrapdownMotion(lay, sim.imu_model), KalmanEstimator(), [Bad()])
    with pytest.raises(ArgumentError, match="measurements\\[0\\]"):
        Engine(StrapdownMotion(lay, sim.imu_model), KalmanEstimator(), [object()])
    with pytest.raises(ArgumentError, match="covariance_interval"):
        Engine(StrapdownMotion(lay, sim.imu_model), KalmanEstimator(), covariance_interval=2.0)


class _Composite:
    """A minimal composite estimator (the shape of an IMM, fixed mode weights): children
    with their own measurement sets, one transition for all, one combined correction,
    every child re-centred on it. Written here to show the protocol suffices."""

    carry_mean = False

    def __init__(self, children, sets, weights):
        self.children, self.sets, self.w = children, sets, np.asarray(weights, float)

    def init(self, motion, P0, n_clone, rng):
        for c in self.children:
            c.init(motion, P0, n_clone, rng)
        self._scratch = np.zeros_like(P0)
        self.counts = {}

    @property
    def kernel_covariance(self):
        return self._scratch

    def predict(self, step):
        self._scratch[:] = 0.0
        for c in self.children:
            c.predict(step)

    def update(self, epoch):
        nis, m = 0.0, 0
        for c, s in zip(self.children, self.sets):
            if epoch.model in s:
                corr = c.update(epoch)
                nis, m = corr.nis, corr.m
        if m == 0:
            return None
        dx = sum(w * c.x for w, c in zip(self.w, self.children))
        for c in self.children:
            c.recentre(dx)
        from mixnav.engine.protocols import Correction
        return Correction(dx, nis, 0, m)

    def covariance(self):
        return sum(w * (c.P + np.outer(c.x, c.x)) for w, c in zip(self.w, self.children))

    def replace_clone(self, J):
        raise NotImplementedError

    def repair(self):
        raise NotImplementedError

    def diagnostics(self):
        return {}

    def warm_up(self):
        pass


def test_a_composite_holds_children_with_their_own_measurement_sets(loose):
    sc, sim = loose
    lay = get_layout(15)
    lever = np.asarray(sc.gnss.lever_arm, float)
    gnss = LooseGnss(sim.fixes, lever, lay)
    motion = StrapdownMotion(lay, sim.imu_model)
    ekf = Engine(motion, KalmanEstimator(), [gnss]).run(sim.imu, sim.init)
    # A mean-carrying child alone is the closed-loop EKF (its mean is re-centred to zero).
    alone = Engine(motion, KalmanEstimator(carry_mean=True), [gnss]).run(sim.imu, sim.init)
    np.testing.assert_allclose(alone.nav, ekf.nav, rtol=0, atol=1e-12)
    # Child A sees the GNSS, child B nothing; weights (1, 0): the EKF's numbers; both
    # children were propagated with the same Phi and Qd, and only A was updated, so
    # P_B - P_A is a covariance (updates only shrink P, propagation keeps the order).
    a, b = KalmanEstimator(carry_mean=True), KalmanEstimator(carry_mean=True)
    comp = Engine(motion, _Composite([a, b], [{gnss}, set()], [1.0, 0.0]), [gnss]).run(sim.imu, sim.init)
    np.testing.assert_allclose(comp.nav, ekf.nav, rtol=0, atol=1e-12)
    np.testing.assert_allclose(comp.sigma, ekf.sigma, rtol=1e-12)
    gap = np.linalg.eigvalsh(b.P - a.P)
    assert gap.min() > -1e-9 * gap.max() and np.trace(b.P) > 100 * np.trace(a.P)
    # child B's mean is minus every correction fed back, carried by Phi: non-zero and
    # the composite's record uses child A only.
    assert np.abs(b.x[6:8]).max() > 1.0 and np.abs(a.x).max() < 1e-12


def test_batched_mechanization_is_the_single_state_kernel(loose):
    """The ensemble motion model: N states through one compiled call equal N single runs."""
    from mixnav.ins._error_kernels import propagate_block
    sc, sim = loose
    lay = get_layout(15)
    motion = StrapdownMotion(lay, sim.imu_model)
    rng = np.random.default_rng(0)
    navs = np.tile(sim.init.nav, (3, 1))
    navs[:, 4:7] += rng.normal(0, 0.5, (3, 3))
    navs[:, 9] += rng.normal(0, 3.0, 3)
    sensors = rng.normal(0, 1e-4, (3, 12))
    prevs = np.zeros((3, 6))
    sl = slice(0, 250)
    imu = sim.imu
    batch = navs.copy()
    motion.propagate_batch(batch, prevs, sensors, imu.dtheta[sl], imu.dvel[sl], imu.dt[sl])
    for p in range(3):
        one = navs[p].copy()
        propagate_block(one, np.zeros(6), sensors[p], imu.dtheta[sl], imu.dvel[sl], imu.dt[sl], np.empty((0, 0)),
                        motion.qc, motion.layout_array, motion.tau, np.empty((4, 15, 15)), motion.qb)
        np.testing.assert_array_equal(batch[p], one)
    assert np.abs(batch[:, 9] - navs[:, 9]).max() > 0.0


def test_batched_h_of_the_loose_model_matches_its_rows(loose):
    """y - h(x) at the nominal is the rows' innovation; a small error dx of the state
    moves h by H dx (the Jacobian the linearised family uses)."""
    from mixnav.attitude import quat_multiply, rotvec_to_quat
    from mixnav.geodesy.frames import displace
    sc, sim = loose
    lay = get_layout(15)
    model = LooseGnss(sim.fixes, np.array([0.8, -0.3, -1.2]), lay)
    nav = sim.init.nav.copy()
    w = np.array([0.02, -0.01, 0.3])
    i = 5
    rows = model.rows(i, nav, w)
    y, Y, R = model.predict_batch(i, nav[None], w)
    np.testing.assert_allclose(y - Y[0], rows.z, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(R, rows.R)
    for k, eps in [(0, 1e-4), (2, 1e-4), (3, 1e-2), (7, 1e-1), (8, 1e-1)]:
        dx = np.zeros(15)
        dx[k] = eps
        q = quat_multiply(rotvec_to_quat(dx[0:3]), nav[0:4])
        true = np.concatenate([q, nav[4:7] + dx[3:6], displace(nav[7:10], dx[6:9])])
        _, Yt, _ = model.predict_batch(i, true[None], w)
        np.testing.assert_allclose((Yt[0] - Y[0]) / eps, rows.H[:, k], rtol=1e-3, atol=2e-3)
