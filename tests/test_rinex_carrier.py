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
