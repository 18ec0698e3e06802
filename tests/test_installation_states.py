"""Installation states of the loose GNSS model: the antenna lever-arm and IMU time-offset
corrections (``gnss_lever``, ``imu_time_offset``; :mod:`mixnav.measurements.loose`).

Jacobian columns against finite differences of h, the time-offset convention against
the truth, the differenced acceleration in closed form, recovery of a wrong configured
lever arm and time offset in simulation (each normalised error checked against the
filter's own sigma), the config path and its errors, and drive-0708, where the time-offset
state must find the offset the installation analysis found by a scan."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mixnav.attitude import euler_to_quat
from mixnav.data import GnssFixes
from mixnav.errors import ConfigError
from mixnav.ins.error_model import StateLayout
from mixnav.ins.mechanization import nav_vector
from mixnav.measurements.loose import (GNSS_LEVER, TIME_OFFSET, LooseGnss, fix_accelerations, gnss_lever_block,
                                       time_offset_block)

LAYOUT = StateLayout("installation", [gnss_lever_block(0.5), time_offset_block(0.1)])


def _fixes(m=5, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(m) * 0.2
    lla = np.column_stack([np.radians(39.9) + 1e-6 * rng.standard_normal(m),
                           np.radians(-105.1) + 1e-6 * rng.standard_normal(m), 1700 + rng.standard_normal(m)])
    v = np.array([12.0, -4.0, 0.3]) + np.outer(t, [1.5, 2.0, -0.1])     # 1.5, 2, -0.1 m/s^2
    return GnssFixes(t, lla, np.full((m, 3), 0.05), v, np.full((m, 3), 0.02))


def test_lever_and_offset_columns_are_the_derivatives_of_h():
    """Each installation column of H equals the finite difference of the innovation over its
    state (z = y - h, so dz = -H d) to 2e-6: h is nearly linear in the lever and linear in
    the offset; the step is 1 mm because latitude and longitude in radians carry ~1e-9 m of
    round-off. A flipped sign or a missing C fails."""
    fx = _fixes()
    model = LooseGnss(fx, np.array([0.4, -0.2, -1.1]), LAYOUT)
    nav = nav_vector(euler_to_quat(np.radians([3.0, -2.0, 130.0])), np.array([11.0, -3.5, 0.2]),
                     fx.lla[2] + np.array([2e-7, -1e-7, 0.5]))
    w_b = np.array([0.02, -0.01, 0.3])
    aux = {GNSS_LEVER: np.array([0.1, 0.05, -0.2]), TIME_OFFSET: np.array([0.04])}
    r = model.rows(2, nav, w_b, aux=aux)
    eps = 1e-3
    for name, sl in ((GNSS_LEVER, LAYOUT.slice(GNSS_LEVER)), (TIME_OFFSET, LAYOUT.slice(TIME_OFFSET))):
        for j in range(sl.stop - sl.start):
            a = {k: v.copy() for k, v in aux.items()}
            a[name][j] += eps
            dz = (r.z - model.rows(2, nav, w_b, aux=a).z) / eps
            np.testing.assert_allclose(dz, r.H[:, sl.start + j], rtol=0, atol=2e-6)
    # the velocity columns of the position rows carry -dt (h_pos = p - v dt)
    np.testing.assert_allclose(r.H[0:3, 3:6], -0.04 * np.eye(3), atol=1e-12)


def test_time_offset_convention_against_the_truth():
    """Fixes at true times, IMU labelled 0.08 s early (its true offset is 0.08 s more than
    configured): the INS state labelled t is the truth at t + 0.08. At the truth, with the
    estimate 0.08 the innovations vanish (median below 1 cm and 2 mm/s; what is left is
    second order, and at the fixes where a turn starts between two fixes the differenced
    acceleration's error, which the rows' variance carries: every velocity innovation is
    within 4 of its sigma); with 0 they are v dt (metres); with the wrong sign they double."""
    from mixnav.config.loader import load_scenario
    from mixnav.experiment.run import truth_at
    from mixnav.sim.scenario import truth_and_ideal_imu
    sc, src, _ = load_scenario("loose-demo")
    truth, _ = truth_and_ideal_imu(sc, src)
    t = np.arange(70.0, 590.0, 0.2)
    tr = truth_at(truth, t)
    fx = GnssFixes(t, tr.lla, np.full((len(t), 3), 0.02), tr.v_n, np.full((len(t), 3), 0.01))
    lay = StateLayout("t", [time_offset_block(0.1)])
    model = LooseGnss(fx, np.zeros(3), lay)
    tau = 0.08
    at_label = truth_at(truth, t + tau)     # the INS labelled t is the truth at t + tau
    z, r = {}, {}
    for dt in (tau, 0.0, -tau):
        rows = [model.rows(i, nav_vector(at_label.q_nb[i], at_label.v_n[i], at_label.lla[i]), np.zeros(3),
                           aux={TIME_OFFSET: np.array([dt])}) for i in range(len(t))]
        z[dt] = np.array([x.z for x in rows])
        r[dt] = np.array([x.R for x in rows])
    med = np.median(np.abs(z[tau]), axis=0)
    assert np.all(med[:3] < 0.01) and np.all(med[3:] < 0.002), med
    assert np.all(np.abs(z[tau][:, 3:]) < 4 * np.sqrt(r[tau][:, 3:])), np.abs(z[tau][:, 3:] / np.sqrt(r[tau][:, 3:])).max()
    rms = {k: np.sqrt((v[:, :2] ** 2).mean(0)) for k, v in z.items()}
    assert np.all(rms[0.0] > 0.5), rms[0.0]
    np.testing.assert_allclose(rms[-tau], 2 * rms[0.0], rtol=0.02)


def test_fix_accelerations_closed_form():
    """Velocities quadratic in time: the mean of the backward and forward differences is the
    exact derivative at interior fixes, and half their spread is |c| h (c the quadratic
    coefficient, h the spacing); across a gap nothing is differenced (one-sided at its edges,
    the acceleration then its own sigma), and an isolated fix gets 0 with a 10 m/s^2 sigma."""
    t = np.r_[np.arange(0.0, 2.01, 0.25), 5.0, np.arange(10.0, 11.01, 0.25)]
    a0, c = np.array([0.5, -1.0, 0.1]), np.array([0.2, 0.0, -0.3])
    v = np.array([1.0, 2.0, 0.0]) + np.outer(t, a0) + np.outer(t ** 2, c)
    acc, sig = fix_accelerations(t, v)
    exact = a0 + 2 * np.outer(t, c)
    interior = np.r_[1:8, 11:14]
    np.testing.assert_allclose(acc[interior], exact[interior], atol=1e-12)
    np.testing.assert_allclose(sig[interior], np.tile(np.abs(c) * 0.25, (len(interior), 1)), atol=1e-12)
    iso = 9                                  # t = 5: neighbours 3 s and 5 s away
    assert np.all(acc[iso] == 0) and np.all(sig[iso] == 10.0)
    for k, nb in ((8, 7), (10, 11)):         # edges of the gap: one-sided
        d = (v[max(k, nb)] - v[min(k, nb)]) / abs(t[k] - t[nb])
        np.testing.assert_allclose(acc[k], d)
        np.testing.assert_allclose(sig[k], np.abs(d))


def _loose_demo(seed):
    from mixnav.config.loader import load_scenario
    from mixnav.sim.scenario import simulate
    sc, src, _ = load_scenario("loose-demo")
    return sc, simulate(sc, seed, src)


@pytest.mark.parametrize("seed", [2, 4])
def test_simulation_recovers_a_wrong_lever_arm(seed):
    """loose-demo (1.5 m / 0.05 m/s fixes at 1 Hz, lever (0.5, 0.2, -1.0) m) filtered with the
    lever configured 0.6 / -0.4 / +0.5 m wrong: the lever states find the missing correction
    within 3 of their own sigmas (measured over seeds 1-8: all within 1.8), and the
    horizontal ones within 0.15 m (sigma about 0.06 m); the vertical one is weakly observed
    (sigma 0.8 m: only the small pitch and roll changes move it)."""
    from mixnav.filters.ekf import ErrorStateEkf
    sc, sim = _loose_demo(seed)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    dl = np.array([0.6, -0.4, 0.5])
    lay = StateLayout("lever", [gnss_lever_block(1.0)])
    res = ErrorStateEkf(lay, sim.imu_model, covariance_interval=0.1).run(
        sim.imu, sim.init, [LooseGnss(sim.fixes, lever - dl, lay)])
    err = res.estimates[GNSS_LEVER][-1] - dl
    sig = res.sigma[-1][lay.slice(GNSS_LEVER)]
    assert np.all(np.abs(err) < 3 * sig), (err, sig)
    assert np.all(np.abs(err[:2]) < 0.15), err


@pytest.mark.parametrize("seed", [5, 8])
def test_simulation_recovers_a_wrong_time_offset(seed):
    """loose-demo with the IMU labelled 0.08 s early (a wrong configured imu_time_offset):
    the time-offset state finds 0.08 s within 3 of its sigma (about 4 ms; measured over
    seeds 1-8: all within 0.8 sigma) and within 0.01 s. With the state the GNSS NIS per dof
    is 1 within 0.1 (about 3,000 degrees of freedom: the mean's 1-sigma is 0.026), while the
    filter without it sees the offset as excess innovation (measured 1.16 and 1.14 against
    1.00 and 0.97)."""
    from mixnav.filters.ekf import ErrorStateEkf
    sc, sim = _loose_demo(seed)
    tau = 0.08
    imu = replace(sim.imu, time=sim.imu.time - tau)
    init = replace(sim.init, time=sim.init.time - tau)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    out = {}
    for name, lay in (("plain", StateLayout("p")), ("est", StateLayout("o", [time_offset_block(0.2)]))):
        res = ErrorStateEkf(lay, sim.imu_model, covariance_interval=0.1).run(
            imu, init, [LooseGnss(sim.fixes, lever, lay)])
        out[name] = float(np.mean(res.nis / res.nis_dim))
    err = float(res.estimates[TIME_OFFSET][-1, 0] - tau)
    sig = float(res.sigma[-1][lay.slice(TIME_OFFSET)][0])
    assert abs(err) < 3 * sig and abs(err) < 0.01, (err, sig)
    assert abs(out["est"] - 1.0) < 0.1 and out["plain"] > out["est"] + 0.1, out


@pytest.mark.parametrize("seed", [3, 5])
def test_a_wandering_offset_is_followed_by_the_walking_state(seed):
    """loose-demo with an IMU clock whose offset wanders as a random walk (2 ms/sqrt(s),
    drawn at 1 s steps from 0.05 s): the state with that walk (``time_offset_walk``) is
    consistent, the mean of its squared normalised error after the first minute is 1 within
    its spread (measured over seeds 1-8: 0.62-2.01, the errors correlated over about 100 s,
    so 540 s holds only a few independent values), while the constant state (no walk) settles
    on a mean and is over-confident: its mean squared normalised error is at least three times
    the walking state's on every seed (measured 3.8-29)."""
    from mixnav.filters.ekf import ErrorStateEkf
    sc, sim = _loose_demo(seed)
    walk = 2e-3
    rng = np.random.default_rng(100 + seed)
    tk = np.arange(0.0, 601.0)
    wander = 0.05 + np.r_[0.0, np.cumsum(rng.normal(0.0, walk, len(tk) - 1))]
    tau = lambda t: np.interp(t, tk, wander)                     # noqa: E731
    imu = replace(sim.imu, time=sim.imu.time - tau(sim.imu.time))
    init = replace(sim.init, time=float(imu.time[0]))
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    z2 = {}
    for name, w in (("constant", 0.0), ("walking", walk)):
        lay = StateLayout("o", [time_offset_block(0.2, w)])
        res = ErrorStateEkf(lay, sim.imu_model, covariance_interval=0.1).run(
            imu, init, [LooseGnss(sim.fixes, lever, lay)])
        t = res.time
        err = res.estimates[TIME_OFFSET][:, 0] - tau(t + tau(t))   # label t is true time t + offset
        sig = res.sigma[:, lay.slice(TIME_OFFSET)][:, 0]
        z2[name] = float(np.mean((err[t > 60] / sig[t > 60]) ** 2))
    assert 0.4 < z2["walking"] < 2.5, z2
    assert z2["constant"] > 3 * z2["walking"], z2


def _dataset_with(tmp_path, text, name):
    from mixnav.config import load_dataset
    p = tmp_path / f"{name}.toml"
    p.write_text(text)
    return load_dataset(str(p))


def test_config_errors_name_the_key(tmp_path):
    """The installation states belong to the loose model: asking a tightly coupled method
    for them, or listing one twice, is a ConfigError naming methods[i].estimate."""
    from mixnav.experiment.aiding import method_layout
    from mixnav.config.method_schema import MethodConfig
    m = MethodConfig(name="t", type="tight-ekf", estimate=["imu_time_offset"])
    with pytest.raises(ConfigError, match=r"loose") as e:
        method_layout(m, None, "x.toml", 2)
    assert "methods[2].estimate" in str(e.value)
    m = MethodConfig(name="l", type="loose-ekf", estimate=["gnss_lever", "gnss_lever"])
    with pytest.raises(ConfigError, match="twice") as e:
        method_layout(m, None, "x.toml", 0)
    assert "methods[0].estimate" in str(e.value)
    lay = method_layout(MethodConfig(name="l", type="loose-ekf", estimate=["gnss_lever", "imu_time_offset"]), None)
    assert lay.n == 19 and lay.block(GNSS_LEVER).sigma0 == 0.5 and lay.block(TIME_OFFSET).sigma0 == 0.1
    assert lay.block(TIME_OFFSET).walk == 0.0
    # the walk from [aiding] time_offset_walk, its unit converted (ms/sqrt(s) -> s/sqrt(s))
    from mixnav.config.aiding_schema import AidingConfig
    from mixnav.experiment.aiding import AidingInputs
    cfg = AidingConfig(time_offset_walk="1.5 ms/sqrt(s)")
    inputs = AidingInputs(cfg, None, None, 0.0, 1.0)
    lay = method_layout(MethodConfig(name="l", type="loose-ekf", estimate=["imu_time_offset"]), inputs)
    assert lay.block(TIME_OFFSET).walk == pytest.approx(1.5e-3)
    with pytest.raises(ValueError, match="time random walk"):
        AidingConfig(time_offset_walk="1 ms")


def test_drive0708_installation_states_find_a_wrong_offset_and_lever(tmp_path):
    """drive-0708 configured with the data README's IMU offset (-0.125 s) and the antenna
    1.05 m off to the right (y = +1.0 m instead of -0.05 m), both estimated: the process
    summary suggests an offset of -0.20 s, the value the installation analysis found by
    scanning NIS (benchmarks/results/drive0708_installation.md; measured -0.204 s; the
    latency drifts by about 0.1 s over the record, so 0.03 s is the tolerance), and an
    antenna y within 0.15 m of the configured -0.05 m (measured +0.05 m; started from the
    configured value the state moves it to +0.015 m, so the recorder's -0.05 m is itself
    uncertain at that level). The windows' 95th-percentile error is less than half the
    plain filter's with the same wrong installation (measured 9.4 against 28.8 m)."""
    from pathlib import Path
    from mixnav.api import process_dataset
    from .conftest import data_file
    folder = data_file("drive-0708")
    text = Path(__file__).parents[1].joinpath("src/mixnav/config/datasets/drive-0708-plain.toml").read_text()
    for a, b in (('imu_time_offset = "-0.2 s"', 'imu_time_offset = "-0.125 s"'),
                 ('antenna_position = ["0 m", "-0.05 m", "-0.65 m"]', 'antenna_position = ["0 m", "1.0 m", "-0.65 m"]')):
        assert a in text
        text = text.replace(a, b)
    text += ('\n[[methods]]\nname = "est"\ntype = "loose-ekf"\nstates = 15\ncovariance_interval = "0.25 s"\n'
             'estimate = ["gnss_lever", "imu_time_offset"]\n')
    p = tmp_path / "wrong-installation.toml"
    p.write_text(text)
    r = process_dataset(str(p), str(folder))
    est = r.installation["estimated"]["est"]
    assert abs(est["suggested_imu_time_offset_s"] - (-0.2)) < 0.03, est
    assert abs(est["suggested_antenna_position_m"][1] - (-0.05)) < 0.15, est
    p95 = r.metrics["horizontal_p95_m"]
    assert p95["est"] < 0.5 * p95["ekf"], p95
