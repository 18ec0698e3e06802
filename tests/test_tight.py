"""Raw observables, the receiver clock and the tightly coupled EKF."""

import numpy as np
import pytest

from mixnav.attitude import quat_multiply, rotvec_to_quat
from mixnav.config.loader import load_scenario, resolve
from mixnav.errors import ConfigError
from mixnav.experiment.montecarlo import run_experiment, write_experiment_outputs
from mixnav.geodesy.frames import displace, lla_to_ecef
from mixnav.gnss.clock import clock_increment_covariance, simulate_clock
from mixnav.gnss.constellation import NominalConstellation
from mixnav.gnss.geometry import LAMBDA_L1
from mixnav.gnss.observables import SatelliteOutage, simulate_observables
from mixnav.ins.error_model import get_layout
from mixnav.measurements.tight import TightGnss
from mixnav.sim.scenario import truth_and_ideal_imu

SATS = NominalConstellation.gps(5)


@pytest.fixture(scope="module")
def truth():
    sc, _, _ = load_scenario("tight-demo")
    return truth_and_ideal_imu(sc)[0]


def _noiseless(truth, rate=1.0, **kw):
    return simulate_observables(truth, SATS, rate, np.array([0.5, 0.2, -1.0]), np.radians(10), 1e-12,
                                1e-12, 1e-12, (0.0, 0.0), (7.0, 0.5), np.random.default_rng(0), **kw)


def test_clock_increments_have_the_closed_form_covariance():
    # 4000 independent two-epoch walks: sample covariance of the increment vs the
    # closed form; 4000 samples give ~2 % standard error on each variance, 10 % tolerance
    rng = np.random.default_rng(3)
    qb, qd, dt = 0.2, 0.05, 2.0
    inc = np.array([simulate_clock(np.array([0.0, dt]), qb, qd, 0.0, 0.0, rng)[1] for _ in range(4000)])
    C = clock_increment_covariance(dt, qb, qd)
    S = np.cov(inc.T)
    np.testing.assert_allclose(np.diag(S), np.diag(C), rtol=0.1)
    assert S[0, 1] == pytest.approx(C[0, 1], rel=0.15)


def test_noiseless_pseudorange_is_range_plus_clock(truth):
    o = _noiseless(truth)
    k = 100
    kt = int(np.searchsorted(truth.time, o.time[k] - 1e-9))
    # antenna from the truth, independently of the simulator's helper
    from mixnav.attitude import quat_to_dcm
    from mixnav.geodesy.frames import dcm_ecef_to_ned
    C_ne = dcm_ecef_to_ned(truth.lla[kt, 0], truth.lla[kt, 1])
    r = lla_to_ecef(truth.lla[kt]) + C_ne.T @ quat_to_dcm(truth.q_nb[kt]) @ np.array([0.5, 0.2, -1.0])
    v = o.valid[k]
    rng = np.linalg.norm(o.sat_pos[k, v] - r, axis=1)
    np.testing.assert_allclose(o.pseudorange[k, v], rng + o.clock[k, 0], atol=1e-6)
    assert o.clock[0].tolist() == [7.0, 0.5] and o.clock[k, 0] == pytest.approx(7.0 + 0.5 * o.time[k] - 0.5
                                                                                  * o.time[0])
    # the carrier differs from the pseudorange by a whole number of wavelengths, constant per satellite
    n_cyc = (o.carrier - o.pseudorange) / LAMBDA_L1
    np.testing.assert_allclose(n_cyc[o.valid], np.round(n_cyc[o.valid]), atol=1e-4)


def test_range_rate_is_the_derivative_of_the_pseudorange(truth):
    o = _noiseless(truth, rate=10.0)
    dt = 0.1
    for k in (50, 1500, 3500):  # straight, turning, ...
        common = set(o.prn[k - 1][o.valid[k - 1]]) & set(o.prn[k + 1][o.valid[k + 1]]) & \
            set(o.prn[k][o.valid[k]])
        for p in common:
            a, b, c = (int(np.nonzero(o.prn[j] == p)[0][0]) for j in (k - 1, k, k + 1))
            fd = (o.pseudorange[k + 1, c] - o.pseudorange[k - 1, a]) / (2 * dt)
            assert o.range_rate[k, b] == pytest.approx(fd, abs=2e-3)


def test_coloured_noise_follows_its_satellite_across_slots(truth):
    # An AR(1) on the range rate is sampled per satellite: when a lost satellite shifts
    # the others to new slots, each satellite's noise stays one AR(1) series (lag-1
    # correlation 0.9), which a per-slot draw would break at every shift.
    from mixnav.noise.processes import AR1
    first = _noiseless(truth)
    lost = int(first.prn[0, 0])  # the first slot's satellite: losing it shifts all others
    o = _noiseless(truth, satellite_outages=[SatelliteOutage(100.0, 400.0, prns=(lost,))],
                   range_rate_noise=AR1(coefficient=0.9, sigma=0.05))
    e = o.range_rate - _noiseless(truth, satellite_outages=[SatelliteOutage(100.0, 400.0, prns=(lost,))]).range_rate
    p = int(o.prn[0, 1])
    slots = [np.nonzero(o.prn[k] == p)[0] for k in range(len(o))]
    assert len({int(sl[0]) for sl in slots if len(sl)}) > 1  # the satellite did change slot
    series = np.array([e[k, sl[0]] for k, sl in enumerate(slots) if len(sl)])
    r1 = np.corrcoef(series[:-1], series[1:])[0, 1]
    assert r1 == pytest.approx(0.9, abs=0.05)


def test_satellite_outage_keeps_the_highest(truth):
    o = _noiseless(truth, satellite_outages=[SatelliteOutage(300.0, 360.0, keep=3)])
    inside = (o.time >= 300) & (o.time < 360)
    assert (o.n_visible[inside] == 3).all() and (o.n_visible[~inside] >= 7).all()
    full = _noiseless(truth)
    k = int(np.nonzero(inside)[0][0])
    kept = np.sort(o.elevation[k][o.valid[k]])
    assert np.allclose(kept, np.sort(full.elevation[k][full.valid[k]])[-3:])


def test_jacobian_matches_finite_differences(truth):
    o = _noiseless(truth)
    lay = get_layout(17)
    meas = TightGnss(o, [0.5, 0.2, -1.0], lay)
    k = 200
    kt = int(np.searchsorted(truth.time, o.time[k] - 1e-9))
    nav = np.concatenate([truth.q_nb[kt], truth.v_n[kt], truth.lla[kt]])
    w = np.array([0.01, -0.02, 0.3])
    clock = np.array([3.0, 0.2])
    _, H, _ = meas.measure(k, nav, w, clock)
    pr0, rr0, *_ = meas.predict(k, nav, w, clock)
    h0 = np.concatenate([pr0, rr0])
    # steps large enough that the change of a 2e7 m range is far above its rounding
    steps = {**{i: 1e-4 for i in range(3)}, **{i: 1e-3 for i in range(3, 9)},
             **{i: 1e-5 for i in range(9, 12)}, 15: 1e-3, 16: 1e-3}
    for i, eps in steps.items():
        dx = np.zeros(17)
        dx[i] = eps
        # the true state that this error describes: dx = x_true - x_est
        q = quat_multiply(rotvec_to_quat(dx[0:3]), nav[0:4])
        nav_t = np.concatenate([q, nav[4:7] + dx[3:6], displace(nav[7:10], dx[6:9])])
        w_t = w - dx[9:12]  # a larger true gyro bias lowers the true compensated rate
        pr, rr, *_ = meas.predict(k, nav_t, w_t, clock + dx[15:17])
        fd = (np.concatenate([pr, rr]) - h0) / eps
        np.testing.assert_allclose(H[:, i], fd, rtol=2e-3, atol=2e-3 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("use_rr", [True, False])
def test_compiled_model_equals_the_numpy_one(truth, use_rr):
    o = simulate_observables(truth, SATS, 1.0, np.array([0.5, 0.2, -1.0]), np.radians(10), 3.0, 0.1,
                             0.003, (0.1, 0.01), (7.0, 0.5), np.random.default_rng(4))
    meas = TightGnss(o, [0.5, 0.2, -1.0], get_layout(17), use_range_rate=use_rr)
    kt = int(np.searchsorted(truth.time, o.time[300] - 1e-9))
    nav = np.concatenate([truth.q_nb[kt], truth.v_n[kt], truth.lla[kt] + [1e-6, -1e-6, 3.0]])
    w, clock = np.array([0.01, -0.02, 0.3]), np.array([3.0, 0.2])
    for a, b in zip(meas.measure(300, nav, w, clock), meas.measure_numpy(300, nav, w, clock)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-7)


def test_tight_method_needs_satellites_and_clock_states(tmp_path):
    text, _ = resolve("tight-demo")
    p = tmp_path / "a.toml"
    p.write_text(text.replace("states = 17", "states = 15"))
    with pytest.raises(ConfigError, match="receiver clock states"):
        load_scenario(str(p))
    start, end = text.index("[gnss.satellites]"), text.index("[init]")
    p.write_text(text[:start] + text[end:])
    with pytest.raises(ConfigError, match=r"\[gnss.satellites\]"):
        load_scenario(str(p))
    p.write_text(text.replace("keep = 3 }", "prns = [31] }"))
    with pytest.raises(ConfigError, match="PRN") as exc:
        load_scenario(str(p))
    assert exc.value.key == "gnss.satellites"
    p.write_text(text.replace('pseudorange_sigma = "3 m"', 'pseudorange_sigma = "-3 m"'))
    with pytest.raises(ConfigError) as exc:
        load_scenario(str(p))
    assert exc.value.key == "gnss.satellites.pseudorange_sigma"


@pytest.fixture(scope="module")
def tight20(tmp_path_factory):
    out = tmp_path_factory.mktemp("tight20")
    df = run_experiment("tight-demo", 20, out, workers=2, progress=False)
    return df, write_experiment_outputs("tight-demo", df, out, figures=False)


def test_tight_ekf_is_consistent_over_20_runs(tight20):
    # Gaussian noise, the filter's own models: run-averaged NEES and NIS must stay in
    # their 95 % chi-square bands. Epochs of one run are correlated (a run that starts
    # high stays high), so we ask 85 % of the epochs in band rather than 95 %, and the
    # time-averaged values within 15 % of their expectation (a wrong H, clock model or
    # sign moves them by factors, not by 15 %).
    _, tables = tight20
    c = tables["consistency"].set_index(["method", "quantity"])
    for q, expect in (("NEES pos", 3), ("NEES vel", 3), ("NIS per dof", 1)):
        assert c.loc[("tight", q), "in_band_fraction"] >= 0.85, q
        assert c.loc[("tight", q), "mean"] == pytest.approx(expect, rel=0.15), q


def test_tight_bounds_the_error_where_loose_has_no_fix(tight20):
    df, _ = tight20
    wide = df.pivot(index="seed", columns="method", values="outage0_horizontal_max_m")
    # 3 satellites for 60 s: the loose filter coasts on the MEMS IMU, the tight one
    # keeps using the ranges; it must win in (nearly) every run and by a wide margin
    assert (wide["tight"] < wide["loose"]).mean() >= 0.9
    assert wide["tight"].median() < 0.5 * wide["loose"].median()
