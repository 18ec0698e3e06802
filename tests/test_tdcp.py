"""Pseudorange + TDCP by stochastic cloning: Jacobian, engine bookkeeping, consistency."""

import numpy as np
import pytest

from mixnav.attitude import quat_multiply, quat_to_dcm, rotvec_to_quat
from mixnav.config.loader import load_scenario, resolve
from mixnav.errors import ConfigError
from mixnav.experiment.run import run_scenario, solution_table
from mixnav.geodesy.frames import dcm_ecef_to_ned, displace, lla_to_ecef
from mixnav.gnss.constellation import NominalConstellation
from mixnav.gnss.observables import simulate_observables
from mixnav.ins.error_model import get_layout
from mixnav.measurements.tdcp import TdcpGnss
from mixnav.sim.scenario import truth_and_ideal_imu

LEVER = np.array([0.5, 0.2, -1.0])


@pytest.fixture(scope="module")
def scenario():
    sc, src, _ = load_scenario("tdcp-demo")
    return sc, src, truth_and_ideal_imu(sc, src)


@pytest.mark.parametrize("clone", [True, False])
def test_compiled_tdcp_rows_equal_the_numpy_model(scenario, clone):
    """The compiled TDCP rows of measure() against the numpy oracle at every
    epoch of a drive, with and without the clone columns."""
    _, _, (truth, _) = scenario
    o = simulate_observables(truth, NominalConstellation.gps(5), 1.0, LEVER, np.radians(10), 1.0, 0.1,
                             0.003, (0.1, 0.01), (5.0, 0.3), np.random.default_rng(2))
    lay = get_layout(17)
    meas = TdcpGnss(o, LEVER, lay, clone=clone)
    kt = lambda i: int(np.searchsorted(truth.time, o.time[i] - 1e-9))  # noqa: E731
    checked = 0
    for k in range(1, len(o.time), 7):
        nav_prev = np.concatenate([truth.q_nb[kt(k - 1)], truth.v_n[kt(k - 1)], truth.lla[kt(k - 1)]])
        mem = meas.remember(k - 1, nav_prev, np.zeros(3), np.array([4.0, 0.3]))
        nav = np.concatenate([truth.q_nb[kt(k)], truth.v_n[kt(k)], truth.lla[kt(k)]]) + 1e-7
        clock = np.array([4.3, 0.3])
        z, H, r = meas.measure(k, nav, np.zeros(3), clock, mem)
        n_pr = int(o.valid[k].sum())
        zt, Ht, rt = meas.tdcp_rows_numpy(k, nav, clock, mem)
        np.testing.assert_allclose(z[n_pr:], zt, rtol=0, atol=1e-7)    # metres of 2e7 m ranges
        np.testing.assert_allclose(H[n_pr:], Ht, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(r[n_pr:], rt)
        checked += len(zt)
    assert checked > 100


def _perturbed(nav, w, dx):
    """The true state that the error ``dx = x_true - x_est`` describes."""
    q = quat_multiply(rotvec_to_quat(dx[0:3]), nav[0:4])
    return np.concatenate([q, nav[4:7] + dx[3:6], displace(nav[7:10], dx[6:9])]), w - dx[9:12]


def test_tdcp_jacobian_matches_finite_differences(scenario):
    _, _, (truth, _) = scenario
    o = simulate_observables(truth, NominalConstellation.gps(5), 1.0, LEVER, np.radians(10), 1.0, 0.1,
                             0.003, (0.1, 0.01), (5.0, 0.3), np.random.default_rng(1))
    lay = get_layout(17)
    meas = TdcpGnss(o, LEVER, lay)
    k = 150
    kt = lambda i: int(np.searchsorted(truth.time, o.time[i] - 1e-9))  # noqa: E731
    nav_prev = np.concatenate([truth.q_nb[kt(k - 1)], truth.v_n[kt(k - 1)], truth.lla[kt(k - 1)]])
    mem = meas.remember(k - 1, nav_prev, np.zeros(3), np.array([4.0, 0.3]))
    nav = np.concatenate([truth.q_nb[kt(k)], truth.v_n[kt(k)], truth.lla[kt(k)]])
    w, clock = np.array([0.01, -0.02, 0.3]), np.array([4.3, 0.3])
    z0, H, r = meas.measure(k, nav, w, clock, mem)
    n_pr = int(o.valid[k].sum())
    assert H.shape == (len(z0), 21) and len(z0) > n_pr  # pseudoranges, then TDCP rows
    np.testing.assert_allclose(r[n_pr:], 2 * 0.003 ** 2)
    # z = measured - h(x): a true-state change dx moves z by -H dx
    steps = {**{i: 1e-4 for i in range(3)}, **{i: 1e-3 for i in range(3, 9)}, 15: 1e-3}
    for i, eps in steps.items():
        dx = np.zeros(17)
        dx[i] = eps
        nav_t, w_t = _perturbed(nav, w, dx)
        z, _, _ = meas.measure(k, nav_t, w_t, clock + dx[15:17], mem)
        np.testing.assert_allclose(-(z - z0) / eps, H[:, i], rtol=2e-3, atol=2e-3)
    for j in range(4):  # the clone: the remembered antenna position (NED) and clock bias
        dxc = np.zeros(4)
        dxc[j] = 1e-3
        z, _, _ = meas.measure(k, nav, w, clock, meas.correct_memory(mem, dxc))
        np.testing.assert_allclose(-(z - z0) / 1e-3, H[:, 17 + j], atol=2e-3)
    assert np.all(H[:n_pr, 17:] == 0)


def test_clone_rows_give_the_antenna_position_error():
    lay = get_layout(17)
    meas = TdcpGnss.__new__(TdcpGnss)  # only the lever arm and layout are needed
    meas.lever, meas.layout = LEVER, lay
    nav = np.array([np.cos(0.3), 0, 0, np.sin(0.3), 0, 0, 0, 0.6, 2.0, 50.0])
    J = meas.clone_rows(nav)
    # antenna NED displacement for an attitude + position error, by direct evaluation
    dx = np.zeros(17)
    dx[[0, 1, 2, 6, 7, 8, 15]] = [1e-4, -2e-4, 3e-4, 0.3, -0.2, 0.1, 2.0]
    def antenna(nv):  # numpy, independent of the compiled helper
        C_ne = dcm_ecef_to_ned(nv[7], nv[8])
        return lla_to_ecef(nv[7:10]) + C_ne.T @ quat_to_dcm(nv[0:4]) @ LEVER, C_ne
    r0, C_ne = antenna(nav)
    np.testing.assert_allclose(meas._antenna(nav)[0], r0, atol=1e-6)
    nav_t, _ = _perturbed(nav, np.zeros(3), dx)
    r1, _ = antenna(nav_t)
    np.testing.assert_allclose(J[:3] @ dx, C_ne @ (r1 - r0), atol=1e-5)
    assert J[3] @ dx == 2.0


@pytest.fixture(scope="module")
def tdcp_runs(scenario):
    sc, src, ideal = scenario
    tables = {m.name: [] for m in sc.methods}
    for seed in range(8):
        out = run_scenario(sc, src, seed=seed, ideal=ideal)
        for name, res in out.results.items():
            assert sum(res.recoveries.values()) == 0
            tables[name].append(solution_table(res, out.sim.truth, out.sim.outages))
    return tables


def test_cloning_is_consistent_and_the_shortcut_is_not(tdcp_runs):
    # Run-averaged NEES over 8 runs and the drive. With cloning the filter's own
    # covariance must bound the errors: its mean NEES per dof is expected below 1,
    # because successive TDCPs share a carrier epoch (correlation -1/2) that the
    # filter treats as white, which overstates the noise of a sum of TDCPs
    # (benchmarks/results/tight.md); a wrong Jacobian or clone bookkeeping pushes it
    # far above 1. Taking the previous position as known collapses the position
    # covariance to millimetres: its NEES is orders of magnitude above the dof.
    nees = {k: np.mean([t["nees_pos"].mean() for t in v]) / 3 for k, v in tdcp_runs.items()}
    nees_v = {k: np.mean([t["nees_vel"].mean() for t in v]) / 3 for k, v in tdcp_runs.items()}
    assert 0.3 < nees["tdcp"] < 1.2 and 0.3 < nees_v["tdcp"] < 1.2, (nees, nees_v)
    assert 0.6 < nees["pr-only"] < 1.3, nees
    assert nees["tdcp-known"] > 100 * nees["tdcp"], nees


def test_tdcp_improves_velocity_and_attitude_over_pseudorange_only(tdcp_runs):
    # RMS over 8 runs. Velocity: TDCP measures the displacement to millimetres
    # (0.17 -> 0.01 m/s over 20 runs); roll and pitch follow (about 2x). Yaw is
    # unobservable in the first 60 s at rest (whole-run RMSE is mostly the initial
    # 2 deg error, equal for both), so it is compared after 150 s (4.5x over 8 runs).
    def rms(ts, cols, t0=0.0):
        return np.sqrt(np.mean([np.mean(sum(t[t.time_s > t0][c] ** 2 for c in cols)) for t in ts]))
    vel = ("err_vn_mps", "err_ve_mps", "err_vd_mps")
    tilt = ("err_roll_deg", "err_pitch_deg")
    a, b = tdcp_runs["tdcp"], tdcp_runs["pr-only"]
    assert rms(a, vel) < 0.2 * rms(b, vel)
    assert rms(a, tilt) < 0.7 * rms(b, tilt)
    assert rms(a, ("err_yaw_deg",), 150.0) < 0.5 * rms(b, ("err_yaw_deg",), 150.0)


def test_tdcp_method_config_errors(tmp_path):
    text, _ = resolve("tdcp-demo")
    p = tmp_path / "a.toml"
    p.write_text(text.replace('tdcp_previous = "known"', 'tdcp_previous = "exact"'))
    with pytest.raises(ConfigError) as exc:
        load_scenario(str(p))
    assert exc.value.key == "methods[2].tdcp_previous" and str(p) in str(exc.value)
    p.write_text(text.replace('carrier_sigma = "3 mm"', 'carrier_sigma = "3"'))
    with pytest.raises(ConfigError) as exc:
        load_scenario(str(p))
    assert exc.value.key == "gnss.satellites.carrier_sigma"
    p.write_text(text.replace('carrier_sigma = "3 mm"', 'carrier_sigmas = "3 mm"'))
    with pytest.raises(ConfigError, match="unknown key") as exc:
        load_scenario(str(p))
    assert exc.value.key == "gnss.satellites.carrier_sigmas"
    p.write_text(text.replace('mask = "10 deg"', 'mask = "10 deg"\noutages = [{ window = ["1 s", "9 s"], '
                                                  'keep = 2, fraction = 1.5 }]'))
    with pytest.raises(ConfigError) as exc:
        load_scenario(str(p))
    assert exc.value.key == "gnss.satellites.outages[0].fraction"


@pytest.mark.parametrize("rule", ["keep = 0", "keep = 1", "keep = 2, fraction = 0.5", "prns = [1, 2, 3, 4, 5, 6, 7, 8]"])
def test_too_few_satellites_never_crash(tmp_path, scenario, rule):
    # Satellites lost for 40 s (all, all but one, half of the epochs with 2, or a PRN list):
    # every filter keeps running, uses what there is (an epoch without satellites is
    # skipped), counts no recovery, and is back near its normal error 60 s later.
    text, _ = resolve("tdcp-demo")
    text = text.replace('carrier_sigma = "3 mm"                               # TDCP noise sigma = sqrt(2) * 3 mm',
                        f'carrier_sigma = "3 mm"\noutages = [{{ window = ["200 s", "240 s"], {rule} }}]')
    p = tmp_path / "few.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    out = run_scenario(sc, src, seed=3, ideal=scenario[2])
    o = out.sim.observations
    inside = (o.time >= 200) & (o.time < 240)
    if rule.startswith("keep"):
        assert o.n_visible[inside].min() == int(rule.split()[2].rstrip(","))
    if "fraction" in rule:
        assert np.mean(o.n_visible[inside] == 2) == pytest.approx(0.5, abs=0.03)
    for name, res in out.results.items():
        assert sum(res.recoveries.values()) == 0, name
        t = solution_table(res, out.sim.truth, out.sim.outages)
        if rule == "keep = 0":
            assert not t["gnss_used"][(t.time_s > 200.5) & (t.time_s < 240)].any()
        late = t[t.time_s > 300]
        assert np.hypot(late.err_n_m, late.err_e_m).max() < 10.0, name
