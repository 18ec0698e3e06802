"""TDCP with several satellite systems (measurements/tdcp.py): one receiver clock and an
inter-system offset per further system, in the rows and in the stochastic clone; the
simulated four-system drive and its mixed-RINEX export round trip."""

import numpy as np
import pytest

from mixnav.config.loader import load_scenario, resolve
from mixnav.experiment.run import run_scenario, solution_table
from mixnav.geodesy.frames import ned_displacement
from mixnav.gnss.constellation import MultiConstellation
from mixnav.gnss.observables import simulate_observables
from mixnav.ins.error_model import get_layout
from mixnav.measurements.tdcp import TdcpGnss
from mixnav.measurements.tight import observation_systems, tight_layout
from mixnav.sim.scenario import truth_and_ideal_imu

LEVER = np.array([0.5, 0.2, -1.0])
#: true inter-system offsets [m] by system code (GPS the reference): Galileo, BeiDou, GLONASS
OFFSETS = {8: 12.0, 32: -20.0, 4: 35.0}
#: the same in the layout's order (GLONASS, Galileo, BeiDou: G R E C J)
OFFSETS_LAYOUT = np.array([OFFSETS[4], OFFSETS[8], OFFSETS[32]])
SATS = MultiConstellation.of(("G", "E", "C", "R"))
#: the scenario text's systems (tight_multi's, on tdcp-demo)
MULTI = """
systems = ["G", "E", "C", "R"]
system_offsets = ["12 m", "-20 m", "35 m"]
"""


@pytest.fixture(scope="module")
def truth():
    sc, src, _ = load_scenario("tdcp-demo")
    return truth_and_ideal_imu(sc, src)[0]


def _observations(truth, seed=3, noise=(1.0, 0.1, 0.003)):
    return simulate_observables(truth, SATS, 1.0, LEVER, np.radians(10), *noise, (0.1, 0.01), (5.0, 0.3),
                                np.random.default_rng(seed), system_offsets=OFFSETS)


def _nav(truth, o, k):
    kt = int(np.searchsorted(truth.time, o.time[k] - 1e-9))
    return np.concatenate([truth.q_nb[kt], truth.v_n[kt], truth.lla[kt]])


def _model(o, clone=True):
    return TdcpGnss(o, LEVER, tight_layout(get_layout(17), observation_systems(o)), clone=clone)


def test_pairs_are_per_system_and_satellite(truth):
    """A TDCP row per satellite tracked at both epochs, a satellite being (system, number):
    GPS 5 and Galileo 5 are two. Against a count of the pairs by Python sets."""
    o = _observations(truth)
    meas = _model(o)
    assert meas.clone_size == 4 + 3 and meas.remembers_aux
    shared = 0
    for k in range(1, len(o.time), 11):
        cur, prev = meas._common_slots(k - 1, k)
        a = {(int(s), int(p)) for s, p, v in zip(o.system[k], o.prn[k], o.valid[k]) if v}
        b = {(int(s), int(p)) for s, p, v in zip(o.system[k - 1], o.prn[k - 1], o.valid[k - 1]) if v}
        assert len(cur) == len(a & b)
        np.testing.assert_array_equal(o.system[k, cur], o.system[k - 1, prev])
        np.testing.assert_array_equal(o.prn[k, cur], o.prn[k - 1, prev])
        shared += len({p for _, p in a} & {p for _, p in b}) < len(a & b)
    assert shared > 0      # numbers repeat across systems at these epochs: the key matters


@pytest.mark.parametrize("clone", [True, False])
def test_compiled_rows_equal_the_numpy_model_and_offsets_enter_by_their_change(truth, clone):
    """The TDCP rows (compiled kernel + offset terms) equal the numpy oracle with offsets in
    both epochs; noiseless observables at the true states give zero TDCP innovations when the
    current and remembered offsets are the true ones, and an offset change ``delta_g`` between
    the epochs' estimates moves exactly the rows of system ``g`` by ``-delta_g``."""
    o = _observations(truth, noise=(1e-12, 1e-12, 1e-12))
    meas = _model(o, clone)
    lay = meas.layout
    true_aux = {"system_offset": OFFSETS_LAYOUT.copy()}
    checked = 0
    for k in range(1, len(o.time), 13):
        mem = meas.remember(k - 1, _nav(truth, o, k - 1), np.zeros(3), o.clock[k - 1], aux=true_aux)
        nav = _nav(truth, o, k)
        rows = meas.rows(k, nav, np.zeros(3), o.clock[k], mem, aux=true_aux)
        n_pr = int(o.valid[k].sum())
        assert np.abs(rows.z[:n_pr]).max() < 1e-5       # pseudoranges: the offsets are in them
        assert np.abs(rows.z[n_pr:]).max() < 1e-5       # TDCP: they cancel
        delta = np.array([0.5, -1.5, 2.5])
        moved = {"system_offset": OFFSETS_LAYOUT + delta}
        z1 = meas.rows(k, nav, np.zeros(3), o.clock[k], mem, aux=moved)
        cur, _ = meas._common_slots(k - 1, k)
        g = meas._sys[k, cur]
        np.testing.assert_allclose(z1.z[n_pr:], -np.concatenate([[0.0], delta])[g], atol=1e-5)
        zt, Ht, rt = meas.tdcp_rows_numpy(k, nav, o.clock[k], mem, aux=moved)
        np.testing.assert_allclose(z1.z[n_pr:], zt, rtol=0, atol=1e-7)
        np.testing.assert_allclose(z1.H[n_pr:], Ht, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(z1.R[n_pr:], rt)
        # the offset columns: +1 for the system's own, and -1 in its clone column
        i_off = lay.slice("system_offset").start
        for j, gj in enumerate(g):
            row = z1.H[n_pr + j]
            assert row[i_off:i_off + 3].tolist() == [float(gj == q) for q in (1, 2, 3)]
            if clone:
                assert row[lay.n + 4:lay.n + 7].tolist() == [-float(gj == q) for q in (1, 2, 3)]
        checked += len(cur)
    assert checked > 200


def test_clone_offsets_follow_the_correction(truth):
    """The clone's offset part: ``J`` picks the offset states, and a clone correction moves
    the remembered offsets, so the TDCP innovation of system ``g`` moves by +dx_c (finite
    differences of the rows against the clone columns of ``H``)."""
    o = _observations(truth)
    meas = _model(o)
    lay = meas.layout
    J = meas.clone_rows(_nav(truth, o, 5))
    i_off = lay.slice("system_offset").start
    np.testing.assert_array_equal(J[4:, i_off:i_off + 3], np.eye(3))
    assert np.count_nonzero(J[4:]) == 3
    k = 120
    aux = {"system_offset": np.array([30.0, 10.0, -15.0])}
    mem = meas.remember(k - 1, _nav(truth, o, k - 1), np.zeros(3), np.array([4.0, 0.3]), aux=aux)
    nav, clock = _nav(truth, o, k), np.array([4.3, 0.3])
    r0 = meas.rows(k, nav, np.zeros(3), clock, mem, aux=aux)
    for j in range(3):
        dxc = np.zeros(7)
        dxc[4 + j] = 1e-2
        r1 = meas.rows(k, nav, np.zeros(3), clock, meas.correct_memory(mem, dxc), aux=aux)
        np.testing.assert_allclose(-(r1.z - r0.z) / 1e-2, r0.H[:, lay.n + 4 + j], atol=1e-6)
        eps = {"system_offset": aux["system_offset"] + 1e-2 * np.eye(3)[j]}
        r2 = meas.rows(k, nav, np.zeros(3), clock, mem, aux=eps)
        np.testing.assert_allclose(-(r2.z - r0.z) / 1e-2, r0.H[:, i_off + j], atol=1e-6)


def multi_tdcp_scenario(folder, name="tdcp-multi"):
    """tdcp-demo with Galileo, BeiDou and GLONASS beside GPS, each with a receiver offset."""
    text, _ = resolve("tdcp-demo")
    assert 'constellation = "gps30"\n' in text
    text = text.replace('constellation = "gps30"\n', 'constellation = "gps30"' + MULTI)
    text = text.replace('name = "tdcp-demo"', f'name = "{name}"')
    p = folder / f"{name}.toml"
    p.write_text(text)
    return p


@pytest.fixture(scope="module")
def multi_tdcp_runs(tmp_path_factory):
    p = multi_tdcp_scenario(tmp_path_factory.mktemp("tdcp_multi"))
    sc, src, _ = load_scenario(str(p))
    ideal = truth_and_ideal_imu(sc, src)
    tables, offsets = {m.name: [] for m in sc.methods}, []
    for seed in range(4):
        out = run_scenario(sc, src, seed=seed, ideal=ideal)
        for name, res in out.results.items():
            assert sum(res.recoveries.values()) == 0, (name, res.recoveries)
            tables[name].append(solution_table(res, out.sim.truth, out.sim.outages))
        offsets.append(out.results["tdcp"])
    return tables, offsets


def test_four_system_tdcp_is_consistent_and_finds_the_offsets(multi_tdcp_runs):
    """The tdcp-ekf (clone) on four systems: run-averaged position and velocity NEES per dof
    in tdcp-demo's band for GPS alone (0.3..1.2, test_tdcp: below 1 because successive TDCPs
    share an epoch, correlation -1/2, taken as white) over 4 runs; the shortcut's far above;
    each run's final offsets within 3 sigma of the truth (a 1-in-370 miss per offset)."""
    tables, results = multi_tdcp_runs
    nees = {k: np.mean([t["nees_pos"].mean() for t in v]) / 3 for k, v in tables.items()}
    nees_v = {k: np.mean([t["nees_vel"].mean() for t in v]) / 3 for k, v in tables.items()}
    print("four-system NEES per dof, position", nees, "velocity", nees_v)
    assert 0.3 < nees["tdcp"] < 1.2 and 0.3 < nees_v["tdcp"] < 1.2, (nees, nees_v)
    assert nees["tdcp-known"] > 100 * nees["tdcp"], nees
    for res in results:
        assert res.layout.block("system_offset").size == 3
        i = res.layout.slice("system_offset")
        est, sig = res.estimates["system_offset"][-1], res.sigma[-1, i]
        assert (np.abs(est - OFFSETS_LAYOUT) < 3 * sig).all(), (est, sig)


@pytest.fixture(scope="module")
def exported_multi_tdcp(tmp_path_factory):
    from tests.test_rinex_ins import export_and_process
    root = tmp_path_factory.mktemp("tdcp_multi_export")
    return export_and_process(multi_tdcp_scenario(root), root, hole=False)


def test_four_system_tdcp_on_rinex_equals_the_in_simulation_one(exported_multi_tdcp):
    """Mixed RINEX 3 with each system's carrier, read back: every carrier continues its arc
    (no slip in a simulation), the tdcp-ekf from the simulation's start on the read-back
    observables follows the in-simulation one to < 1 cm at every epoch and its offsets to
    1 cm (pseudoranges agree to 0.5 mm, carrier differences to 0.2 mm: test_tight_multi,
    test_rinex_carrier); `mixnav process` ran tdcp-ekf with three offset states."""
    from tests.test_rinex_ins import simulated_and_read_back_runs
    _, _, ex, po = exported_multi_tdcp
    counts = po.checks["rinex"]["cycle_slips"]
    assert set(counts) == set("GREC")
    for c in counts.values():
        assert c["loss of lock"] == c["gap"] == c["Doppler"] == 0
        assert c["continuous"] == c["observations"] - c["arc start"]
    res, meas_used = simulated_and_read_back_runs(
        exported_multi_tdcp, lambda x: x.type == "tdcp-ekf" and x.tdcp_previous == "clone")
    for meas in meas_used:
        assert meas[0].n_off == 3 and meas[0].clone_size == 7
    d = ned_displacement(res[1].nav[:, 7:10], res[0].nav[:, 7:10])
    print("four-system tdcp-ekf RINEX vs simulation: max position difference [m]", np.abs(d).max())
    assert np.abs(d).max() < 0.01
    np.testing.assert_allclose(res[1].estimates["system_offset"], res[0].estimates["system_offset"], atol=0.01)
    r = po.results["tdcp"]
    assert r.layout.block("system_offset").size == 3
    i = r.layout.slice("system_offset")
    assert (np.abs(r.estimates["system_offset"][-1] - OFFSETS_LAYOUT) < 3 * r.sigma[-1, i]).all()
