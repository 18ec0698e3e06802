"""The fixed-interval RTS smoother of the closed-loop filter (engine/smoother.py).

- the backward recursion on plain arrays, fed by a linear Kalman filter run in
  closed-loop form (correction injected into a nominal, error reset to zero), equals
  the batch weighted least-squares solution of the whole interval;
- on loose-demo with its 60 s outage the smoothed drift is far below the filter's and
  the smoothed position NEES is chi-square-like;
- the recoveries, the injection into every state block, the history's memory, and
  the errors.
"""

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.engine import Engine
from mixnav.engine.smoother import rts_backward, rts_smooth
from mixnav.errors import ArgumentError
from mixnav.experiment.run import solution_table
from mixnav.filters.ekf import ErrorStateEkf, KalmanEstimator
from mixnav.filters.gmekf import BankMixtures, GaussianMixtureEkf, StandardMixture
from mixnav.ins.error_model import StateBlock, StateLayout, get_layout
from mixnav.ins.strapdown import StrapdownMotion
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate, truth_and_ideal_imu


# --- a linear-Gaussian system, written here independently of mixnav ---------------------------

def _linear_problem(seed=3, E=60):
    """2-D constant velocity with a random-walk bias on the x position measurement:
    x = [px, py, vx, vy, b] (n = 5). Irregular steps; events without a measurement,
    with one (position or velocity) or with two in turn (position then velocity: two
    closed-loop updates at one event, as the engine does with two models)."""
    rng = np.random.default_rng(seed)
    n = 5
    dts = rng.uniform(0.2, 1.0, E)
    q_acc, q_b = 0.3, 0.02
    Phis, Qs = [np.eye(n)], [None]
    for dt in dts[1:]:
        F = np.eye(n)
        F[0, 2] = F[1, 3] = dt
        Q = np.zeros((n, n))
        for i, j in ((0, 2), (1, 3)):  # white acceleration, exact discretisation
            Q[i, i], Q[i, j], Q[j, i], Q[j, j] = dt ** 3 / 3, dt ** 2 / 2, dt ** 2 / 2, dt
        Q[:4, :4] *= q_acc
        Q[4, 4] = q_b * dt
        Phis.append(F)
        Qs.append(Q)
    m0 = np.array([1.0, -2.0, 0.5, 0.3, 0.0])
    P0 = np.diag([4.0, 4.0, 1.0, 1.0, 0.25])
    Hp = np.array([[1.0, 0, 0, 0, 1.0], [0, 1.0, 0, 0, 0]])  # position (x biased)
    Hv = np.array([[0, 0, 1.0, 0, 0], [0, 0, 0, 1.0, 0]])    # velocity
    Rp, Rv = np.diag([0.5, 0.8]), np.diag([0.05, 0.04])
    x = m0 + np.linalg.cholesky(P0) @ rng.standard_normal(n)
    truth, meas = [], []
    for k in range(E):
        if k:
            x = Phis[k] @ x + np.linalg.cholesky(Qs[k]) @ rng.standard_normal(n)
        truth.append(x.copy())
        kind = k % 4  # 0: none, 1: position, 2: velocity, 3: both
        rows = []
        if kind in (1, 3):
            rows.append((Hp, Rp, Hp @ x + np.linalg.cholesky(Rp) @ rng.standard_normal(2)))
        if kind in (2, 3):
            rows.append((Hv, Rv, Hv @ x + np.linalg.cholesky(Rv) @ rng.standard_normal(2)))
        meas.append(rows)
    return dict(n=n, Phi=np.array(Phis), Q=Qs, m0=m0, P0=P0, meas=meas, truth=np.array(truth))


def _closed_loop_kf(pb):
    """The linear KF in closed-loop form: the nominal carries the estimate, each update's
    correction is injected into it and the error estimate reset to zero. Records what
    the engine's History holds."""
    n, E = pb["n"], len(pb["meas"])
    nom, P = pb["m0"].copy(), pb["P0"].copy()
    rec = {k: [] for k in ("P_pred", "P_filt", "dx", "nav")}
    for k in range(E):
        if k:
            nom = pb["Phi"][k] @ nom
            P = pb["Phi"][k] @ P @ pb["Phi"][k].T + pb["Q"][k]
        rec["P_pred"].append(P.copy())
        dsum = np.zeros(n)
        for H, R, y in pb["meas"][k]:
            z = y - H @ nom                      # innovation about the current nominal
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T
            dx = K @ z
            nom = nom + dx                       # feedback ...
            IKH = np.eye(n) - K @ H
            P = IKH @ P @ IKH.T + K @ R @ K.T    # ... and the error estimate is zero again
            dsum += dx
        rec["P_filt"].append(P.copy())
        rec["dx"].append(dsum)
        rec["nav"].append(nom.copy())
    return {k: np.array(v) for k, v in rec.items()}


def _batch_wls(pb):
    """All states of the interval at once: prior, process and measurement equations
    stacked, the normal equations solved; the inverse normal matrix is the covariance."""
    n, E = pb["n"], len(pb["meas"])
    N = np.zeros((E * n, E * n))
    rhs = np.zeros(E * n)
    blk = lambda k: slice(k * n, (k + 1) * n)  # noqa: E731
    W0 = np.linalg.inv(pb["P0"])
    N[blk(0), blk(0)] += W0
    rhs[blk(0)] += W0 @ pb["m0"]
    for k in range(1, E):  # x_k - Phi_k x_{k-1} = w_k ~ N(0, Q_k)
        A = np.zeros((n, E * n))
        A[:, blk(k)] = np.eye(n)
        A[:, blk(k - 1)] = -pb["Phi"][k]
        N += A.T @ np.linalg.inv(pb["Q"][k]) @ A
    for k in range(E):
        for H, R, y in pb["meas"][k]:
            Wr = np.linalg.inv(R)
            N[blk(k), blk(k)] += H.T @ Wr @ H
            rhs[blk(k)] += H.T @ Wr @ y
    x = np.linalg.solve(N, rhs).reshape(E, n)
    C = np.linalg.inv(N)
    return x, np.array([C[blk(k), blk(k)] for k in range(E)])


def test_closed_loop_recursion_equals_the_batch_least_squares_solution():
    pb = _linear_problem()
    rec = _closed_loop_kf(pb)
    x_batch, P_batch = _batch_wls(pb)
    d_s, P_s, not_pd = rts_backward(pb["Phi"], rec["P_pred"], rec["P_filt"], rec["dx"])
    x_s = rec["nav"] + d_s  # the linear system's "inject"
    assert not_pd == 0
    # round-off only: the batch normal matrix of 300 unknowns is well conditioned here
    scale_x, scale_P = np.abs(x_batch).max(), np.abs(P_batch).max()
    np.testing.assert_allclose(x_s, x_batch, rtol=0, atol=1e-8 * scale_x)
    np.testing.assert_allclose(P_s, P_batch, rtol=0, atol=1e-8 * scale_P)
    # the last event is the filter's; earlier ones are strictly better informed
    np.testing.assert_allclose(x_s[-1], rec["nav"][-1], atol=1e-12 * scale_x)
    assert np.all(np.trace(P_s[:-1], axis1=1, axis2=2) < np.trace(rec["P_filt"][:-1], axis1=1, axis2=2))
    # and the closed-loop bookkeeping matters: leaving dx out (an open-loop formula on the
    # closed-loop record) is far from the batch solution
    d_bad, _, _ = rts_backward(pb["Phi"], rec["P_pred"], rec["P_filt"], np.zeros_like(rec["dx"]))
    assert np.abs(rec["nav"] + d_bad - x_batch).max() > 1e3 * 1e-8 * scale_x


def test_keep_returns_the_covariances_asked_for():
    pb = _linear_problem(E=20)
    rec = _closed_loop_kf(pb)
    d_all, P_all, _ = rts_backward(pb["Phi"], rec["P_pred"], rec["P_filt"], rec["dx"])
    keep = np.array([0, 7, 7, 19, 3])  # any order, repeats allowed
    d_s, P_s, _ = rts_backward(pb["Phi"], rec["P_pred"], rec["P_filt"], rec["dx"], keep=keep)
    np.testing.assert_array_equal(d_s, d_all)
    np.testing.assert_array_equal(P_s, P_all[keep])
    with pytest.raises(ArgumentError, match="keep"):
        rts_backward(pb["Phi"], rec["P_pred"], rec["P_filt"], rec["dx"], keep=[20])


def test_a_singular_prediction_is_jittered_and_a_broken_one_skipped_never_nan():
    pb = _linear_problem(E=30)
    rec = _closed_loop_kf(pb)
    ref_d, ref_P, _ = rts_backward(pb["Phi"], rec["P_pred"], rec["P_filt"], rec["dx"])
    # A deterministic extra state (zero variance, no noise, decoupled): every P_pred is
    # singular. Jitter of 1e-12 of the largest variance factors it and, the state being
    # decoupled, leaves the others' smoothed solution as it was.
    E, n = rec["dx"].shape
    grow = lambda a: np.pad(a, [(0, 0)] + [(0, 1)] * (a.ndim - 1))  # noqa: E731
    Phi = grow(pb["Phi"])
    Phi[:, n, n] = 1.0
    d, P, not_pd = rts_backward(Phi, grow(rec["P_pred"]), grow(rec["P_filt"]), grow(rec["dx"]))
    assert not_pd == E - 1 and np.isfinite(d).all() and np.isfinite(P).all()
    np.testing.assert_allclose(d[:, :n], ref_d, atol=1e-9 * np.abs(ref_d).max())
    np.testing.assert_allclose(P[:, :n, :n], ref_P, atol=1e-9 * np.abs(ref_P).max())
    assert not d[:, n].any() and not P[:, n, :].any()
    # A P_pred that no jitter fixes (negative definite): that step is skipped, the
    # smoothed solution restarts from the filter's at the event before.
    P_pred = rec["P_pred"].copy()
    j = 12
    P_pred[j] = -np.eye(n)
    d, P, not_pd = rts_backward(pb["Phi"], P_pred, rec["P_filt"], rec["dx"])
    assert not_pd == 1 and np.isfinite(d).all() and np.isfinite(P).all()
    assert not d[j - 1].any()
    np.testing.assert_array_equal(P[j - 1], rec["P_filt"][j - 1])
    np.testing.assert_array_equal(d[j:], ref_d[j:])  # after it, untouched


# --- the INS: loose-demo, a 60 s GNSS outage in a turn ----------------------------------------

N_SEEDS = 10


@pytest.fixture(scope="module")
def demo():
    sc, src, _ = load_scenario("loose-demo")
    ideal = truth_and_ideal_imu(sc, src)
    lay = get_layout(15)
    lever = np.asarray(sc.gnss.lever_arm, float)
    runs = []
    for seed in range(N_SEEDS):
        sim = simulate(sc, seed, src, ideal=ideal)
        res = ErrorStateEkf(lay, sim.imu_model).run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, lay)],
                                                    history=True)
        sm = rts_smooth(res)
        runs.append((res, sm, solution_table(res, sim.truth, sc.gnss.outages),
                     solution_table(sm, sim.truth, sc.gnss.outages)))
    return sc, runs


def test_smoother_bridges_the_outage(demo):
    sc, runs = demo
    (a, b), = [tuple(o) for o in sc.gnss.outages]
    for res, sm, tf, ts in runs:
        inside = (tf.time_s > a) & (tf.time_s <= b)
        hf = np.hypot(tf.err_n_m, tf.err_e_m)[inside].max()
        hs = np.hypot(ts.err_n_m, ts.err_e_m)[inside].max()
        # GNSS on both sides: the smoothed drift is a fraction of the filter's (measured
        # at most a third over 40 seeds; the filter's is 6-30 m)
        assert hs < 0.5 * hf, (hs, hf)
        assert sm.recoveries["smoother_not_pd"] == 0 and sm.timing["smoother_time_s"] > 0
        # its timing is its own: the forward pass's epoch times are not the smoother's
        assert set(sm.timing) == {"smoother_time_s"} and "epoch_time_mean_us" in res.timing
        # smoothing only adds information: no sigma grows, and the outage's largest
        # horizontal sigma (at its end for the filter, mid-way for the smoother) shrinks
        assert np.all(sm.sigma <= res.sigma * (1 + 1e-9))
        i = inside.to_numpy()
        assert np.all(sm.sigma[i][:, 6:8].max(0) < 0.5 * res.sigma[i][:, 6:8].max(0))
        # at the last event the smoother is the filter
        np.testing.assert_allclose(sm.nav[-1], res.nav[-1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(sm.pv_cov[-1], res.pv_cov[-1], rtol=1e-12)
        assert len(sm.nis) == 0 and sm.history is None
        np.testing.assert_array_equal(sm.gnss_used, res.gnss_used)


def test_smoothed_position_nees_is_consistent(demo):
    sc, runs = demo
    nees = np.array([ts["nees_pos"].to_numpy().mean() for _, _, _, ts in runs])
    # A consistent smoother's position NEES has mean 3 (its dof). The time average of one
    # run scatters widely because the smoothed errors are correlated over tens of seconds:
    # over 40 seeds its standard deviation was 0.76 (mean 3.16), so the mean of 10 seeds
    # has a standard deviation of about 0.24 and [2.25, 3.75] is +-3 of them about 3.
    # That still fails covariances off by a factor 1.4 either way (NEES 2.1 or 4.2), e.g.
    # smoothed means reported with the filter's covariance (too large in the outage).
    assert 2.25 <= nees.mean() <= 3.75, nees


def test_a_bank_with_a_process_mixture_records_its_predicted_covariance(demo):
    """The bank keeps the white process noise apart until the next split; its reported
    covariance must include it, else the history's P_pred is short of Qd at every
    measured step and the recursion's gain is too large (the smoothed drift was then
    hundreds of metres). Checked: P_pred(k) - Phi P_filt(k-1) Phi^T is a covariance,
    and the merged-Gaussian smoother bridges the outage like the EKF's."""
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 0, src)
    lay = get_layout(15)
    proc = StandardMixture((0.5, 0.5), (0.0, 0.0), (0.5, 1.5))
    g = GaussianMixtureEkf(lay, sim.imu_model, BankMixtures(process=proc), max_components=4)
    res = g.run(sim.imu, sim.init, [LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)],
                history=True)
    h = res.history
    Qd = h.P_pred[1:] - h.Phi[1:] @ h.P_filt[:-1] @ np.swapaxes(h.Phi[1:], 1, 2)
    lo = np.linalg.eigvalsh(0.5 * (Qd + np.swapaxes(Qd, 1, 2)))[:, 0]
    assert np.all(lo > -1e-12 * np.abs(Qd).max(axis=(1, 2))), lo.min()
    sm = rts_smooth(res)
    (a, b), = [tuple(o) for o in sc.gnss.outages]
    tf, ts = solution_table(res, sim.truth, sc.gnss.outages), solution_table(sm, sim.truth, sc.gnss.outages)
    inside = ((tf.time_s > a) & (tf.time_s <= b)).to_numpy()
    hf = np.hypot(tf.err_n_m, tf.err_e_m).to_numpy()[inside].max()
    hs = np.hypot(ts.err_n_m, ts.err_e_m).to_numpy()[inside].max()
    assert hs < 0.5 * hf and sm.recoveries["smoother_not_pd"] == 0, (hs, hf)


class _LooseIgnoringAux(LooseGnss):
    """LooseGnss for a layout with an auxiliary block (its rows do not take ``aux``)."""

    def rows(self, i, nav, w_b, clock, memory=None, aux=None):
        return super().rows(i, nav, w_b, clock, memory)


def test_every_block_is_smoothed_and_injected():
    """Sensor, clock and auxiliary blocks get the smoothed correction of their states;
    the nominal gets attitude, velocity and position (checked with the motion model's
    own inject on the rows of the recursion)."""
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 0, src)
    lay = StateLayout("scale+clock+odo", ["gyro_scale", "accel_scale", "clock",
                                          StateBlock("odo_scale", 1, "random_walk", "aux", sigma0=0.02,
                                                     walk=1e-4)])
    motion = StrapdownMotion(lay, sim.imu_model)
    meas = [_LooseIgnoringAux(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)]
    res = Engine(motion, KalmanEstimator(), meas, history=True).run(sim.imu, sim.init)
    sm = rts_smooth(res)
    h = res.history
    k = np.searchsorted(h.time, res.time - 1e-6)
    d_s, P_s, _ = rts_backward(h.Phi, h.P_pred, h.P_filt, h.dx, keep=k)
    for i in (0, 150, 333, len(k) - 2):
        nav, sensor = h.nav[k[i]].copy(), res.sensor[i].copy()
        clock, aux = res.estimates["clock"][i].copy(), {"odo_scale": res.estimates["odo_scale"][i].copy()}
        motion.inject(nav, sensor, clock, aux, d_s[k[i]])
        np.testing.assert_array_equal(sm.nav[i], nav)
        np.testing.assert_array_equal(sm.sensor[i], sensor)
        np.testing.assert_array_equal(sm.estimates["gyro_scale"][i], sensor[6:9])
        np.testing.assert_array_equal(sm.estimates["clock"][i], clock)
        np.testing.assert_array_equal(sm.estimates["odo_scale"][i], aux["odo_scale"])
        np.testing.assert_array_equal(sm.sigma[i], np.sqrt(np.diag(P_s[i])))
        np.testing.assert_array_equal(sm.pv_cov[i], P_s[i][3:9, 3:9])
    assert np.abs(sm.sensor - res.sensor).max() > 0 and sm.sigma.shape == (len(res.time), lay.n)


def test_history_memory_is_what_its_docstring_says():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 0, src)
    lay = get_layout(21)
    res = ErrorStateEkf(lay, sim.imu_model).run(sim.imu, sim.init, [LooseGnss(sim.fixes, np.asarray(
        sc.gnss.lever_arm, float), lay)], history=True)
    h, n = res.history, lay.n
    E = len(h.time)
    total = sum(a.nbytes for a in (h.time, h.Phi, h.P_pred, h.P_filt, h.dx, h.nav, h.updated))
    assert total == E * (8 * (3 * n * n + n + 11) + 1)
    # one array per field, no per-event objects: each field is a view of one block
    assert all(a.base is not None and a.base.shape[0] == E for a in (h.Phi, h.P_pred, h.P_filt, h.dx))


def test_a_result_without_history_is_an_argument_error():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 0, src)
    lay = get_layout(15)
    res = ErrorStateEkf(lay, sim.imu_model).run(sim.imu, sim.init, [LooseGnss(sim.fixes, np.asarray(
        sc.gnss.lever_arm, float), lay)])
    with pytest.raises(ArgumentError, match="history=True") as e:
        rts_smooth(res)
    assert e.value.argument == "history"
