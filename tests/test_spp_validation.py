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


@pytest.mark.parametrize("weights,robust", [("rtklib", (2.5, 6.0)), ("elevation", None), ("rtklib-2.4.3", None),
                                            ("rtklib-2.4.3", (2.5, 6.0))])
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


def _two_errors(scale=1.0):
    """10 satellites G + C, mixnav's weights at ``scale`` x 1 m, errors of 7 and 11 m (times
    ``scale``) on the 80 deg and 20 deg rows: all rows together fail the chi-square; several
    single exclusions pass it, and the one of the smallest weighted residual is not the one of
    the smallest residual RMS (the setup is asserted where used)."""
    sats, rho, _ = _epochs()
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False, sigma_a=scale, sigma_b=scale,
                      validate=True)
    bad = rho.copy()
    bad[6] += 7.0 * scale
    bad[0] += 11.0 * scale
    return sats, bad, opts


def _exclusions(sats, rho, opts):
    """Every single exclusion solved without FDE: ``{row: (passes validation, chi2 / rows,
    residual RMS [m])}``; an independent loop over wls_position, the oracle of FDE's choice."""
    out = {}
    for i in range(len(rho)):
        keep = np.arange(len(rho)) != i
        c = wls_position(rho[keep], sats.select(keep), opts, system=SYSTEM[keep])
        out[i] = (c.validation == "passed", c.chi2 / c.n_sat, float(np.sqrt(np.mean(c.residuals ** 2))))
    return out


def test_fde_keeps_the_exclusion_of_the_smallest_residual_rms_in_both_engines():
    """RTKLIB raim_fde's choice among the exclusions that pass: the smallest post-fit residual
    RMS [m] (not the smallest weighted residual), in wls_position and the compiled loop."""
    sats, bad, opts = _two_errors()
    assert wls_position(bad, sats, opts, system=SYSTEM).validation == "chi-square"
    cands = {i: v for i, v in _exclusions(sats, bad, opts).items() if v[0]}
    by_rms = min(cands, key=lambda i: cands[i][2])
    by_weighted = min(cands, key=lambda i: cands[i][1])
    assert len(cands) >= 2 and by_rms != by_weighted, cands        # the two rules differ here
    fixed = wls_position(bad, sats, dataclasses.replace(opts, fde=True), system=SYSTEM)
    assert fixed.validation == "fde" and fixed.excluded == by_rms
    args = (_Fixed(sats, SYSTEM), np.full(1, 2100), 3e5 + np.zeros(1), np.zeros(10, int), sats.prn, bad)
    a, b = _both(*args, options=dataclasses.replace(opts, fde=True), system=SYSTEM)
    _assert_same(a, b)
    assert b.validation == {"epochs_passed_after_exclusion": 1} and b.n_sat.tolist() == [9]
    assert np.linalg.norm(b.pos_ecef[0] - fixed.pos_ecef) < 1e-6


def test_fde_refuses_exclusions_whose_residual_rms_exceeds_100_m():
    """The same epoch at 100 x the sigmas and errors: the chi-squares are the same (a scale
    cancels in them), so the same exclusions pass validation, but their residual RMS is
    100 x as large, beyond RTKLIB raim_fde's 100 m: none is kept, the epoch stays rejected."""
    sats, bad, opts = _two_errors(scale=100.0)
    cands = {i: v for i, v in _exclusions(sats, bad, opts).items() if v[0]}
    assert len(cands) >= 2 and min(v[2] for v in cands.values()) > 100.0, cands
    fixed = wls_position(bad, sats, dataclasses.replace(opts, fde=True), system=SYSTEM)
    assert fixed.validation == "chi-square" and fixed.excluded == -1
    args = (_Fixed(sats, SYSTEM), np.full(1, 2100), 3e5 + np.zeros(1), np.zeros(10, int), sats.prn, bad)
    a, b = _both(*args, options=dataclasses.replace(opts, fde=True), system=SYSTEM)
    _assert_same(a, b)
    assert b.status.tolist() == [STATUS_REJECTED]


def test_rtklib_243_weights_are_demo5s_with_a_third_of_the_code_sigma():
    """weights = "rtklib-2.4.3": b34's pntpos variance, demo5's with the code term 0.3 m
    (err[0] 100 x 0.003 m) instead of 0.9 m: the two variances differ by exactly
    (0.9^2 - 0.3^2) f^2 (1 + 1/sin(max(el, 5 deg))), the other terms equal."""
    el = np.radians([3.0, 15.0, 30.0, 60.0, 90.0])
    fact, var_eph = np.array([1.0, 1.5, 1.0, 1.0, 1.5]), np.array([4.0, 25.0, 5.8, 0.0, 2.0])
    atm = (None,) * 7 + ((fact, var_eph),)
    iono = np.array([1.0, 3.0, 5.0, 2.0, 0.5])
    s_ex = _sigma(SppOptions(weights="rtklib"), el, np.ones(5), atm, iono)
    s_b34 = _sigma(SppOptions(weights="rtklib-2.4.3"), el, np.ones(5), atm, iono)
    code = fact ** 2 * (1.0 + 1.0 / np.sin(np.maximum(el, np.radians(5.0))))
    np.testing.assert_allclose(s_ex ** 2 - s_b34 ** 2, (0.81 - 0.09) * code, rtol=1e-12)
    # b34's whole variance written out (pntpos.c varerr + rescode's terms)
    trop = (0.3 / (np.sin(el) + 0.1)) ** 2
    np.testing.assert_allclose(s_b34 ** 2, 0.09 * code + var_eph + 0.3 ** 2 + (0.5 * iono) ** 2 + trop, rtol=1e-12)
    with pytest.raises(ValueError, match="rtklib-2.4.3"):
        SppOptions(weights="rtklib-2.4")


def test_rtklib_243_procedure_solves_the_epochs_rtklib_243_solved(urban):  # noqa: F811
    """RTKLIB 2.4.3 b34's single-point procedure written anew (plain WLS with b34's variances,
    valsol, raim_fde: weights = "rtklib-2.4.3", validate, fde) on urbannav GPS + BeiDou, 15 deg
    mask, against b34's own per-epoch output (rnx2rtkp of commit 180043e,
    benchmarks/results/rtklib_urbannav_b34_epochs.csv): the same 802 epochs solved, and
    all but one within 0.2 m of b34's positions (the median difference is ~0.1 m of model
    detail; one epoch takes another exclusion)."""
    from pathlib import Path
    from mixnav.geodesy.frames import lla_to_ecef
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "rtklib_urbannav_b34_epochs.csv"
    rows = [ln.split(",") for ln in path.read_text().splitlines()[1:] if ln.startswith("GC,")]
    b34_tow = np.round([float(r[1]) for r in rows])
    b34_pos = np.array([lla_to_ecef(np.array([np.radians(float(r[2])), np.radians(float(r[3])), float(r[4])]))
                        for r in rows])
    obs, eph = urban
    m = np.isin(obs.system, ["G", "C"])
    opts = SppOptions(elevation_mask=np.deg2rad(15.0), weights="rtklib-2.4.3", validate=True, fde=True)
    tr = solve_epochs(eph, obs.week, obs.tow, obs.epoch[m], obs.prn[m], obs.pseudorange[m], opts,
                      system=obs.system[m])
    solved = np.round(tr.tow[tr.ok])
    assert len(b34_tow) == 802 and set(solved.tolist()) == set(b34_tow.tolist())
    order = np.argsort(b34_tow)
    d = np.linalg.norm(tr.pos_ecef[tr.ok] - b34_pos[order][np.searchsorted(b34_tow[order], solved)], axis=1)
    assert (d < 0.2).sum() >= 801 and np.median(d) < 0.15, (np.median(d), np.sort(d)[-3:])
