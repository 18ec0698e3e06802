"""The compiled SPP (gnss/_spp_kernel.py, ``SppOptions.engine = "compiled"``) against the
numpy solution epoch by epoch (``engine = "numpy"``, the independent reference), and the
batched satellite states (MultiEphemeris.states_by_system) against the per-epoch ones.

Tolerances: positions, clocks and offsets 1e-6 m (the two differ by their linear algebra's
rounding, 1e-8 m seen); DOPs 1e-9; covariances 1e-9 relative; everything discrete (status,
counts, systems) equal."""

import dataclasses

import numpy as np
import pytest

from mixnav.gnss.multi_ephemeris import MultiEphemeris
from mixnav.gnss.spp import STATUS_FEW, STATUS_NOT_CONVERGED, STATUS_OK, SppOptions, solve_epochs

from .conftest import data_file
from .test_spp import CLOCK, RX, _constellation
from .test_spp_multi import OFFSETS, URBAN, _pseudoranges


def _both(*args, options, **kw):
    a = solve_epochs(*args, dataclasses.replace(options, engine="numpy"), **kw)
    b = solve_epochs(*args, dataclasses.replace(options, engine="compiled"), **kw)
    return a, b


def _assert_same(a, b):
    assert a.status.tolist() == b.status.tolist()
    assert np.array_equal(np.isnan(a.pos_ecef), np.isnan(b.pos_ecef))
    ok = a.ok
    assert np.abs(a.pos_ecef[ok] - b.pos_ecef[ok]).max(initial=0.0) < 1e-6
    assert np.abs(a.clock_bias[ok] - b.clock_bias[ok]).max(initial=0.0) < 1e-6
    assert np.abs(a.rms_residual[ok] - b.rms_residual[ok]).max(initial=0.0) < 1e-6
    for d in ("pdop", "hdop", "vdop"):
        assert np.abs(getattr(a, d)[ok] - getattr(b, d)[ok]).max(initial=0.0) < 1e-9
    assert np.allclose(a.cov[ok], b.cov[ok], rtol=1e-9, atol=1e-12)
    assert np.array_equal(np.isnan(a.cov), np.isnan(b.cov))
    assert a.n_sat.tolist() == b.n_sat.tolist()
    assert a.skipped_satellites == b.skipped_satellites
    assert a.skipped_by_system == b.skipped_by_system
    assert set(a.offsets) == set(b.offsets)
    for s in a.offsets:
        assert np.array_equal(np.isnan(a.offsets[s]), np.isnan(b.offsets[s]))
        f = np.isfinite(a.offsets[s])
        assert np.abs(a.offsets[s][f] - b.offsets[s][f]).max(initial=0.0) < 1e-6
        assert a.n_sat_system[s].tolist() == b.n_sat_system[s].tolist()
    if a.clock_system is None:
        assert b.clock_system is None
    else:
        assert a.clock_system.tolist() == b.clock_system.tolist()


# ------------------------------------------------------------ every rule, closed form
class _Fixed:
    """A MultiEphemeris stand-in: fixed states by satellite id, any time; ids it does not
    know are ``no ephemeris``."""

    def __init__(self, sats, system):
        self.sats, self.ids = sats, [f"{s}{p:02d}" for s, p in zip(system, sats.prn)]

    def __contains__(self, s):
        return False

    def states_of(self, ids, week, tow, apply_group_delay=True):
        from mixnav.gnss.ephemeris import EphemerisSkips
        ids = [str(i) for i in ids]
        keep = np.array([i in self.ids for i in ids])
        idx = np.array([self.ids.index(i) for i in ids if i in self.ids], int)
        skips = {i[0]: EphemerisSkips(np.array([int(i[1:])]), ("no ephemeris",)) for i in np.array(ids)[~keep]}
        return self.sats.select(idx), np.array([i[0] for i in ids])[keep], keep, skips


def test_every_rule_equals_numpy_and_the_closed_form():
    """Epochs built to take each branch: two GPS rows under the mask (counted per system),
    GPS present but all under the mask (BeiDou takes the clock), 3 rows (too few before the
    solution; the next epoch keeps the start), too few after the mask (the start is
    dropped), BeiDou alone, a satellite without ephemeris, per-row sigma factors. Exact
    pseudoranges: the solution is the true point, clock and offset."""
    el = [5, 7, 20, 35, 50, 65, 80, 25, 45, 60]
    sats, _, _ = _constellation(n=10, el_deg=el, az_deg=np.arange(10) * 36.0 + 5)
    system = np.array(["G"] * 5 + ["C"] * 5)
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False)
    rho = _pseudoranges(sats, system, opts)
    plan = [list(range(10)), [0, 1, 5, 6, 7, 8, 9], [2, 3, 5], [0, 1, 2, 3, 5], [5, 6, 7, 8, 9],
            [2, 3, 4, 5, 6, 7, -1], list(range(10))]
    ep = np.concatenate([np.full(len(p), j) for j, p in enumerate(plan)])
    idx = np.concatenate(plan)
    prn = np.where(idx >= 0, sats.prn[idx], 30)
    sys_rows = np.where(idx >= 0, system[idx], "C")
    pr = np.where(idx >= 0, rho[idx], 2.2e7)
    scale = np.where(ep == 6, np.linspace(0.5, 3.0, len(ep)), 1.0)
    k = len(plan)
    a, b = _both(_Fixed(sats, system), np.full(k, 2100), 3e5 + np.arange(k), ep, prn, pr, options=opts,
                 system=sys_rows, sigma_scale=scale)
    _assert_same(a, b)
    assert b.status.tolist() == [STATUS_OK, STATUS_OK, STATUS_FEW, STATUS_FEW, STATUS_OK, STATUS_OK, STATUS_OK]
    ok = b.ok
    assert np.linalg.norm(b.pos_ecef[ok] - RX, axis=1).max() < 1e-3
    assert b.clock_system.tolist() == ["G", "C", "", "", "C", "G", "G"]
    assert abs(b.clock_bias[1] - (CLOCK + OFFSETS["C"])) < 1e-3          # the clock is BeiDou's
    assert abs(b.clock_bias[0] - CLOCK) < 1e-3 and abs(b.offsets["C"][0] - OFFSETS["C"]) < 1e-3
    assert np.isnan(b.offsets["G"][1]) and b.offsets["C"][1] == 0.0
    assert b.n_sat_system["G"].tolist() == [3, 0, 0, 0, 0, 3, 3]
    assert b.n_sat_system["C"].tolist() == [5, 5, 0, 0, 5, 3, 5]
    # below the mask: 2 in epochs 0, 1, 6 (epoch 3 raised: not counted); C30: no ephemeris
    assert b.skipped_by_system == {"GPS": {"below elevation mask": 6}, "BeiDou": {"no ephemeris": 1}}


# ------------------------------------------------------------ the urbannav log
@pytest.fixture(scope="module")
def urban():
    from mixnav.io.rinex_obs import read_rinex_obs
    obs = read_rinex_obs(data_file("urbannav-tst-static", "2020_06_03_TST_03.obs"), systems="GREC")
    eph = MultiEphemeris.from_rinex(sorted(URBAN.glob("hksc155*")))
    return obs.with_glonass_channels(eph["R"].channels()), eph


@pytest.mark.parametrize("systems", ["G", "GC", "GREC"])
def test_urbannav_compiled_equals_numpy(urban, systems):
    obs, eph = urban
    m = np.isin(obs.system, list(systems))
    a, b = _both(eph, obs.week, obs.tow, obs.epoch[m], obs.prn[m], obs.pseudorange[m],
                 options=SppOptions(elevation_mask=np.deg2rad(15.0)), system=obs.system[m],
                 glonass_channel=obs.glonass_channel()[m])
    _assert_same(a, b)
    assert b.ok.sum() == 986 and b.skipped_satellites["below elevation mask"] > 0


@pytest.mark.parametrize("max_iter", [2, 3])
def test_urbannav_unsettled_epochs_equal_numpy(urban, max_iter):
    """Few iterations (2: no epoch converges, each start dropped; 3: they do), a high mask,
    sigma factors per row, and two GPS satellites of three cut away every fifth epoch
    (too few after the mask): statuses of every kind, equal to the numpy path's."""
    obs, eph = urban
    k = 150
    m = np.isin(obs.system, ["G", "E"]) & (obs.epoch < k)
    m &= ~((obs.epoch % 5 == 0) & (obs.system == "G") & (obs.prn % 3 > 0))
    rng = np.random.default_rng(7)
    opts = SppOptions(elevation_mask=np.deg2rad(30.0), max_iter=max_iter)
    a, b = _both(eph, obs.week[:k], obs.tow[:k], obs.epoch[m], obs.prn[m], obs.pseudorange[m], options=opts,
                 system=obs.system[m], sigma_scale=rng.uniform(0.5, 2.0, int(m.sum())))
    _assert_same(a, b)
    counts = b.status_counts()
    assert counts[STATUS_FEW] >= 20
    assert counts[STATUS_NOT_CONVERGED if max_iter == 2 else STATUS_OK] == k - counts[STATUS_FEW]


def test_batched_states_equal_per_epoch(urban):
    """states_by_system on every observation of 60 epochs at once equals states_of epoch by
    epoch, bit for bit (the record choice and the orbits are per row)."""
    obs, eph = urban
    m = obs.epoch < 60
    ep = obs.epoch[m]
    ids = np.char.add(obs.system[m].astype(str), np.char.zfill(obs.prn[m].astype(str), 2))
    tow = obs.tow[ep] - obs.pseudorange[m] / 299792458.0
    pos, vel, clk, drift, reason = eph.states_by_system(obs.system[m], obs.prn[m], obs.week[ep], tow, chunk=97)
    for j in range(60):
        r = ep == j
        st, _, keep, skips = eph.states_of(ids[r], obs.week[j], tow[r])
        assert np.array_equal(reason[r] == "", keep)
        assert np.array_equal(pos[r][keep], st.pos_ecef) and np.array_equal(clk[r][keep], st.clock_bias)
        assert np.array_equal(vel[r][keep], st.vel_ecef) and np.array_equal(drift[r][keep], st.clock_drift)
        assert sorted(reason[r][~keep].tolist()) == sorted(x for s in skips.values() for x in s.reason)
    assert (reason != "").any()


def test_android_static_gps_compiled_equals_numpy():
    """The one-system path (GPS records, BroadcastEphemeris) on the phone log."""
    from mixnav.config.loader import load_dataset
    from mixnav.experiment.data_folder import find_data_dir
    from mixnav.experiment.spp_process import options, read_raw
    data_file("android-static")
    ds, source, _ = load_dataset("android-static")
    obs, eph, _ = read_raw(ds, source, find_data_dir(ds, None, source))
    assert not hasattr(eph, "states_of")
    a, b = _both(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange, options=options(ds))
    _assert_same(a, b)
    assert b.ok.all() and b.clock_system is None


def test_engine_is_checked():
    with pytest.raises(ValueError, match="engine"):
        SppOptions(engine="fast")


# ------------------------------------------------------------ RTKLIB's weights
def test_rtklib_variance_closed_form():
    """RTKLIB pntpos's variance of one row, by hand: GPS at 30 deg, URA 2.4 m, a 4 m
    ionosphere delay, Saastamoinen: 0.9^2 (1 + 1/sin 30) + 2.4^2 + 0.3^2 + (0.5 x 4)^2 +
    (0.3 / (sin 30 + 0.1))^2 = 2.43 + 5.76 + 0.09 + 4 + 0.25 = 12.53 m^2; GLONASS's code
    term 1.5^2 times; below 5 deg the code term is held at 5 deg's."""
    from mixnav.gnss.spp import _sigma
    opts = SppOptions(weights="rtklib")
    el = np.deg2rad([30.0, 30.0, 2.0, 5.0])
    atm = (None,) * 7 + ((np.array([1.0, 1.5, 1.0, 1.0]), np.full(4, 2.4**2)),)
    iono = np.array([4.0, 4.0, 0.0, 0.0])
    var = _sigma(opts, el, np.ones(4), atm, iono) ** 2
    assert var[0] == pytest.approx(12.53, abs=1e-12)
    assert var[1] - var[0] == pytest.approx((1.5**2 - 1) * 2.43, abs=1e-12)
    code = lambda e: 0.81 * (1 + 1 / np.sin(e))  # noqa: E731
    trop = lambda e: (0.3 / (np.sin(e) + 0.1)) ** 2  # noqa: E731
    assert var[2] - trop(el[2]) == pytest.approx(var[3] - trop(el[3]), abs=1e-12)
    assert var[3] == pytest.approx(code(el[3]) + 5.76 + 0.09 + trop(el[3]), abs=1e-12)
    # without the ionosphere model: its 5 m instead
    assert (_sigma(opts, el, np.ones(4), atm, None) ** 2 - var)[2] == pytest.approx(25.0, abs=1e-12)


def test_ephemeris_variance_from_the_accuracy_field():
    from mixnav.gnss.multi_ephemeris import ephemeris_variance
    # GPS / BeiDou URA [m] -> the table entry at or above it (IS-GPS-200 20.3.3.3.1.1)
    sig = np.sqrt(ephemeris_variance("G", [0.0, 2.0, 2.4, 2.41, 6144.0, 1e4, np.nan]))
    assert sig.tolist() == pytest.approx([2.4, 2.4, 2.4, 3.4, 6144.0, 6144.0, 6144.0])
    # Galileo SISA [m]: its encoding's steps; beyond 6 m, negative or blank: NAPA 500 m
    sig = np.sqrt(ephemeris_variance("E", [0.3, 0.51, 1.0, 3.12, 6.5, -1.0, np.nan]))
    assert sig.tolist() == pytest.approx([0.3, 0.52, 1.0, 3.12, 500.0, 500.0, 500.0])
    assert ephemeris_variance("R", [1.0]).tolist() == [25.0]


def test_urbannav_ura_read(urban):
    _, eph = urban
    for s in "GEC":
        assert np.isfinite(eph[s].rec["ura"]).all() and (eph[s].rec["ura"] > 0).all()
    assert set(np.unique(eph["G"].rec["ura"]).tolist()) == {2.0, 2.8}


def test_rtklib_weights_compiled_equals_numpy(urban):
    obs, eph = urban
    m = obs.epoch < 200
    a, b = _both(eph, obs.week[:200], obs.tow[:200], obs.epoch[m], obs.prn[m], obs.pseudorange[m],
                 options=SppOptions(elevation_mask=np.deg2rad(15.0), weights="rtklib"), system=obs.system[m],
                 glonass_channel=obs.glonass_channel()[m])
    _assert_same(a, b)
    # the weights change the solution: metres, not rounding
    c = solve_epochs(eph, obs.week[:200], obs.tow[:200], obs.epoch[m], obs.prn[m], obs.pseudorange[m],
                     SppOptions(elevation_mask=np.deg2rad(15.0)), system=obs.system[m],
                     glonass_channel=obs.glonass_channel()[m])
    assert np.linalg.norm(c.pos_ecef - b.pos_ecef, axis=1).mean() > 1.0


def test_rtklib_weights_need_the_accuracy():
    sats, _, _ = _constellation(n=6)
    with pytest.raises(ValueError, match="ephemeris_var"):
        from mixnav.gnss.spp import wls_position
        wls_position(np.full(6, 2.2e7), sats, SppOptions(weights="rtklib"))
    with pytest.raises(ValueError, match="weights"):
        SppOptions(weights="rtk")


# ------------------------------------------------------------ the robust solution compiled
def test_robust_compiled_equals_numpy_and_removes_an_outlier():
    """IGG-III data snooping in the compiled loop: an 80 m error on one of 10 satellites is
    excluded (the solution back at the true point, the counts say so), and every epoch
    equals the numpy path's; with 5 rows of one system the error cannot be located
    (untestable below 2 spare rows)."""
    sats, _, _ = _constellation(n=10, el_deg=[20, 30, 40, 50, 60, 70, 80, 25, 45, 65])
    system = np.array(["G"] * 6 + ["C"] * 4)
    opts = SppOptions(elevation_mask=np.deg2rad(10.0), ionosphere=False, robust=(2.5, 6.0))
    rho = _pseudoranges(sats, system, opts)
    bad = rho.copy()
    bad[2] += 80.0
    plan = [(rho, range(10)), (bad, range(10)), (bad, range(5))]
    ep = np.concatenate([np.full(len(p), j) for j, (_, p) in enumerate(plan)])
    idx = np.concatenate([list(p) for _, p in plan])
    pr = np.concatenate([r[list(p)] for r, p in plan])
    a, b = _both(_Fixed(sats, system), np.full(3, 2100), 3e5 + np.arange(3), ep, sats.prn[idx], pr, options=opts,
                 system=system[idx])
    _assert_same(a, b)
    assert a.robust == b.robust == {"rows_downweighted": 0, "rows_excluded": 1, "epochs_ok": 2,
                                    "epochs_untestable": 1}
    assert np.linalg.norm(b.pos_ecef[:2] - RX, axis=1).max() < 1e-3
    assert b.n_sat.tolist() == [10, 9, 5]
    assert np.linalg.norm(b.pos_ecef[2] - RX) > 1.0           # untestable: the error stays


@pytest.mark.parametrize("weights", ["elevation", "rtklib"])
def test_urbannav_robust_compiled_equals_numpy(urban, weights):
    obs, eph = urban
    k = 250
    m = np.isin(obs.system, ["G", "C", "E"]) & (obs.epoch < k)
    opts = SppOptions(elevation_mask=np.deg2rad(15.0), robust=(2.5, 6.0), weights=weights)
    a, b = _both(eph, obs.week[:k], obs.tow[:k], obs.epoch[m], obs.prn[m], obs.pseudorange[m], options=opts,
                 system=obs.system[m])
    _assert_same(a, b)
    assert a.robust == b.robust
    assert b.robust["rows_excluded"] > 0 and b.robust.get("epochs_not_separable", 0) > 0
