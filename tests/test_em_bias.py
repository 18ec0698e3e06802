"""EM estimate of a GNSS multipath bias (P4 eqs. 17-27): the fit on a window with a known
bias, no bias declared in one cloud, the settings' errors, and the filter removing it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mixnav.errors import ArgumentError
from mixnav.filters.em_bias import EmBiasKalman, EmBiasSettings, fit_bias


def _window(rng, n=60, bias=(10.0, 0.0, 0.0), p=0.3):
    """P4's multipath: 0.7 N(0, 1 m^2) + 0.3 N(bias, 4 m^2) per axis."""
    Y = rng.normal(0.0, 1.0, (n, 3))
    b = rng.random(n) < p
    Y[b] = rng.normal(bias, 2.0, (b.sum(), 3))
    return Y, b


def test_em_recovers_a_known_bias():
    """Over 20 windows of 60 epochs (~18 biased), the fitted bias is within 1.5 m of the
    true 10 m offset on every window: its error is the mean of ~18 N(0, 4) samples minus
    that of ~42 N(0, 1) samples, about 0.5 m per axis (1-sigma), so its norm is below 2 m
    (4 sigma; chi with 3 dof exceeds 4 with probability 1e-3); the mean error over the
    windows is below 0.3 m (no systematic pull: 0.5 / sqrt(20) = 0.11 m per axis)."""
    rng = np.random.default_rng(0)
    errs = []
    for k in range(20):
        Y, _ = _window(rng)
        r = fit_bias(Y, EmBiasSettings(), np.random.default_rng(k))
        assert r is not None
        errs.append(r[0] - np.array([10.0, 0.0, 0.0]))
    errs = np.array(errs)
    assert np.linalg.norm(errs, axis=1).max() < 2.0, errs
    assert np.linalg.norm(errs.mean(axis=0)) < 0.3, errs.mean(axis=0)


def test_no_bias_declared_in_one_cloud():
    """Innovations from one N(0, 1) cloud: EM may split it, but never 3 m apart, so no bias is
    declared (20 windows)."""
    rng = np.random.default_rng(1)
    for k in range(20):
        assert fit_bias(rng.normal(0, 1, (60, 3)), EmBiasSettings(), np.random.default_rng(k)) is None


@pytest.mark.parametrize("kw, arg", [({"window": 0.0}, "window"), ({"min_samples": 1}, "min_samples"),
                                     ({"max_state_sigma": -1.0}, "max_state_sigma"), ({"gate": 0.2}, "gate"),
                                     ({"min_separation": 0.0}, "min_separation"), ({"min_weight": 0.6}, "min_weight")])
def test_settings_are_checked(kw, arg):
    with pytest.raises(ArgumentError) as e:
        EmBiasSettings(**kw)
    assert e.value.argument == arg


def test_filter_removes_the_bias_in_a_multipath_window():
    """loose-demo's trajectory with RTK-grade fixes (0.05 m, as P4's) and P4's multipath
    (0.7 N(0, 1) + 0.3 N(10 m north, 4)) from 150 to 300 s: the EKF whose GNSS rows pass
    through the EM bias removal has a maximum horizontal error there below 0.7 of the plain
    EKF's (both told R = 1 m^2 per axis, the clean component), and the bias it removes at
    the epochs it calls biased is 10 m north within 1.5 m on average."""
    from mixnav.config.loader import load_scenario
    from mixnav.engine import Engine
    from mixnav.experiment.run import solution_table
    from mixnav.filters.ekf import KalmanEstimator
    from mixnav.geodesy.frames import displace
    from mixnav.ins.error_model import get_layout
    from mixnav.ins.strapdown import StrapdownMotion
    from mixnav.measurements.loose import LooseGnss
    from mixnav.sim.scenario import simulate
    from mixnav.data import GnssFixes
    from mixnav.experiment.run import truth_at
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    rng = np.random.default_rng(7)
    t = sim.fixes.time
    tr = truth_at(sim.truth, t)
    fx = GnssFixes(t, displace(tr.lla, rng.normal(0, 0.05, (len(t), 3))), np.full((len(t), 3), 1.0),
                   tr.v_n + rng.normal(0, 0.05, (len(t), 3)), np.full((len(t), 3), 0.05))
    win = (fx.time >= 150) & (fx.time <= 300)
    off = np.zeros((len(fx.time), 3))
    Y, b = _window(rng, int(win.sum()))
    off[win] = Y
    fixes = replace(fx, lla=displace(fx.lla, off))
    lay = get_layout(15)
    gnss = LooseGnss(fixes, np.zeros(3), lay)
    motion = StrapdownMotion(lay, sim.imu_model)
    out = {}
    for name, est in (("ekf", KalmanEstimator()), ("em", EmBiasKalman({gnss}))):
        res = Engine(motion, est, [gnss], rng=np.random.default_rng(0)).run(sim.imu, sim.init)
        t = solution_table(res, sim.truth, ((150, 300),))
        o = t[t.in_outage]
        out[name] = float(np.hypot(o.err_n_m, o.err_e_m).max())
    o = est.outputs()
    applied = (np.linalg.norm(o["bias"], axis=1) > 0) & (o["bias_times"] >= 150) & (o["bias_times"] <= 300)
    assert applied.sum() > 0.5 * b.sum(), (applied.sum(), b.sum())
    assert np.linalg.norm(o["bias"][applied].mean(axis=0) - [10.0, 0.0, 0.0]) < 1.5, o["bias"][applied].mean(axis=0)
    assert out["em"] < 0.7 * out["ekf"], out
    assert not np.any(o["bias"][o["bias_times"] > 360])


def test_bias_metrics_against_the_systematic_error():
    """bias_metrics by hand: 4 logged epochs (one not a fix time, ignored), true bias 10 m
    north-east on two of them; removals on epochs 0 (right within (0.3, -0.4, 0)), 1 (clean:
    a false removal) and none on the biased epoch 3 (missed)."""
    from types import SimpleNamespace
    from mixnav.experiment.run import bias_metrics
    tb = np.array([1.0, 2.0, 3.0, 4.0])
    b_true = np.array([[10.0, 10.0, 0.0], [0, 0, 0], [0, 0, 0], [10.0, 10.0, 0.0]])
    est = np.array([[10.3, 9.6, 0.0], [1.0, 0.0, 0.0], [0, 0, 0], [0, 0, 0], [5.0, 5.0, 5.0]])
    res = SimpleNamespace(outputs={"bias_times": np.array([1.0, 2.0, 3.0, 4.0, 4.5]), "bias": est})
    m = bias_metrics(res, (tb, b_true))
    assert m["bias_epochs_removed"] == 2 and m["bias_epochs_biased"] == 2
    assert m["bias_error_rms_m"] == pytest.approx(np.sqrt((0.3 ** 2 + 0.4 ** 2 + 1.0) / 2))
    assert m["bias_error_horizontal_axis_rms_m"] == pytest.approx(np.sqrt((0.09 + 0.16 + 1.0 + 0.0) / 4))
    assert m["bias_false_share"] == 0.5 and m["bias_detected_share"] == 0.5
    assert bias_metrics(res, None) == {} and bias_metrics(SimpleNamespace(outputs={}), (tb, b_true)) == {}
