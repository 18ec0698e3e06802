"""The whole-epoch LOS/NLOS mixture update (mixnav.filters.epoch_mixture)."""

from __future__ import annotations

import numpy as np
import pytest

from mixnav.engine.protocols import Epoch
from mixnav.errors import ArgumentError
from mixnav.filters._ekf_kernels import kalman_correct
from mixnav.filters.ekf import KalmanEstimator
from mixnav.filters.epoch_mixture import EpochMixtureEstimator
from mixnav.measurements.base import Rows
from mixnav.measurements.kinds import PSEUDORANGE

from .test_motion import _dr_run, _simulate, _straight_drive


class _Motion:
    def __init__(self, n):
        from mixnav.ins.error_model import StateBlock, StateLayout
        self.layout = StateLayout("toy", [], core=(StateBlock("position", n, "model", "nav"),))


class _FixedRows:
    def __init__(self, rows):
        self._r = rows

    def rows(self, *a, **k):
        return self._r


def _epoch(z, H, r):
    ep = Epoch(0.0, 0, _FixedRows(Rows(z, H, r, np.full(len(z), PSEUDORANGE, dtype=np.int64))), None, None, None,
               None)
    ep._rows, ep._done = ep.model.rows(), True
    return ep


def _problem(seed=0, m=8, n=5):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    P = A @ A.T + n * np.eye(n)
    H = rng.standard_normal((m, n))
    r = rng.uniform(4.0, 25.0, m)
    z = rng.standard_normal(m) * np.sqrt(r)
    return P, H, r, z


def _scipy_responsibilities(e, r, h, w, s, mu, sd):
    from scipy.stats import norm
    a = w * norm.pdf(e, 0.0, np.sqrt(s * r + h))
    b = (1 - w) * norm.pdf(e, mu, np.sqrt(sd ** 2 + h))
    return a / (a + b)


def test_compiled_responsibilities_match_scipy_densities():
    """The kernel's log-space responsibilities equal the ratio of scipy's normal densities;
    rows outside the mixture or with w = 1 are LOS."""
    from mixnav.filters._epoch_mixture_kernels import responsibilities
    rng = np.random.default_rng(4)
    m = 40
    e, r, h = rng.normal(10, 30, m), rng.uniform(4, 100, m), rng.uniform(0, 20, m)
    w = rng.uniform(0.05, 0.95, m)
    mix = np.ones(m, bool)
    mix[:3] = False
    w[3] = 1.0
    g = responsibilities(e, r, h, mix, w, 1.3, 40.0, 25.0)
    ref = _scipy_responsibilities(e, r, h, w, 1.3, 40.0, 25.0)
    assert np.allclose(g[4:], ref[4:], rtol=1e-10, atol=1e-14) and (g[:4] == 1.0).all()
    # the predictive log density: the mixture's for mixture rows, N(0, r + h) for the others
    from scipy.stats import norm
    from mixnav.filters._epoch_mixture_kernels import predictive_log_density
    dens = np.where(mix, w * norm.pdf(e, 0, np.sqrt(1.3 * r + h)) + (1 - w) * norm.pdf(e, 40.0, np.sqrt(625.0 + h)),
                    norm.pdf(e, 0, np.sqrt(r + h)))
    got = predictive_log_density(e, r, h, mix, w, 1.3, 40.0, 25.0)
    assert got == pytest.approx(np.log(dens).sum(), rel=1e-10)


def test_all_line_of_sight_is_the_kalman_update():
    P, H, r, z = _problem()
    est = EpochMixtureEstimator(los_weight=1.0, learn=False)
    est.init(_Motion(5), P, 0, np.random.default_rng(0))
    c = est.update(_epoch(z, H, r))
    P_k, dx_k, nis_k, _ = kalman_correct(P, z, H, r, 1e4)
    assert np.allclose(c.dx, dx_k, atol=1e-12) and np.allclose(est.P, P_k, atol=1e-12)


def test_a_delayed_row_is_explained_by_the_delay_component():
    """One row 300 m long: its LOS responsibility vanishes and the update is the Kalman update
    with that row as ``z - mu`` of variance ``sd^2`` (the M-step with g = 0, closed form)."""
    P, H, r, z = _problem(seed=1)
    z = z.copy()
    z[3] += 300.0
    mu, sd = 250.0, 40.0
    est = EpochMixtureEstimator(los_weight=0.7, delay_mean=mu, delay_sd=sd, learn=False, tolerance=1e-10,
                                iterations=200)
    est.init(_Motion(5), P, 0, np.random.default_rng(0))
    c = est.update(_epoch(z, H, r))
    g = _scipy_responsibilities(z - H @ c.dx, r, np.einsum("ij,jk,ik->i", H, est.P, H), 0.7, 1.0, mu, sd)
    assert g[3] < 1e-12 and (np.delete(g, 3) > 1 - 1e-6).all()
    z2, r2 = z.copy(), r.copy()
    z2[3] -= mu
    r2[3] = sd ** 2
    P_k, dx_k, _, _ = kalman_correct(P, z2, H, r2, 1e4)
    assert np.allclose(c.dx, dx_k, rtol=1e-6, atol=1e-6)
    assert est.counts["em_not_converged"] == 0


def test_bad_settings_name_the_key():
    for kw, key in ((dict(los_weight=0.0), "los_weight"), (dict(delay_sd=-1.0), "delay_sd"),
                    (dict(forget=1.5), "forget"), (dict(iterations=0), "iterations"),
                    (dict(kinds=("no-such-kind",)), "kinds")):
        with pytest.raises(ArgumentError) as exc:
            EpochMixtureEstimator(**kw)
        assert exc.value.argument == key


def _urban(seed):
    """The simulated drive with non-line-of-sight delays: each satellite is delayed in
    random segments (a third of the time on average), by 20-80 m (uniform, fixed per
    segment), as buildings block it."""
    rng = np.random.default_rng(1000 + seed)
    segments = {}
    for sat in list(range(1, 8)) + list(range(101, 107)):
        starts = np.sort(rng.uniform(0, 120, 3))
        segments[sat] = [(s, s + rng.uniform(5, 20), rng.uniform(20, 80)) for s in starts]

    def bias(t, ids):
        out = np.zeros(len(ids))
        for k, sat in enumerate(ids):
            for a, b, d in segments[int(sat)]:
                if a <= t < b:
                    out[k] = d
        return out
    return bias


def test_urban_drive_mixture_beats_the_ekf_with_consistent_nees():
    """10 seeds of the simulated urban drive: the epoch mixture's horizontal RMSE is below
    half the EKF's in every run, and its position NEES (3 dof) is in the band [1, 6]
    (pooled mean; the EKF, told Gaussian noise, is far above)."""
    t, psi, lla = _straight_drive()
    clock = 200.0 - 3.0 * t
    out = {"ekf": [], "mix": []}
    nees = {"ekf": [], "mix": []}
    for seed in range(10):
        ep = _simulate(lla[1:], t[1:], clock[1:], 37.0, 3.0, seed=seed, bias=_urban(seed))
        for name, est in (("ekf", KalmanEstimator()), ("mix", EpochMixtureEstimator())):
            res, err, lay = _dr_run(ep, t, psi, lla, est, seed=seed)
            k = len(t) // 4
            out[name].append(float(np.sqrt(np.mean(err[k:, 0] ** 2 + err[k:, 1] ** 2))))
            P = res.pv_cov[:, 3:, 3:]
            nees[name] += [float(e @ np.linalg.solve(Pk, e)) for e, Pk in zip(err[k:], P[k:])]
    assert all(m < 0.5 * e for m, e in zip(out["mix"], out["ekf"])), (out["mix"], out["ekf"])
    assert 1.0 < np.mean(nees["mix"]) < 6.0, np.mean(nees["mix"])
    assert np.mean(nees["ekf"]) > 10.0


def test_signal_strength_bands_learn_where_the_delays_are():
    """Delayed rows mostly arrive weak (C/N0 25 dB-Hz with probability 0.8), clear ones
    strong (45 dB-Hz with probability 0.8): the per-band LOS weights learn it (weak band
    below 0.45, strong band above 0.75) and the banded filter is no worse than the
    single-weight one (mean over 6 seeds)."""
    from mixnav.gnss.pseudoranges import PseudorangeEpochs
    t, psi, lla = _straight_drive()
    clock = 200.0 - 3.0 * t
    rms = {(): [], (35.0,): []}
    weights = []
    for seed in range(6):
        bias = _urban(seed)
        ep = _simulate(lla[1:], t[1:], clock[1:], 37.0, 3.0, seed=seed, bias=bias)
        rng = np.random.default_rng(seed)
        tt = np.repeat(ep.time, np.diff(ep.start))
        delayed = np.array([bias(ti, [sid])[0] > 0 for ti, sid in zip(tt, ep.sat_id)])
        weak = np.where(delayed, rng.random(len(tt)) < 0.8, rng.random(len(tt)) < 0.2)
        ep = PseudorangeEpochs(ep.time, ep.start, ep.pseudorange, ep.variance, ep.sat_ecef, ep.sat_id, ep.system,
                               ep.elevation, np.where(weak, 25.0, 45.0))
        for edges in rms:
            est = EpochMixtureEstimator(cn0_edges=edges)
            res, err, lay = _dr_run(ep, t, psi, lla, est, seed=seed)
            k = len(t) // 4
            rms[edges].append(float(np.sqrt(np.mean(err[k:, 0] ** 2 + err[k:, 1] ** 2))))
            if edges:
                weights.append(est.w_band[:2].copy())
    w = np.mean(weights, axis=0)
    assert w[0] < 0.45 and w[1] > 0.75, w
    assert np.mean(rms[(35.0,)]) <= np.mean(rms[()]) * 1.02, rms


def test_correlated_errors_scale_the_update_as_an_ar1_mean():
    """With ``correlation_time`` tau, an epoch ``dt`` after the previous one is the Kalman
    update with the variances times ``(1 + rho) / (1 - rho)``, ``rho = exp(-dt / tau)`` (all
    rows LOS: closed form); the first epoch (no previous one) is the plain update."""
    P, H, r, z = _problem(3)
    est = EpochMixtureEstimator(los_weight=1.0, learn=False, correlation_time=2.0)
    est.init(_Motion(5), P, 0, np.random.default_rng(0))
    est.update(_epoch(z, H, r))
    assert np.allclose(est.P, kalman_correct(P, z, H, r, 1e4)[0], atol=1e-12)
    est.P = P.copy()
    ep = _epoch(z, H, r)
    ep.time = 0.2
    c = est.update(ep)
    rho = np.exp(-0.2 / 2.0)
    P_k, dx_k, _, _ = kalman_correct(P, z, H, r * (1 + rho) / (1 - rho), 1e4)
    assert np.allclose(c.dx, dx_k, atol=1e-12) and np.allclose(est.P, P_k, atol=1e-12)
    with pytest.raises(ArgumentError, match="correlation_time"):
        EpochMixtureEstimator(correlation_time=-1.0)
    with pytest.raises(ArgumentError, match="los_weight_bands"):
        EpochMixtureEstimator(cn0_edges=(35.0,), los_weight_bands=[0.5, 0.5])


def test_los_correlation_time_recovers_an_ar1():
    """Standardised AR(1) errors of 12 satellites at 5 Hz for 60 s with tau = 2 s: the
    estimate is within 15 % (the lag-one correlation from ~3500 pairs has a standard error
    near 0.01, i.e. about 6 % of tau); white errors give tau below 0.1 s (rho ~ 0 +- 0.03);
    rows judged delayed (g < 0.5) are left out."""
    from mixnav.alignment.track import los_correlation_time
    rng = np.random.default_rng(1)
    dt, tau, n_sat, n_ep = 0.2, 2.0, 12, 300
    rho = np.exp(-dt / tau)
    e = np.zeros((n_ep, n_sat))
    e[0] = rng.standard_normal(n_sat)
    for k in range(1, n_ep):
        e[k] = rho * e[k - 1] + np.sqrt(1 - rho ** 2) * rng.standard_normal(n_sat)
    t = np.repeat(np.arange(n_ep) * dt, n_sat)
    key = np.tile(np.arange(n_sat), n_ep)
    var = np.full(t.size, 25.0)
    g = np.ones(t.size)
    est = los_correlation_time(t, key, 5.0 * e.ravel(), var, g)
    assert abs(est - tau) < 0.15 * tau, est
    white = los_correlation_time(t, key, 5.0 * rng.standard_normal(t.size), var, g)
    assert white < 0.1, white
    g2 = g.copy()
    junk = e.ravel().copy()
    junk[::7] = 60.0 + 40.0 * rng.standard_normal(junk[::7].size)     # delayed rows, flagged
    g2[::7] = 0.0
    assert abs(los_correlation_time(t, key, 5.0 * junk, var, g2) - tau) < 0.2 * tau


def test_los_correlation_time_leaves_out_what_an_epoch_shares():
    """The same AR(1) errors (tau = 2 s) plus a slow error every satellite of an epoch shares
    (a track or clock error of the window's fit, a random walk of twice their sd): counted as
    each satellite's own it lengthens tau by half; ``common = True`` removes each epoch's
    mean first and recovers tau (within 20 %; the mean of 12 satellites takes 1/12 of each
    satellite's own error with it, which shortens tau a little)."""
    from mixnav.alignment.track import los_correlation_time
    rng = np.random.default_rng(2)
    dt, tau, n_sat, n_ep = 0.2, 2.0, 12, 300
    rho = np.exp(-dt / tau)
    e = np.zeros((n_ep, n_sat))
    e[0] = rng.standard_normal(n_sat)
    for k in range(1, n_ep):
        e[k] = rho * e[k - 1] + np.sqrt(1 - rho ** 2) * rng.standard_normal(n_sat)
    shared = np.cumsum(rng.standard_normal(n_ep)) * 0.15
    shared -= shared.mean()
    e = e + 2.0 * shared[:, None] / shared.std()
    t = np.repeat(np.arange(n_ep) * dt, n_sat)
    key = np.tile(np.arange(n_sat), n_ep)
    var = np.full(t.size, 25.0)
    g = np.ones(t.size)
    assert los_correlation_time(t, key, 5.0 * e.ravel(), var, g) > 1.4 * tau
    assert abs(los_correlation_time(t, key, 5.0 * e.ravel(), var, g, common=True) - tau) < 0.2 * tau


def test_a_filter_without_bands_of_its_own_takes_the_alignments():
    """The hand-over (vehicle_process.mixture_handover): bands named in [alignment] only reach
    an epoch mixture that sets no cn0_edges itself, with the LOS weights learned on them; its
    own edges win (an explicit [] means none: the band weights are dropped)."""
    from types import SimpleNamespace
    from mixnav.filters.epoch_mixture import EpochMixtureOptions, _build_epoch_mixture
    start = {"los_weight": 0.6, "delay_mean": 40.0, "delay_sd": 20.0, "correlation_time": 1.5,
             "cn0_edges": [30.0, 40.0], "los_weight_bands": [0.2, 0.5, 0.8, 0.6]}
    ctx = SimpleNamespace(extra={"mixture_start": start})
    est = _build_epoch_mixture(EpochMixtureOptions(), 1e4, ctx)
    np.testing.assert_array_equal(est.cn0_edges, [30.0, 40.0])
    np.testing.assert_array_equal(est.w_band0, [0.2, 0.5, 0.8, 0.6])
    assert est.start["mu"] == 40.0
    none = _build_epoch_mixture(EpochMixtureOptions(cn0_edges=[]), 1e4, ctx)
    assert len(none.cn0_edges) == 0 and none.w_band0 is None
    own = _build_epoch_mixture(EpochMixtureOptions(cn0_edges=[35.0]), 1e4, ctx)
    np.testing.assert_array_equal(own.cn0_edges, [35.0])
    assert start["cn0_edges"] == [30.0, 40.0]      # the hand-over itself is not changed
