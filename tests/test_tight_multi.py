"""Several satellite systems in the tight INS: the simulator's nominal Galileo, BeiDou and
GLONASS constellations with receiver inter-system offsets, and TightGnss with one receiver
clock plus an offset state per further system (measurements/tight.py)."""

import numpy as np
import pytest

from mixnav.attitude import quat_multiply, rotvec_to_quat
from mixnav.config.loader import load_scenario, resolve
from mixnav.errors import ArgumentError
from mixnav.experiment.run import run_scenario
from mixnav.geodesy.frames import displace, lla_to_ecef, ned_displacement
from mixnav.gnss.constellation import GLONASS_CHANNELS, MultiConstellation, NominalConstellation
from mixnav.gnss.geometry import C_LIGHT, GM_GPS
from mixnav.gnss.observables import simulate_observables
from mixnav.gnss.orbits import BEIDOU, GALILEO, GLONASS
from mixnav.ins.error_model import get_layout
from mixnav.measurements.tight import TightGnss, observation_systems, tight_layout
from mixnav.sim.scenario import truth_and_ideal_imu

LEVER = np.array([0.5, 0.2, -1.0])
#: true inter-system offsets [m] by system code: Galileo, BeiDou, GLONASS (GPS the reference)
OFFSETS = {8: 12.0, 32: -20.0, 4: 35.0}
SATS = MultiConstellation.of(("G", "E", "C", "R"))


@pytest.fixture(scope="module")
def truth():
    sc, _, _ = load_scenario("tight-demo")
    return truth_and_ideal_imu(sc)[0]


def _noiseless(truth, **kw):
    return simulate_observables(truth, SATS, 1.0, LEVER, np.radians(10), 1e-12, 1e-12, 1e-12, (0.0, 0.0),
                                (7.0, 0.5), np.random.default_rng(0), system_offsets=OFFSETS, **kw)


def _nav(truth, o, k):
    kt = int(np.searchsorted(truth.time, o.time[k] - 1e-9))
    return kt, np.concatenate([truth.q_nb[kt], truth.v_n[kt], truth.lla[kt]])


def test_nominal_orbits_have_each_systems_period_and_radius():
    """Circular orbits: radius = the semi-major axis, speed in the inertial frame = sqrt(GM / a),
    period 2 pi sqrt(a^3 / GM) (Kepler's third law: Galileo 14 h 05 min, BeiDou MEO 12 h 53 min,
    GLONASS 11 h 15 min 44 s, the systems' published periods to a minute)."""
    for c, gm, period_min in ((NominalConstellation.galileo(), GALILEO.gm, 14 * 60 + 5),
                              (NominalConstellation.beidou(), BEIDOU.gm, 12 * 60 + 53),
                              (NominalConstellation.glonass(), GLONASS.gm, 11 * 60 + 15 + 44 / 60)):
        s = c.states(1234.0)
        r = np.linalg.norm(s.pos_ecef, axis=1)
        np.testing.assert_allclose(r, c.semi_major_axis, rtol=1e-12)
        v_inertial = s.vel_ecef + np.cross([0.0, 0.0, c.omega_e], s.pos_ecef)
        np.testing.assert_allclose(np.linalg.norm(v_inertial, axis=1), np.sqrt(gm / c.semi_major_axis), rtol=1e-12)
        assert 2 * np.pi / c.mean_motion / 60 == pytest.approx(period_min, abs=1.0)
        # velocity is the time derivative of position (central difference, 0.1 s)
        a, b = c.states(1233.95), c.states(1234.05)
        np.testing.assert_allclose((b.pos_ecef - a.pos_ecef) / 0.1, s.vel_ecef, atol=1e-4)
    # the GPS constellation is unchanged by the system constants (GPS's are its defaults)
    g = NominalConstellation.gps(5)
    assert g.gm == GM_GPS and g.mean_motion == np.sqrt(GM_GPS / g.semi_major_axis ** 3)


def test_multi_constellation_ids_and_glonass_channels():
    ids = SATS.ids
    system, number = MultiConstellation.split_ids(ids)
    assert len(set(ids.tolist())) == len(ids) == 30 + 3 * 24
    assert (number[system == 1] == np.arange(1, 31)).all()            # GPS ids are the PRNs
    for code in (4, 8):
        assert (number[system == code] == np.arange(1, 25)).all()
    # BeiDou: MEO numbers only (a GEO number would get the GEO rotation in the broadcast orbits)
    from mixnav.gnss.multi_ephemeris import BEIDOU_GEO_PRNS
    assert len(number[system == 32]) == 24 and not np.isin(number[system == 32], BEIDOU_GEO_PRNS).any()
    ch = SATS.glonass_channels
    assert set(ch) == set(range(1, 25)) and set(ch.values()) <= set(range(-7, 7))
    # antipodal slots of a plane (4 apart) share a channel, as the ICD's plan has it
    assert all(GLONASS_CHANNELS[p] == GLONASS_CHANNELS[p + 4] for p in (1, 2, 3, 4, 9, 10, 11, 12, 17, 18, 19, 20))


def test_observables_carry_each_systems_offset_and_wavelength(truth):
    o = _noiseless(truth)
    assert set(np.unique(o.system[o.valid]).tolist()) == {1, 4, 8, 32}
    k = 100
    kt, nav = _nav(truth, o, k)
    from mixnav.attitude import quat_to_dcm
    from mixnav.geodesy.frames import dcm_ecef_to_ned
    r = lla_to_ecef(truth.lla[kt]) + dcm_ecef_to_ned(*truth.lla[kt, :2]).T @ quat_to_dcm(truth.q_nb[kt]) @ LEVER
    v = o.valid[k]
    geo = np.linalg.norm(o.sat_pos[k, v] - r, axis=1)
    off = np.array([OFFSETS.get(int(c), 0.0) for c in o.system[k, v]])
    np.testing.assert_allclose(o.pseudorange[k, v], geo + o.clock[k, 0] + off, atol=1e-6)
    # carrier minus pseudorange: a whole number of the system's wavelength (GLONASS by channel)
    f = {1: 1575.42e6, 8: 1575.42e6, 32: 1561.098e6}
    for j in np.nonzero(v)[0]:
        c, p = int(o.system[k, j]), int(o.prn[k, j])
        lam = C_LIGHT / (f[c] if c != 4 else 1602e6 + 0.5625e6 * GLONASS_CHANNELS[p])
        n_cyc = (o.carrier[k, j] - o.pseudorange[k, j]) / lam
        assert n_cyc == pytest.approx(round(n_cyc), abs=1e-3)


def test_model_needs_the_offset_block(truth):
    o = _noiseless(truth)
    with pytest.raises(ArgumentError, match="system_offset"):
        TightGnss(o, LEVER, get_layout(17))
    assert observation_systems(o) == (1, 4, 8, 32)           # GPS the reference, then G R E C order
    lay = tight_layout(get_layout(17), observation_systems(o))
    assert lay.n == 20 and lay.block("system_offset").size == 3
    # a model of GPS and Galileo only leaves the other slots out, counted
    lay2 = tight_layout(get_layout(17), (1, 8))
    m = TightGnss(o, LEVER, lay2, systems=(1, 8))
    assert m.skipped_slots == int(np.isin(o.system[o.valid], (4, 32)).sum()) > 0


def test_innovations_vanish_at_the_truth(truth):
    """Noiseless observables at the true state, clock and offsets (relative to GPS): every
    pseudorange innovation is zero to rounding, whatever the system; with the offsets left
    at zero each system's rows are off by exactly its offset."""
    o = _noiseless(truth)
    lay = tight_layout(get_layout(17), observation_systems(o))
    meas = TightGnss(o, LEVER, lay)
    aux = {"system_offset": np.array([OFFSETS[4], OFFSETS[8], OFFSETS[32]])}
    for k in (10, 250, 500):
        _, nav = _nav(truth, o, k)
        w = np.zeros(3)
        rows = meas.rows(k, nav, w, o.clock[k], aux=aux)
        n = int(o.valid[k].sum())
        assert np.abs(rows.z[:n]).max() < 1e-5
        z0 = meas.rows(k, nav, w, o.clock[k]).z[:n]
        off = np.array([OFFSETS.get(int(c), 0.0) for c in o.system[k, o.valid[k]]])
        np.testing.assert_allclose(z0, off, atol=1e-5)


def test_offset_columns_match_finite_differences(truth):
    o = simulate_observables(truth, SATS, 1.0, LEVER, np.radians(10), 3.0, 0.1, 0.003, (0.1, 0.01), (7.0, 0.5),
                             np.random.default_rng(4), system_offsets=OFFSETS)
    lay = tight_layout(get_layout(17), observation_systems(o))
    meas = TightGnss(o, LEVER, lay)
    k = 200
    _, nav = _nav(truth, o, k)
    nav[7:10] += [1e-6, -1e-6, 3.0]
    w, clock = np.array([0.01, -0.02, 0.3]), np.array([3.0, 0.2])
    aux = {"system_offset": np.array([30.0, 10.0, -15.0])}
    rows = meas.rows(k, nav, w, clock, aux=aux)
    z, H, r = rows.z, rows.H, rows.R
    # the compiled rows equal the numpy model
    for a, b in zip((z, H, r), meas.measure_numpy(k, nav, w, clock, aux)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-7)
    pr0, rr0, *_ = meas.predict(k, nav, w, clock, aux)
    h0 = np.concatenate([pr0, rr0])
    i_off = lay.slice("system_offset").start
    for g in range(3):
        eps = 1e-2
        a = {"system_offset": aux["system_offset"] + eps * np.eye(3)[g]}
        pr, rr, *_ = meas.predict(k, nav, w, clock, a)
        fd = (np.concatenate([pr, rr]) - h0) / eps
        np.testing.assert_allclose(H[:, i_off + g], fd, atol=1e-6)
        assert H[:, i_off + g].sum() == (o.system[k, o.valid[k]] == (4, 8, 32)[g]).sum()   # its satellites' rows
    # the other columns as the single-system model's: position and clock by finite differences
    for i, eps in ((6, 1e-3), (7, 1e-3), (8, 1e-3), (15, 1e-3), (16, 1e-3), (0, 1e-4)):
        dx = np.zeros(lay.n)
        dx[i] = eps
        q = quat_multiply(rotvec_to_quat(dx[0:3]), nav[0:4])
        nav_t = np.concatenate([q, nav[4:7] + dx[3:6], displace(nav[7:10], dx[6:9])])
        pr, rr, *_ = meas.predict(k, nav_t, w, clock + dx[15:17], aux)
        fd = (np.concatenate([pr, rr]) - h0) / eps
        np.testing.assert_allclose(H[:, i], fd, rtol=2e-3, atol=2e-3 * max(1.0, np.abs(fd).max()))
    # the ensemble prediction: at the nominal y - Y[0] is z; a member's own offsets move its rows
    y, Y, _ = meas.predict_batch(k, np.stack([nav, nav]), w, np.stack([clock, clock]),
                                 aux={"system_offset": np.stack([aux["system_offset"], aux["system_offset"] + 1.0])})
    np.testing.assert_allclose(y - Y[0], z, atol=1e-7)
    n = int(o.valid[k].sum())
    np.testing.assert_allclose(Y[1, :n] - Y[0, :n], (o.system[k, o.valid[k]] != 1).astype(float), atol=1e-7)
    # channel ids tell systems apart (GPS 5 and Galileo 5 are two channels)
    ch = meas.row_channels(k, len(z))
    assert len(set(ch.tolist())) == len(ch)


MULTI = """
systems = ["G", "E", "C", "R"]
system_offsets = ["12 m", "-20 m", "35 m"]
"""


def multi_scenario(folder, systems_text=MULTI, name="tight-multi"):
    """tight-demo with Galileo, BeiDou and GLONASS beside GPS, each with a receiver offset."""
    text, _ = resolve("tight-demo")
    text = text.replace('constellation = "gps30"\n', 'constellation = "gps30"' + systems_text)
    text = text.replace('name = "tight-demo"', f'name = "{name}"')
    p = folder / f"{name}.toml"
    p.write_text(text)
    return p


#: estimators run by tight-ekf on the four-system simulation (the particle filters are not:
#: on tight-demo's GPS alone the PF with its defaults is already off by tens of metres)
ESTIMATORS = ("ukf", "robust-adaptive", "vb-akf", "student-t")


#: a Gaussian-mixture bank and an IMM of two modes, tight on the four systems too
BANK_AND_IMM = """
[[methods]]
name = "tight-gaussian-mixture"
type = "tight-ekf"
states = 17
estimator = "gaussian-mixture"
[methods.mixture]
max_components = 4
measurement.pseudorange = { weights = [0.9, 0.1], scales = [1.0, 9.0] }

[[methods]]
name = "tight-imm"
type = "tight-ekf"
states = 17
estimator = "imm"
[methods.imm]
transition = [[0.95, 0.05], [0.05, 0.95]]
[[methods.imm.modes]]
name = "plain"
estimator = "ekf"
measurements = ["gnss"]
[[methods.imm.modes]]
name = "robust"
estimator = "robust-adaptive"
measurements = ["gnss"]
"""


@pytest.fixture(scope="module")
def multi_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("multi")
    p = multi_scenario(root)
    p.write_text(p.read_text() + "".join(f'\n[[methods]]\nname = "tight-{e}"\ntype = "tight-ekf"\nstates = 17\n'
                                         f'estimator = "{e}"\ncovariance_interval = "1 s"\n' for e in ESTIMATORS)
                 + BANK_AND_IMM)
    sc, source, _ = load_scenario(str(p))
    return run_scenario(sc, source, seed=1)


@pytest.mark.parametrize("name", ["tight"] + [f"tight-{e}" for e in ESTIMATORS + ("gaussian-mixture", "imm")])
def test_simulated_multi_system_run_estimates_the_offsets(multi_run, name):
    """The tight filters on four systems (GPS clock + three offset states, starting at zero
    with 100 m sigma) find each offset relative to GPS: the final estimates within 3 sigma of
    the truth (a one-in-370 miss per offset for a consistent filter) and their sigma below
    0.5 m (some 8 satellites per system, 3 m pseudoranges, 600 epochs)."""
    res = multi_run.results[name]
    est = res.estimates["system_offset"][-1]
    i = res.layout.slice("system_offset")
    sig = res.sigma[-1, i]
    truth = np.array([OFFSETS[4], OFFSETS[8], OFFSETS[32]])     # the layout's order: GLONASS, Galileo, BeiDou
    assert (np.abs(est - truth) < 3 * sig).all(), (est, sig)
    assert (sig < 0.5).all()
    assert res.recoveries.get("rejected_not_pd", 0) == 0


def test_more_systems_keep_the_tight_filter_through_the_three_satellite_window(multi_run):
    """From 300 to 360 s only the 3 highest satellites of all systems stay (tight-demo's
    outage): the multi-system run must be at least as good as the scenario's own loose filter
    there, and the run-wide horizontal error of the tight filter stays at metres (pseudoranges
    of 3 m, no wrong offset left in the rows: a 12-35 m offset taken as zero pulls the fix
    by metres)."""
    run = multi_run
    truth = run.sim.truth
    h = {}
    for name in ("loose", "tight"):
        res = run.results[name]
        k = np.searchsorted(truth.time, res.time - 1e-9)
        assert np.abs(truth.time[k] - res.time).max() < 1e-6
        d = ned_displacement(res.nav[:, 7:10], truth.lla[k])
        h[name] = np.hypot(d[:, 0], d[:, 1])
    t = run.results["tight"].time
    assert np.sqrt(np.mean(h["tight"] ** 2)) < 2.5
    win = (t >= 300) & (t < 360)
    assert h["tight"][win].max() <= h["loose"][win].max()


# --- the export round trip: RINEX 3 of several systems, read back by ``mixnav process`` --------

GEC = """
systems = ["G", "E", "C", "R"]
system_offsets = ["12 m", "-20 m", "35 m"]
"""
#: the offsets in the filter's order (GLONASS, Galileo, BeiDou: G R E C J)
GEC_TRUTH = [35.0, 12.0, -20.0]


@pytest.fixture(scope="module")
def exported_multi(tmp_path_factory):
    from tests.test_rinex_ins import export_and_process, short_scenario
    root = tmp_path_factory.mktemp("multi_export")
    p = short_scenario(root)
    p.write_text(p.read_text().replace('constellation = "gps30"\n', 'constellation = "gps30"' + GEC))
    return export_and_process(p, root)


def test_multi_system_export_writes_mixed_rinex(exported_multi):
    from mixnav.gnss.multi_ephemeris import MultiEphemeris
    from mixnav.io.rinex_obs import read_rinex_obs
    _, _, ex, po = exported_multi
    head = ex.files["observations"].read_text().splitlines()
    assert "M: Mixed" in head[0]
    types = {ln[0]: ln[6:58].split() for ln in head if ln[60:].strip() == "SYS / # / OBS TYPES"}
    assert types == {"G": ["C1C", "L1C", "D1C"], "R": ["C1C", "L1C", "D1C"], "E": ["C1C", "L1C", "D1C"],
                     "C": ["C2I", "L2I", "D2I"]}
    eph = MultiEphemeris.from_rinex([ex.files["navigation"]])
    assert {s for s in "GREC" if s in eph} == set("GREC")
    assert eph["R"].channels() == {p: GLONASS_CHANNELS[p] for p in range(1, 25)}
    assert po.dataset.raw_gnss.systems == ["G", "E", "C", "R"]
    c = po.checks["rinex"]
    assert c["systems"] == ["G", "R", "E", "C"] and c["observations_not_filtered"].get("no ephemeris", 0) == 0
    assert not c["satellites_skipped_by_system"]
    # the file read back: every simulated observation of every system, at every epoch, and
    # the header's GLONASS channels
    obs = read_rinex_obs(ex.files["observations"], systems=("G", "E", "C", "R"))
    assert obs.glonass_channels == {p: GLONASS_CHANNELS[p] for p in set(obs.prn[obs.systems() == "R"].tolist())}
    sim = ex.sim.observations
    assert len(obs.prn) == int(sim.valid.sum())


def test_multi_system_pseudoranges_read_back_to_the_millimetre(exported_multi):
    """Per satellite and epoch, the tight observables rebuilt from the mixed RINEX files equal
    the simulated ones: pseudoranges to the file's 1 mm rounding (0.5 mm), range rates to
    1 mHz of Doppler (0.2 mm/s), satellite positions to < 1 cm, velocities to 1 mm/s (the
    broadcast orbits of every system reproduce the nominal ones), the same satellites."""
    _, _, ex, po = exported_multi
    a, b = ex.sim.observations, po.observations
    np.testing.assert_array_equal(a.time, b.time)
    worst = np.zeros(4)
    for k in range(len(a)):
        ka = list(zip(a.system[k][a.valid[k]].tolist(), a.prn[k][a.valid[k]].tolist()))
        kb = list(zip(b.system[k][b.valid[k]].tolist(), b.prn[k][b.valid[k]].tolist()))
        assert sorted(ka) == sorted(kb)
        for j, key in enumerate(ka):
            i = kb.index(key)
            worst = np.maximum(worst, [abs(a.pseudorange[k, j] - b.pseudorange[k, i]),
                                       abs(a.range_rate[k, j] - b.range_rate[k, i]),
                                       np.linalg.norm(a.sat_pos[k, j] - b.sat_pos[k, i]),
                                       np.linalg.norm(a.sat_vel[k, j] - b.sat_vel[k, i])])
    assert worst[0] <= 0.5e-3 + 1e-7 and worst[1] <= 2e-4 and worst[2] < 0.01 and worst[3] < 1e-3, worst


def test_tight_ekf_on_multi_system_rinex_equals_the_in_simulation_one(exported_multi):
    """Same start (the simulation's initial estimate), same IMU: the tight EKF with its GPS
    clock and three offset states on the RINEX observables follows the in-simulation one to
    < 1 cm at every epoch, and so do the offset estimates."""
    from tests.test_rinex_ins import simulated_and_read_back_runs
    res, meas_used = simulated_and_read_back_runs(exported_multi, lambda x: x.type == "tight-ekf")
    for meas in meas_used:
        assert meas[0].layout.block("system_offset").size == 3
    d = ned_displacement(res[1].nav[:, 7:10], res[0].nav[:, 7:10])
    assert np.abs(d).max() < 0.01
    np.testing.assert_allclose(res[1].estimates["system_offset"], res[0].estimates["system_offset"], atol=0.01)
    # and the offsets found are the simulated ones within 3 sigma
    i = res[1].layout.slice("system_offset")
    assert (np.abs(res[1].estimates["system_offset"][-1] - GEC_TRUTH) < 3 * res[1].sigma[-1, i]).all()


def test_processed_multi_system_dataset_runs_the_tight_filter_with_offsets(exported_multi):
    """``mixnav process`` of the export: the tight method's layout has the three offsets, it
    starts from the SPP's offsets (metres from the truth: one epoch's SPP), and ends near the
    truth."""
    _, _, _, po = exported_multi
    r = po.results["tight"]
    assert r.layout.block("system_offset").size == 3
    off0 = po.checks["rinex"]["system_offsets0_m"]
    assert set(off0) == {"R", "E", "C"}
    np.testing.assert_allclose([off0["R"], off0["E"], off0["C"]], GEC_TRUTH, atol=10)
    i = r.layout.slice("system_offset")
    assert (np.abs(r.estimates["system_offset"][-1] - GEC_TRUTH) < 3 * r.sigma[-1, i]).all()


def test_coloured_bank_refuses_several_systems(truth):
    from mixnav.measurements.differenced import DifferencedMeasurement
    o = _noiseless(truth)
    lay = tight_layout(get_layout(17), observation_systems(o))
    with pytest.raises(ArgumentError, match="one satellite system"):
        DifferencedMeasurement(TightGnss(o, LEVER, lay), lay, {"pseudorange": 0.5})


def test_scenario_system_offsets_are_checked(tmp_path):
    from mixnav.errors import ConfigError
    p = multi_scenario(tmp_path, '\nsystems = ["G", "E"]\nsystem_offsets = ["1 m", "2 m"]\n', name="bad1")
    with pytest.raises(ConfigError, match="one per system after the first"):
        load_scenario(str(p))
    p = multi_scenario(tmp_path, '\nsystems = ["G", "G"]\n', name="bad2")
    with pytest.raises(ConfigError, match="distinct"):
        load_scenario(str(p))
    p = multi_scenario(tmp_path, '\nsystems = ["G", "J"]\n', name="bad3")
    with pytest.raises(ConfigError):
        load_scenario(str(p))


def test_writers_refuse_what_a_mixed_file_cannot_hold(tmp_path):
    from mixnav.io.rinex_write import write_rinex_nav_multi, write_rinex_obs
    one = dict(week=[2305], tow=[100.0], epoch=[0, 0], pseudorange=[2.1e7, 2.2e7])
    with pytest.raises(ArgumentError, match="Galileo PRNs are 1..36") as exc:
        write_rinex_obs(tmp_path / "o.rnx", prn=[5, 40], system=["G", "E"], **one)
    assert exc.value.argument == "prn"
    with pytest.raises(ArgumentError, match="no frequency channel") as exc:
        write_rinex_obs(tmp_path / "o.rnx", prn=[5, 3], system=["G", "R"], glonass_channels={1: 1}, **one)
    with pytest.raises(ArgumentError, match="unknown system"):
        write_rinex_obs(tmp_path / "o.rnx", prn=[5, 3], system=["G", "S"], **one)
    rec = NominalConstellation.galileo().broadcast_records(1.3e9, [1.3e9 + 7200.0], time_system="E")
    with pytest.raises(ArgumentError, match="leap_seconds"):
        write_rinex_nav_multi(tmp_path / "n.rnx", {"E": rec}, glonass={"prn": [1]})
    with pytest.raises(ArgumentError, match="state vectors"):
        write_rinex_nav_multi(tmp_path / "n.rnx", {"R": rec})
    assert not list(tmp_path.iterdir())           # nothing half-written


def test_beidou_and_galileo_records_reproduce_the_nominal_orbits(tmp_path):
    """Written and read back (mixnav's navigation reader, each system's constants and time
    scale), the records give the nominal constellation's positions to 0.1 mm and velocities to
    0.1 mm/s at times between records (BeiDou in BDT, 14 s and 1356 weeks from GPST)."""
    from mixnav.gnss.multi_ephemeris import MultiEphemeris
    from mixnav.io.rinex_write import write_rinex_nav_multi
    t0 = 1.3e9                                        # GPS seconds of the constellations' t = 0
    toe = np.arange(0, 4) * 7200.0 + t0
    cons = {"E": NominalConstellation.galileo(), "C": NominalConstellation.beidou()}
    write_rinex_nav_multi(tmp_path / "n.rnx", {x: c.broadcast_records(t0, toe, time_system=x) for x, c in cons.items()})
    eph = MultiEphemeris.from_rinex([tmp_path / "n.rnx"])
    for x, c in cons.items():
        for t in (t0 + 1000.0, t0 + 9000.3, t0 + 20000.0):
            week, tow = divmod(t, 604800.0)
            got = eph.states(x, c.prn, int(week), tow)
            want = c.states(t - t0)
            np.testing.assert_allclose(got.pos_ecef, want.pos_ecef, atol=1e-4)
            np.testing.assert_allclose(got.vel_ecef, want.vel_ecef, atol=1e-4)
            assert np.abs(got.clock_bias).max() < 1e-15
