"""Variational-Bayes adaptive noise (Sarkka & Nummenmaa 2009) on the EKF (VB-AKF) and the
UKF (VB-AUKF): the fixed point, convergence to a known constant noise, tracking a x5 jump,
and bad settings refused naming the key."""

from dataclasses import replace

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.errors import ArgumentError
from mixnav.experiment.run import solution_table
from mixnav.filters._ukf_kernels import vb_correct
from mixnav.filters.ukf import VbAdaptiveUkf
from mixnav.filters.vb_akf import ChannelNoise, VbAdaptiveEkf
from mixnav.geodesy.frames import displace
from mixnav.ins.error_model import get_layout
from mixnav.ins.imu_model import ImuErrorModel
from mixnav.measurements.kinds import POSITION, channel_id
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate


def test_the_iteration_stops_at_its_fixed_point():
    """With enough iterations the returned beta is the fixed point: the Kalman update
    with R = beta / alpha gives residual moments that reproduce beta (SN09 algorithm 1)."""
    rng = np.random.default_rng(4)
    n, m = 5, 3
    A = rng.standard_normal((n, n))
    P = A @ A.T + np.eye(n)
    H = rng.standard_normal((m, n))
    z = rng.standard_normal(m) * 3
    a0, b0 = np.full(m, 2.0), np.array([2.0, 5.0, 0.5])
    PHt = P @ H.T
    Pyy = H @ PHt
    x, Pp, nis, status, a, b, it = vb_correct(np.zeros(n), P, PHt, Pyy, Pyy, z, b0, a0, b0, True, 500, 1e-13, 1e4)
    assert status == 0 and it < 500
    np.testing.assert_array_equal(a, a0 + 0.5)
    R = b / a
    S = Pyy + np.diag(R)
    K = np.linalg.solve(S, PHt.T).T
    x_ref = K @ z
    P_ref = P - K @ S @ K.T
    e = z - H @ x_ref
    np.testing.assert_allclose(b, b0 + 0.5 * (e ** 2 + np.diag(H @ P_ref @ H.T)), rtol=1e-9)
    np.testing.assert_allclose(x, x_ref, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(Pp, P_ref, rtol=1e-8, atol=1e-12)


def test_a_scalar_constant_noise_is_learned_with_rho_one():
    """A random constant observed in noise of sigma 2, the model told sigma 1: with
    rho = 1 (no forgetting) the tracked sigma converges to 2. After 4000 epochs the
    variance estimate has a relative standard error of sqrt(2 / 4000) = 2 %, so sigma
    about 1 %; 4 % is 4 of those."""
    rng = np.random.default_rng(5)
    noise = ChannelNoise(rho=1.0, prior_shape=1.0, prior_scale=1.0, iterations=5, tolerance=1e-8)
    x, P = np.zeros(1), np.eye(1) * 100.0
    truth = 3.0
    ch = np.array([7])
    H = np.ones((1, 1))
    for k in range(4000):
        z = truth + 2.0 * rng.standard_normal() - x[0]
        a0, b0 = noise.predicted(ch, np.ones(1))
        PHt = P @ H.T
        Pyy = H @ PHt
        dx, P, nis, status, a, b, it = vb_correct(np.zeros(1), P, PHt, Pyy, Pyy, np.array([z]), np.ones(1), a0, b0,
                                                  True, noise.iterations, noise.tolerance, 1e4)
        x = x + dx
        noise.store(float(k), ch, a, b, it)
    assert abs(noise.sigma()[7] / 2.0 - 1.0) < 0.04, noise.sigma()


@pytest.fixture(scope="module")
def demo():
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, 3, src)
    return sc, sim, np.asarray(sc.gnss.lever_arm, dtype=float)


def _pos_sigma(res):
    o = res.outputs
    ch = o["vb_channel"][0]
    cols = [list(ch).index(channel_id(POSITION, a)) for a in range(3)]
    return o["vb_time"], o["vb_sigma"][:, cols]


@pytest.mark.parametrize("cls", [VbAdaptiveEkf, VbAdaptiveUkf])
def test_a_constant_noise_is_learned_on_the_ins(demo, cls):
    """loose-demo's fixes have the noise they report (1.5, 1.5, 3 m); the filter starts
    from a variance 4x too large (prior_scale 4) and rho = 1. Over 540 epochs the sample
    variance of one channel has a relative standard error of about sqrt(2/540) = 6 %
    (sigma 3 %); the INS's own error adds to the residuals early on: 12 %."""
    sc, sim, lever = demo
    f = cls(get_layout(15), sim.imu_model, rho=1.0, prior_scale=4.0)
    res = f.run(sim.imu, sim.init, [LooseGnss(sim.fixes, lever, f.layout)])
    t, s = _pos_sigma(res)
    assert np.abs(s[-1] / sim.fixes.pos_sigma[-1] - 1).max() < 0.12, s[-1]


def _jumped(sim, t_jump, factor, seed=11):
    """The fixes with their position noise sd times ``factor`` from ``t_jump`` on (the
    reported sigma unchanged): extra N(0, (factor^2 - 1) sigma^2) NED metres."""
    f = sim.fixes
    rng = np.random.default_rng(seed)
    sel = f.time >= t_jump
    extra = np.zeros_like(f.lla)
    extra[sel] = rng.standard_normal((sel.sum(), 3)) * f.pos_sigma[sel] * np.sqrt(factor ** 2 - 1)
    return replace(f, lla=displace(f.lla, extra))


@pytest.mark.parametrize("cls", [VbAdaptiveEkf, VbAdaptiveUkf])
def test_the_tracked_sigma_follows_a_x5_jump(demo, cls):
    """Position noise x5 from t = 120 s (loose-demo's outage is 300-360 s). With rho = 0.9
    (memory about 10 epochs) the tracked horizontal sigma (mean of north and east) passes
    80 % of the new level within 15 epochs of the jump (measured: 9), and over the 50-170 s after it
    stays within 15 % of it on average (measured: 0.3 %) (one channel's variance with ~10 epochs of memory
    scatters by about sqrt(2/19) = 32 %; averaged over 120 epochs and two channels what
    is left is the bias). Position NEES there in [1.5, 5] (measured 3.6; the EKF told the old
    sigma: 51)."""
    sc, sim, lever = demo
    t_jump = 120.0
    fixes = _jumped(sim, t_jump, 5.0)
    f = cls(get_layout(15), sim.imu_model, rho=0.9)
    res = f.run(sim.imu, sim.init, [LooseGnss(fixes, lever, f.layout)])
    t, s = _pos_sigma(res)
    true_h = 5.0 * sim.fixes.pos_sigma[0, 0]
    sh = s[:, :2].mean(axis=1)
    after = t >= t_jump
    k_reach = np.argmax(sh[after] > 0.8 * true_h)
    assert sh[after][k_reach] > 0.8 * true_h and k_reach <= 15, k_reach
    late = (t >= t_jump + 50) & (t <= t_jump + 170)
    assert abs(sh[late].mean() / true_h - 1) < 0.15, sh[late].mean() / true_h
    tab = solution_table(res, sim.truth)
    nees = tab["nees_pos"][(tab.time_s > t_jump + 50) & (tab.time_s < t_jump + 170)].mean()
    assert 1.5 < nees < 5.0, nees


@pytest.mark.parametrize("kw,key", [(dict(rho=0.0), "rho"), (dict(rho=1.2), "rho"), (dict(prior_shape=0.0), "prior_shape"),
                                    (dict(prior_scale=-1.0), "prior_scale"), (dict(iterations=0), "iterations"),
                                    (dict(tolerance=-1e-3), "tolerance")])
@pytest.mark.parametrize("cls", [VbAdaptiveEkf, VbAdaptiveUkf])
def test_bad_vb_settings_name_the_key(cls, kw, key):
    with pytest.raises(ArgumentError) as e:
        cls(get_layout(15), ImuErrorModel(), **kw)
    assert e.value.argument == key


# --- from scenario files -------------------------------------------------------------------
from mixnav.config import load_scenario as _load  # noqa: E402
from mixnav.errors import ConfigError  # noqa: E402

BASE = _load("loose-demo")[2]


def _scenario(tmp_path, method_lines):
    text = BASE[:BASE.index("[[methods]]")] + "[[methods]]\nname = \"m\"\ntype = \"loose-ekf\"\n" + method_lines
    p = tmp_path / "sc.toml"
    p.write_text(text)
    return _load(str(p))


@pytest.mark.parametrize("est,line,where", [
    ("vb-aukf", "rho = 1.5", "options.rho"), ("vb-akf", "rho = 0", "options.rho"),
    ("vb-akf", "prior_shape = -1", "options.prior_shape"), ("vb-aukf", "iterations = 0", "options.iterations"),
    ("ukf", "alpha = \"big\"", "options.alpha"), ("ukf", "rho = 0.9", "options.rho"),
    ("vb-aukf", "prior_scale = 0", "options.prior_scale")])
def test_bad_values_in_a_scenario_file_are_config_errors_naming_the_key(tmp_path, est, line, where):
    with pytest.raises(ConfigError) as e:
        _scenario(tmp_path, f'estimator = "{est}"\n[methods.options]\n{line}\n')
    assert e.value.key == f"methods[0].{where}"
    if est == "ukf" and where == "options.rho":
        assert "has no option 'rho'" in str(e.value)


def test_a_centre_weight_that_breaks_positivity_is_refused_when_built(tmp_path):
    """alpha = 0.3 passes the schema (> 0) but with 21 states gives wc0 < 0: the filter
    refuses it when the method is built, and the error names the file's key."""
    from mixnav.experiment import methods
    sc, src, _ = _scenario(tmp_path, 'estimator = "ukf"\nstates = 21\n[methods.options]\nalpha = 0.3\n')
    sim = simulate(sc, 1, src)
    with pytest.raises(ConfigError, match="negative") as e:
        methods.build(sc.methods[0], sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0)
    assert e.value.key == "methods[0].options.alpha"


def test_the_p5_scenario_runs_and_reports_the_tracked_sigma():
    """The shipped P5-aircraft file builds all five methods; a VB method's solution table
    carries vb_sigma_<channel> columns, its metrics vb_sigma_mean, and the true sd of the
    scenario's position-noise profile is x5 inside the jump (the velocity noise as stated)."""
    from mixnav.experiment.run import gnss_noise_sd, method_metrics, run_scenario
    sc, src, _ = load_scenario("P5-aircraft")
    assert [m.estimator for m in sc.methods] == ["ekf", "ukf", "vb-akf", "sage-husa", "vb-aukf"]
    sd = gnss_noise_sd(sc, src, np.array([100.0, 500.0, 1100.0]))
    np.testing.assert_allclose(sd["position_n"], [2.0, 10.0, 8.0])
    np.testing.assert_allclose(sd["velocity_d"], [0.2, 0.2, 0.2])
    sc = sc.model_copy(update={"methods": [sc.methods[4]]})
    out = run_scenario(sc, src, seed=1)
    res = out.results["vb-aukf"]
    tab = solution_table(res, out.sim.truth)
    assert {f"vb_sigma_{k}_{a}" for k in ("position", "velocity") for a in "ned"} <= set(tab.columns)
    m = method_metrics(res, tab, ())
    assert set(m["vb_sigma_mean"]) == {f"{k}_{a}" for k in ("position", "velocity") for a in "ned"}


def test_per_satellite_channels_get_their_own_columns():
    """Tight coupling: the channels are satellites that rise and set; each gets its own
    vb_sigma_<kind>_<prn> column, held from its own updates (not the row position)."""
    from mixnav.experiment.run import _noise_columns

    class R:
        time = np.array([0.5, 1.0, 2.0, 3.0])
        outputs = {"vb_time": np.array([1.0, 2.0, 3.0]),
                   "vb_channel": np.array([[8005, 8007], [8007, 8009], [8009, -1]]),
                   "vb_sigma": np.array([[1.0, 2.0], [3.0, 4.0], [5.0, np.nan]])}

    from mixnav.measurements.kinds import channel_id, kind_code
    pr = kind_code("pseudorange")
    R.outputs["vb_channel"] = np.where(R.outputs["vb_channel"] >= 0,
                                       channel_id(pr, R.outputs["vb_channel"] - 8000), -1)
    cols = _noise_columns(R)
    assert list(cols) == ["vb_sigma_pseudorange_5", "vb_sigma_pseudorange_7", "vb_sigma_pseudorange_9"]
    np.testing.assert_array_equal(cols["vb_sigma_pseudorange_5"], [np.nan, 1.0, 1.0, 1.0])
    np.testing.assert_array_equal(cols["vb_sigma_pseudorange_7"], [np.nan, 2.0, 3.0, 3.0])
    np.testing.assert_array_equal(cols["vb_sigma_pseudorange_9"], [np.nan, np.nan, 4.0, 5.0])


def test_channel_ids_round_trip_and_label_every_scheme():
    """One channel-id scheme for every model (measurements.kinds.channel_id): the parts
    come back, ids sort by kind, then system, then satellite or axis, and the labels of
    the noise columns name the observable and the satellite. The multi-system
    pseudorange channels had their own scheme, which the label read as another kind
    (smartLoc's GPS 12 pseudorange was labelled 'range_rate_12')."""
    from mixnav.filters.vb_akf import channel_label
    from mixnav.measurements.kinds import channel_parts, kind_code
    pr, vel = kind_code("pseudorange"), kind_code("velocity")
    ids = channel_id(np.array([pr, pr, pr, vel]), np.array([12, 5, 12, 2]), np.array([1, 8, 0, 0]))
    assert [channel_parts(c) for c in ids] == [(pr, 1, 12), (pr, 8, 5), (pr, 0, 12), (vel, 0, 2)]
    assert sorted(ids.tolist()) == [ids[2], ids[0], ids[1], ids[3]]
    assert [channel_label(c) for c in ids] == ["pseudorange_G12", "pseudorange_E05", "pseudorange_12", "velocity_d"]
