"""SPP validation (``SppOptions.validate``: chi-square of the weighted post-fit residuals and
GDOP, RTKLIB valsol's rule) and FDE (``SppOptions.fde``: each satellite left out in turn,
RTKLIB raim_fde's rule), in both engines.

Synthetic epochs use exact pseudoranges (the solution is the true point to 1e-3 m, so a
clean epoch's chi-square is ~0 and a 100 m error on one row is far beyond any quantile);
the chi-square quantiles are checked against the printed table values (Abramowitz & Stegun
26.8 / RTKLIB's chisqr table: 10.83, 13.82, 16.27, 18.47, 20.52 for 1..5 degrees of freedom)."""

import dataclasses

import numpy as np
import pytest

from mixnav.gnss.spp import (STATUS_OK, STATUS_REJECTED, SppOptions, chi2_limit, solve_epochs, wls_position,
                             _sigma)

from .test_spp import RX, _constellation
from .test_spp_kernel import _Fixed, _assert_same, _both, urban  # noqa: F401  (the fixture)
from .test_spp_multi import _pseudoranges

EL = [20, 30, 40, 50, 60, 70, 80, 25, 45, 65]
SYSTEM = np.array(["G"] * 6 + ["C"] * 4)


def _epochs(bad_row=2, error=100.0):
    """Epoch 0 clean, epoch 1 with ``error`` [m] on row ``bad_row``; 10 satellites G + C."""
    sats, _, _ = _constellation(n=10, el_deg=EL)
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False)
    rho = _pseudoranges(sats, SYSTEM, opts)
    bad = rho.copy()
    bad[bad_row] += error
    return sats, rho, bad


def test_chi2_quantiles_match_the_table():
    assert [round(chi2_limit(d), 2) for d in range(1, 6)] == [10.83, 13.82, 16.27, 18.47, 20.52]


def test_fde_needs_validation():
    with pytest.raises(ValueError, match="fde"):
        SppOptions(fde=True)
    with pytest.raises(ValueError, match="max_gdop"):
        SppOptions(validate=True, max_gdop=0.0)


def test_one_epoch_outlier_rejected_then_excluded():
    """wls_position: the clean epoch passes (chi-square ~0), the 100 m error fails the
    chi-square test, FDE leaves out exactly that satellite and recovers the true point."""
    sats, rho, bad = _epochs()
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False, validate=True)
    clean = wls_position(rho, sats, opts, system=SYSTEM)
    assert clean.validation == "passed" and clean.valid and clean.chi2 < 1e-6 and clean.dof == 10 - 5
    sol = wls_position(bad, sats, opts, system=SYSTEM)
    assert sol.validation == "chi-square" and not sol.valid
    # the chi-square is the weighted residuals' (an independent sum over the rows)
    sigma = _sigma(opts, sol.elevation, np.ones(sol.n_sat))
    assert sol.chi2 == pytest.approx(np.sum((sol.residuals / sigma) ** 2), rel=1e-12)
    assert sol.chi2 > chi2_limit(sol.dof)
    fixed = wls_position(bad, sats, dataclasses.replace(opts, fde=True), system=SYSTEM)
    assert fixed.validation == "fde" and fixed.valid and fixed.excluded == 2
    assert fixed.n_sat == 9 and 3 not in fixed.prn.tolist() and fixed.used_index.tolist() == [0, 1, 3, 4, 5, 6, 7, 8, 9]
    assert np.linalg.norm(fixed.pos_ecef - RX) < 1e-3 and fixed.chi2 < 1e-6


def test_gdop_limit():
    """The GDOP test: position + receiver clock of the unweighted cofactor, against the limit
    just above and just below the solution's own value."""
    sats, rho, _ = _epochs()
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False, validate=True)
    sol = wls_position(rho, sats, opts, system=SYSTEM)
    gdop = np.hypot(sol.dop["pdop"], sol.dop["tdop"])
    assert 1.0 < gdop < sol.dop["gdop"]          # the offset's own term is not in it
    above = wls_position(rho, sats, dataclasses.replace(opts, max_gdop=gdop * 1.001), system=SYSTEM)
    below = wls_position(rho, sats, dataclasses.replace(opts, max_gdop=gdop * 0.999), system=SYSTEM)
    assert above.validation == "passed" and below.validation == "gdop"
    # the compiled loop's GDOP: the same verdicts
    args = (_Fixed(sats, SYSTEM), np.full(1, 2100), 3e5 + np.zeros(1), np.zeros(10, int), sats.prn, rho)
    for factor, status, key in ((1.001, STATUS_OK, "epochs_passed"), (0.999, STATUS_REJECTED, "epochs_rejected_gdop")):
        a, b = _both(*args, options=dataclasses.replace(opts, max_gdop=gdop * factor), system=SYSTEM)
        _assert_same(a, b)
        assert b.status.tolist() == [status] and a.validation == b.validation == {key: 1}


@pytest.mark.parametrize("robust", [None, (2.5, 6.0)])
def test_solve_epochs_rejects_and_fde_recovers_in_both_engines(robust):
    """Over epochs: the clean one passes, the bad one is rejected (status, counts, no
    position, the next epoch not started from it), FDE recovers it; compiled == numpy. The
    robust solution removes the 100 m error itself, so validation passes it."""
    sats, rho, bad = _epochs()
    plan = [rho, bad, rho]
    ep = np.repeat(np.arange(3), 10)
    pr = np.concatenate(plan)
    common = dict(system=np.tile(SYSTEM, 3))
    args = (_Fixed(sats, SYSTEM), np.full(3, 2100), 3e5 + np.arange(3), ep, np.tile(sats.prn, 3), pr)
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False, validate=True, robust=robust)
    a, b = _both(*args, options=opts, **common)
    _assert_same(a, b)
    assert a.validation == b.validation
    if robust is None:
        assert b.status.tolist() == [STATUS_OK, STATUS_REJECTED, STATUS_OK]
        assert np.isnan(b.pos_ecef[1]).all() and b.n_sat[1] == 0
        assert b.validation == {"epochs_passed": 2, "epochs_rejected_chi-square": 1}
    else:
        assert b.status.tolist() == [STATUS_OK] * 3 and b.validation == {"epochs_passed": 3}
    a, b = _both(*args, options=dataclasses.replace(opts, fde=True), **common)
    _assert_same(a, b)
    assert a.validation == b.validation
    assert b.status.tolist() == [STATUS_OK] * 3
    assert np.linalg.norm(b.pos_ecef - RX, axis=1).max() < 1e-3
    if robust is None:
        assert b.validation == {"epochs_passed": 2, "epochs_passed_after_exclusion": 1}
        assert b.n_sat.tolist() == [10, 9, 10]
        assert b.skipped_by_system == {}        # the left-out satellite is not the mask's


def test_validation_off_changes_nothing():
    sats, rho, bad = _epochs()
    ep = np.repeat(np.arange(2), 10)
    args = (_Fixed(sats, SYSTEM), np.full(2, 2100), 3e5 + np.arange(2), ep, np.tile(sats.prn, 2),
            np.concatenate([rho, bad]))
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False)
    tr = solve_epochs(*args, opts, system=np.tile(SYSTEM, 2))
    assert tr.ok.all() and tr.validation == {}


@pytest.mark.parametrize("weights,robust", [("rtklib", (2.5, 6.0)), ("elevation", None)])
def test_urbannav_validation_compiled_equals_numpy(urban, weights, robust):  # noqa: F811
    """250 epochs of urbannav (GPS + BeiDou + Galileo) with validation and FDE: both engines
    give the same statuses, counts and positions; some epochs are rejected or recovered."""
    obs, eph = urban
    k = 250
    m = np.isin(obs.system, ["G", "C", "E"]) & (obs.epoch < k)
    opts = SppOptions(elevation_mask=np.deg2rad(15.0), robust=robust, weights=weights, validate=True, fde=True)
    a, b = _both(eph, obs.week[:k], obs.tow[:k], obs.epoch[m], obs.prn[m], obs.pseudorange[m], options=opts,
                 system=obs.system[m])
    _assert_same(a, b)
    assert a.validation == b.validation and a.robust == b.robust
    assert b.validation.get("epochs_passed_after_exclusion", 0) > 0
    if robust is None:      # plain WLS with mixnav's weights: some epochs no exclusion repairs
        assert b.status_counts().get(STATUS_REJECTED, 0) > 0


def test_the_validate_and_fde_keys_reach_the_spp():
    """`[raw_gnss] validate`, `fde` are the SppOptions the SPP runs with (the robust method's
    too); off by default; fde alone and a smartLoc log are refused by key."""
    from pathlib import Path

    from mixnav.config.loader import load_dataset_text
    from mixnav.errors import ConfigError
    from mixnav.experiment.spp_process import options
    root = Path(__file__).resolve().parents[1] / "src" / "mixnav" / "config" / "datasets"
    text = (root / "urbannav-tst-static.toml").read_text()
    ds, _, _ = load_dataset_text(text, "u.toml")
    assert not options(ds).validate and not options(ds).fde
    ds, _, _ = load_dataset_text(text.replace("[raw_gnss]\n", "[raw_gnss]\nvalidate = true\nfde = true\n", 1),
                                 "u.toml")
    robust = next(m for m in ds.methods if m.robust is not None)
    for o in (options(ds), options(ds, robust)):
        assert o.validate and o.fde
    assert options(ds, robust).robust is not None
    with pytest.raises(ConfigError) as e:
        load_dataset_text(text.replace("[raw_gnss]\n", "[raw_gnss]\nfde = true\n", 1), "u.toml")
    assert "fde" in str(e.value)
    sl = (root / "smartloc-berlin-gnss.toml").read_text().replace("[raw_gnss]\n", "[raw_gnss]\nvalidate = true\n", 1)
    with pytest.raises(ConfigError) as e:
        load_dataset_text(sl, "s.toml")
    assert "validate" in str(e.value)


def test_android_static_gps_validation_compiled_equals_numpy():
    """The one-system path (GPS records, BroadcastEphemeris: the mask's count summed per epoch)
    with validation and FDE on the phone log: both engines equal."""
    from mixnav.config.loader import load_dataset
    from mixnav.experiment.data_folder import find_data_dir
    from mixnav.experiment.spp_process import options, read_raw

    from .conftest import data_file
    data_file("android-static")
    ds, source, _ = load_dataset("android-static")
    obs, eph, _ = read_raw(ds, source, find_data_dir(ds, None, source))
    opts = dataclasses.replace(options(ds), validate=True, fde=True)
    a, b = _both(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange, options=opts)
    _assert_same(a, b)
    assert a.validation == b.validation and b.clock_system is None
    assert sum(b.validation.values()) == len(b.status)
