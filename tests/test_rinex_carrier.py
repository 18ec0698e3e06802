"""RINEX carrier phase and loss-of-lock indicators: written by io/rinex_write.py, read back by
io/rinex_obs.py and georinex; the TDCP observables of an exported simulated run equal the
simulator's and the tdcp-ekf on them follows the in-simulation one."""

import numpy as np
import pytest

from mixnav.data import LLI_COLUMNS
from mixnav.errors import ArgumentError
from mixnav.io.rinex_obs import read_rinex_obs
from mixnav.io.rinex_write import write_rinex_obs


def test_carrier_and_lli_read_back_by_the_reader_and_georinex(tmp_path):
    """Carriers of 1e8 cycles with sub-milli-cycle digits come back rounded to the file's
    0.001 cycle (|difference| <= 0.5e-3); each indicator in its column (0 blank); a blank
    carrier is NaN with its pseudorange kept; the old columns unchanged in value."""
    import georinex as gr
    rng = np.random.default_rng(3)
    k, per = 4, 5
    week = np.full(k, 2305)
    tow = 295200.0 + np.arange(k)
    epoch = np.repeat(np.arange(k), per)
    prn = np.tile(np.arange(1, 1 + per), k)
    rho = 2.0e7 + rng.uniform(0, 5e6, k * per)
    cp = rho / 0.1903 + rng.integers(-10 ** 6, 10 ** 6, k * per)
    dop = rng.uniform(-4000, 4000, k * per)
    lli = np.zeros(k * per, int)
    lli[[3, 8, 9]] = [1, 2, 3]
    cp[11] = np.nan
    write_rinex_obs(tmp_path / "o.rnx", week, tow, epoch, prn, rho, doppler=dop, carrier=cp, lli=lli)
    r = read_rinex_obs(tmp_path / "o.rnx")
    ok = np.isfinite(cp)
    assert np.abs(r.carrier[ok] - cp[ok]).max() <= 0.5e-3 + 1e-6 and np.isnan(r.carrier[11])
    assert np.abs(r.pseudorange - rho).max() <= 0.5e-3 + 1e-8
    assert np.abs(r.doppler - dop).max() <= 0.5e-3 + 1e-8
    np.testing.assert_array_equal(r.lli[:, LLI_COLUMNS.index("carrier")], lli)
    assert not r.lli[:, [0, 2]].any()
    ds = gr.load(tmp_path / "o.rnx")
    g = ds["L1C"].values
    sv = [int(s[1:]) for s in ds.sv.values]
    for i in np.nonzero(ok)[0]:
        assert abs(g[epoch[i], sv.index(prn[i])] - cp[i]) <= 0.5e-3 + 1e-6
    with pytest.raises(ArgumentError) as exc:
        write_rinex_obs(tmp_path / "x.rnx", week, tow, epoch, prn, rho, lli=lli)
    assert exc.value.argument == "lli"
    with pytest.raises(ArgumentError) as exc:
        write_rinex_obs(tmp_path / "x.rnx", week, tow, epoch, prn, rho, carrier=cp, lli=lli + 8)
    assert exc.value.argument == "lli"
    with pytest.raises(ArgumentError) as exc:
        write_rinex_obs(tmp_path / "x.rnx", week, tow, epoch, prn, rho, carrier=np.full(k * per, 2e10))
    assert exc.value.argument == "carrier"
    assert not (tmp_path / "x.rnx").exists()


# ------------------------------------------------------------------ the round trip


@pytest.fixture(scope="module")
def exported_tdcp(tmp_path_factory):
    """tdcp-demo exported (IMU CSV, RINEX with L1C) and processed back (SPP, alignment, the
    tight and tdcp-ekf methods on the file's carrier with cycle-slip detection)."""
    from tests.test_rinex_ins import export_and_process
    return export_and_process("tdcp-demo", tmp_path_factory.mktemp("tdcprinex"), hole=False)


def test_export_carries_the_tdcp_methods_and_carrier(exported_tdcp):
    sc, _, ex, po = exported_tdcp
    assert "tdcp" in ex.methods and "tdcp-known" in ex.methods
    assert po.dataset.raw_gnss.carrier_sigma == sc.gnss.satellites.carrier_sigma
    counts = po.checks["rinex"]["cycle_slips"]["G"]
    # a simulated carrier has no slip: every observation continues its arc but the first of
    # each satellite (no loss of lock, no gap, no Doppler alarm at 5 sigma over ~5000 pairs)
    assert counts["loss of lock"] == counts["gap"] == counts["Doppler"] == 0
    assert counts["continuous"] == counts["observations"] - counts["arc start"]


def test_rinex_carrier_equals_the_simulated_one(exported_tdcp):
    """The tdcp filter's carrier rebuilt from L1C: the simulator's [m] up to the file's
    0.001-cycle rounding (0.1 mm) in every time difference: the ambiguities and the
    (zero here) corrections cancel; every slot continuous after the satellite's first epoch."""
    _, _, ex, po = exported_tdcp
    a, b = ex.sim.observations, po.observations
    np.testing.assert_array_equal(a.time, b.time)
    worst = 0.0
    for k in range(1, len(a)):
        for j in np.nonzero(a.valid[k])[0]:
            p = a.prn[k, j]
            i = list(b.prn[k]).index(p)
            if p not in a.prn[k - 1][a.valid[k - 1]]:
                continue
            jp, ip = list(a.prn[k - 1]).index(p), list(b.prn[k - 1]).index(p)
            d_sim = a.carrier[k, j] - a.carrier[k - 1, jp]
            d_rnx = b.carrier[k, i] - b.carrier[k - 1, ip]
            worst = max(worst, abs(d_sim - d_rnx))
            assert b.carrier_continuous[k, i]
    assert worst <= 2 * 0.5e-3 * 0.1903 + 1e-7, worst
    assert b.sigma_cp == a.sigma_cp


def test_tdcp_ekf_on_rinex_equals_the_in_simulation_one(exported_tdcp):
    """Same start, same IMU: the tdcp-ekf (clone) on the RINEX observables follows the
    in-simulation one to < 1 cm at every epoch (pseudoranges agree to 0.5 mm, TDCPs to 0.2 mm,
    satellite positions to a few mm: test_rinex_ins)."""
    from mixnav.geodesy.frames import ned_displacement
    from tests.test_rinex_ins import simulated_and_read_back_runs
    res, _ = simulated_and_read_back_runs(exported_tdcp,
                                          lambda x: x.type == "tdcp-ekf" and x.tdcp_previous == "clone")
    d = ned_displacement(res[1].nav[:, 7:10], res[0].nav[:, 7:10])
    print("tdcp-ekf RINEX vs simulation: max position difference [m]", np.abs(d).max(),
          "velocity", np.abs(res[1].nav[:, 4:7] - res[0].nav[:, 4:7]).max())
    assert np.abs(d).max() < 0.01


def test_tdcp_on_a_file_without_carrier_is_refused(exported_tdcp, tmp_path):
    """A tdcp-ekf method on a RINEX file without L1C: a config error naming its key, before any work."""
    from mixnav.config.loader import load_dataset
    from mixnav.errors import ConfigError
    from mixnav.experiment.process import process
    _, _, ex, _ = exported_tdcp
    folder = ex.files["dataset"].parent
    obs = read_rinex_obs(folder / "obs.rnx")
    write_rinex_obs(tmp_path / "nocp.rnx", obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange,
                    doppler=obs.doppler)
    text = ex.files["dataset"].read_text().replace('file = "obs.rnx"', f'file = "{tmp_path / "nocp.rnx"}"')
    (tmp_path / "d.toml").write_text(text)
    ds, src, _ = load_dataset(str(tmp_path / "d.toml"))
    i = next(j for j, m in enumerate(ds.methods) if m.type == "tdcp-ekf")
    with pytest.raises(ConfigError) as exc:
        process(ds, src)
    assert exc.value.key == f"methods[{i}].type" and "carrier" in str(exc.value)


#: GPS L2 / L1 frequency ratio (1227.60 / 1575.42 MHz = 60 / 77)
F2_OVER_F1 = 60.0 / 77.0


def _with_l2(src, dst, slip_prn: int, slip_epoch: int, slip_cycles: float):
    """``src`` (the export's GPS RINEX 3: C1C L1C D1C) with C2L and L2L added: C2L = C1C, L2L
    = L1C f2/f1 (so lambda1 phi1 - lambda2 phi2 = 0), plus ``slip_cycles`` on L2 alone of
    satellite ``slip_prn`` from the ``slip_epoch``-th epoch record on (a slip the L1 carrier
    and Doppler know nothing of)."""
    out, epoch = [], -1
    for line in src.read_text().splitlines():
        if line.endswith("SYS / # / OBS TYPES"):
            line = f"{'G    5 C1C L1C D1C C2L L2L':<60}SYS / # / OBS TYPES"
        elif line.startswith(">"):
            epoch += 1
        elif line.startswith("G") and epoch >= 0:
            f = line[3:].ljust(48)
            c1, l1 = float(f[0:14]), float(f[16:30])
            l2 = l1 * F2_OVER_F1 + (slip_cycles if int(line[1:3]) == slip_prn and epoch >= slip_epoch else 0.0)
            line = f"{line[:3]}{f}{c1:14.3f}  {l2:14.3f}"
        out.append(line)
    dst.write_text("\n".join(out) + "\n")


def test_second_signal_adds_the_geometry_free_check(exported_tdcp, tmp_path):
    """``[raw_gnss] second_signals = { G = "C2L" }``: the file is read again for C2L/L2L and the
    geometry-free check runs on the tdcp-ekf's carrier arcs. A 7-cycle slip on L2 alone (one
    satellite, one epoch on) is found there and only there (lambda_2 7 = 1.7 m against the
    4 cm threshold; the L1 carrier, Doppler and loss-of-lock flags see nothing), counted
    under the system and reason, and the TDCP arc is cut at that one slot."""
    from mixnav.config.loader import load_dataset
    from mixnav.experiment.process import process
    _, _, ex, po0 = exported_tdcp
    folder = ex.files["dataset"].parent
    _with_l2(folder / "obs.rnx", tmp_path / "obs2.rnx", slip_prn=7, slip_epoch=150, slip_cycles=7.0)
    text = ex.files["dataset"].read_text().replace('file = "obs.rnx"', f'file = "{tmp_path / "obs2.rnx"}"')
    text = text.replace('carrier_sigma = ', 'second_signals = { G = "C2L" }\ncarrier_sigma = ')
    (tmp_path / "d.toml").write_text(text)
    ds, src, _ = load_dataset(str(tmp_path / "d.toml"))
    po = process(ds, src)
    rinex = po.checks["rinex"]
    assert "C2L" in rinex["second_signals"] and po0.checks["rinex"]["second_signals"] is None
    c, c0 = rinex["cycle_slips"]["G"], po0.checks["rinex"]["cycle_slips"]["G"]
    assert c["geometry-free"] == 1 and c0.get("geometry-free", 0) == 0
    assert c["loss of lock"] == c["gap"] == c["Doppler"] == 0
    assert c["continuous"] == c0["continuous"] - 1 and c["observations"] == c0["observations"]
    # the one slot whose arc is cut: satellite 7, beside the arc starts both runs have
    o, o0 = po.observations, po0.observations
    cut = o.valid & np.isfinite(o.carrier) & ~o.carrier_continuous
    cut0 = o0.valid & np.isfinite(o0.carrier) & ~o0.carrier_continuous
    extra = cut & ~cut0
    assert extra.sum() == 1 and o.prn[extra].tolist() == [7] and not (cut0 & ~cut).any()


def test_second_signals_are_checked(exported_tdcp, tmp_path):
    """A second signal on the first one's band, or of a system not read: a ConfigError on the
    [raw_gnss] table whose message starts with the key (as the table's other cross-key checks)."""
    from mixnav.config.loader import load_dataset
    from mixnav.errors import ConfigError
    _, _, ex, _ = exported_tdcp
    for value, why in (('{ G = "C1W" }', "band"), ('{ E = "C7Q" }', "systems")):
        text = ex.files["dataset"].read_text().replace('carrier_sigma = ', f'second_signals = {value}\ncarrier_sigma = ')
        (tmp_path / "d.toml").write_text(text)
        with pytest.raises(ConfigError, match=why) as exc:
            load_dataset(str(tmp_path / "d.toml"))
        assert exc.value.key == "raw_gnss" and "second_signals: " in str(exc.value)
