"""Cycle-slip detection (mixnav.gnss.cycle_slips): injected slips of known size and epoch in
simulated carriers are found where they are and nowhere else; each rule on its own; the
Doppler residual against a plain loop; the real urbannav carrier."""

from pathlib import Path

import numpy as np
import pytest

from mixnav.errors import ArgumentError
from mixnav.gnss.cycle_slips import REASONS, carrier_frequency, detect_cycle_slips, slips_of_observations
from mixnav.gnss.geometry import C_LIGHT

LAM1 = C_LIGHT / 1575.42e6
LAM2 = C_LIGHT / 1227.60e6
URBANNAV = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "urbannav-tst-static"


def simulated(rng, n_sat=8, n_ep=600, sigma_d=0.05, sigma_phi=0.01, rate=1.0):
    """Carriers [cycles] and Doppler [Hz] of ``n_sat`` satellites over ``n_ep`` epochs: ranges
    with a line-of-sight velocity and a slowly varying acceleration (a few mm/s^2, a satellite
    pass), two frequencies with the ionosphere (a few mm/s on L1), white noise."""
    t = np.arange(n_ep) / rate
    rows = []
    for j in range(n_sat):
        v, a, w = rng.uniform(-800, 800), rng.uniform(-0.2, 0.2), rng.uniform(1e-3, 3e-3)
        rho = 2.2e7 + v * t + 0.5 * a * t ** 2 + 50.0 * np.sin(w * t)        # [m]
        rho_dot = v + a * t + 50.0 * w * np.cos(w * t)
        iono = 3.0 + 0.002 * t                                               # L1 delay [m]
        n1, n2 = rng.integers(-10 ** 6, 10 ** 6, 2)
        phi1 = (rho - iono) / LAM1 + n1 + rng.standard_normal(n_ep) * sigma_phi
        phi2 = (rho - iono * (1575.42 / 1227.60) ** 2) / LAM2 + n2 + rng.standard_normal(n_ep) * sigma_phi
        dop = -(rho_dot - 0.002) / LAM1 + rng.standard_normal(n_ep) * sigma_d
        rows.append((np.arange(n_ep), np.full(n_ep, j), phi1, phi2, dop))
    ep, sat, phi1, phi2, dop = (np.concatenate(c) for c in zip(*rows))
    return t, ep, sat, phi1, phi2, dop


def inject(sat, ep, phi, where, sizes):
    """Add ``sizes`` cycles to satellite ``s``'s carrier from epoch ``k`` on, for each (s, k)."""
    phi = phi.copy()
    for (s, k), d in zip(where, sizes):
        phi[(sat == s) & (ep >= k)] += d
    return phi


SLIPS = [(0, 100), (1, 250), (2, 251), (3, 400), (4, 50), (5, 599), (6, 300), (7, 10)]
SIZES = [1.0, -1.0, 2.0, 0.5, 5.0, -100.0, 1000.0, -3.0]


def slip_index(ep, sat, where):
    return sorted(int(np.flatnonzero((sat == s) & (ep == k))[0]) for s, k in where)


@pytest.mark.parametrize("doppler_sigma", [0.05, None])
def test_doppler_check_finds_injected_slips_and_nothing_else(doppler_sigma):
    # 8 satellites x 599 pairs = 4792 tests at 5 sigma: P(false alarm) 5.7e-7 each, 0.003
    # expected in all (seeded, so the result is fixed; other seeds agree); a 0.5-cycle slip
    # stands 0.5 / 0.035 = 14 sigma off, missed with probability ~0.
    rng = np.random.default_rng(36)
    t, ep, sat, phi1, _, dop = simulated(rng)
    phi = inject(sat, ep, phi1, SLIPS, SIZES)
    clean = detect_cycle_slips(t, ep, sat, phi1, doppler=dop, doppler_sigma=doppler_sigma)
    assert clean.counts["G"]["Doppler"] == 0
    assert clean.counts["G"]["continuous"] == len(ep) - 8           # all but the arc starts
    found = detect_cycle_slips(t, ep, sat, phi, doppler=dop, doppler_sigma=doppler_sigma)
    assert sorted(np.flatnonzero(found.slips()).tolist()) == slip_index(ep, sat, SLIPS)
    assert (found.flags[found.slips()] == REASONS["Doppler"]).all()
    if doppler_sigma is None:
        # the MAD of the clean residuals: sqrt(0.05^2/2 + 2 0.01^2) = 0.0387 per pair, widened by the
        # leave-one-out median of the 7 other satellites, sqrt(1 + pi / 14): 0.0428 (4792 pairs:
        # the MAD's own scatter about 1.7 %, so 6 % is 3.5 of its sigmas)
        assert found.doppler_sigma["G"] == pytest.approx(0.0387 * np.sqrt(1 + np.pi / 14), rel=0.06)


def test_doppler_residual_against_a_plain_loop():
    """The residual of each pair (previous observation of the satellite, trapezoid Doppler),
    less the median of the other pairs' residuals of its epoch, rebuilt by plain loops."""
    rng = np.random.default_rng(1)
    t, ep, sat, phi1, _, dop = simulated(rng, n_sat=5, n_ep=40)
    keep = rng.random(len(ep)) > 0.1          # some observations missing: pairs across a gap too
    ep, sat, phi1, dop = ep[keep], sat[keep], phi1[keep], dop[keep]
    phi1 = phi1 + 1.7 * t[ep]                  # a receiver clock phase walk: common to all satellites
    cs = detect_cycle_slips(t, ep, sat, phi1, doppler=dop, doppler_sigma=0.05, max_gap=10.0)
    raw = {}
    for i in range(len(ep)):
        earlier = [j for j in range(len(ep)) if sat[j] == sat[i] and ep[j] < ep[i]]
        if not earlier:
            assert cs.previous[i] == -1 and np.isnan(cs.doppler_residual[i])
            continue
        j = max(earlier, key=lambda q: ep[q])
        assert cs.previous[i] == j
        raw[i] = phi1[i] - phi1[j] + (dop[i] + dop[j]) / 2 * (t[ep[i]] - t[ep[j]])
    for i, r in raw.items():
        others = [raw[q] for q in raw if ep[q] == ep[i] and q != i]
        want = r - np.median(others) if len(others) >= 2 else r
        assert cs.doppler_residual[i] == pytest.approx(want, abs=1e-6)


def test_loss_of_lock_and_half_cycle_rules():
    t = np.arange(6.0)
    ep = np.arange(6)
    sat = np.zeros(6, int)
    phi = np.full(6, 1e6)                      # a constant carrier: no Doppler test here
    lli = np.array([0, 1, 2, 2, 0, 0])         # lost lock at 1; half-cycle set at 2, kept at 3, cleared at 4
    cs = detect_cycle_slips(t, ep, sat, phi, lli=lli)
    assert cs.flags.tolist() == [REASONS["arc start"], REASONS["loss of lock"], REASONS["half-cycle change"], 0,
                                 REASONS["half-cycle change"], 0]
    assert cs.continuous.tolist() == [False, False, False, True, False, True]


def test_gap_and_missing_carrier():
    t = np.array([0.0, 1.0, 2.0, 4.0, 5.0, 6.0, 7.0])       # epoch 3 is 2 s after 2: a gap of the receiver
    ep = np.arange(7)
    phi = np.array([5.0, 5.0, 5.0, 5.0, np.nan, 5.0, 5.0])  # no carrier at 4: 5 continues from 3 (2 s) -> gap
    cs = detect_cycle_slips(t, ep, np.zeros(7, int), phi)
    assert cs.interval == 1.0
    assert cs.flags.tolist() == [REASONS["arc start"], 0, 0, REASONS["gap"], REASONS["no carrier"],
                                 REASONS["gap"], 0]
    assert cs.counts["G"]["gap"] == 2 and cs.counts["G"]["continuous"] == 3


def test_geometry_free_finds_a_slip_the_doppler_cannot_see_and_is_blind_to_77_60():
    rng = np.random.default_rng(7)
    t, ep, sat, phi1, phi2, dop = simulated(rng, n_sat=4, n_ep=300)
    lam1, lam2 = np.full(len(ep), LAM1), np.full(len(ep), LAM2)
    clean = detect_cycle_slips(t, ep, sat, phi1, carrier2=phi2, wavelength=lam1, wavelength2=lam2)
    assert clean.counts["G"]["geometry-free"] == 0
    # the GF jump of a slip (dn1, dn2) is lambda1 dn1 - lambda2 dn2 exactly (noise cancels in the difference)
    p1 = inject(sat, ep, phi1, [(1, 120)], [1.0])
    cs = detect_cycle_slips(t, ep, sat, p1, carrier2=phi2, wavelength=lam1, wavelength2=lam2)
    i = slip_index(ep, sat, [(1, 120)])[0]
    assert cs.gf_jump[i] - clean.gf_jump[i] == pytest.approx(LAM1, abs=1e-6)
    assert np.flatnonzero(cs.slips()).tolist() == [i]
    # 77 L1 and 60 L2 cycles: 77 lambda1 - 60 lambda2 = 1.3 mm, under the GF threshold; the Doppler sees it
    p1, p2 = inject(sat, ep, phi1, [(2, 200)], [77.0]), inject(sat, ep, phi2, [(2, 200)], [60.0])
    blind = detect_cycle_slips(t, ep, sat, p1, carrier2=p2, wavelength=lam1, wavelength2=lam2)
    assert not blind.slips().any()
    seen = detect_cycle_slips(t, ep, sat, p1, carrier2=p2, wavelength=lam1, wavelength2=lam2, doppler=dop,
                              doppler_sigma=0.05)
    assert np.flatnonzero(seen.slips()).tolist() == slip_index(ep, sat, [(2, 200)])
    assert seen.flags[seen.slips()][0] == REASONS["Doppler"]


def test_carrier_frequencies():
    f = carrier_frequency(["G", "G", "R", "R", "E", "C", "C", "C", "J"],
                          ["L1C", "L2L", "L1C", "L2C", "L7Q", "L1I", "L7I", "L1X", "L5Q"],
                          [0, 0, -7, 6, 0, 0, 0, 0, 0], version=3.02)
    assert f.tolist() == [1575.42e6, 1227.60e6, 1602e6 - 7 * 0.5625e6, 1246e6 + 6 * 0.4375e6, 1207.14e6,
                          1561.098e6, 1207.14e6, 1561.098e6, 1176.45e6]
    assert carrier_frequency(["C"], ["L1X"], version=3.04)[0] == 1575.42e6   # 3.04: band 1 X is B1C
    assert np.isnan(carrier_frequency(["R"], ["L1C"], [np.nan])[0])        # GLONASS without a channel


def test_bad_arguments():
    with pytest.raises(ArgumentError, match="twice"):
        detect_cycle_slips([0.0, 1.0], [0, 0], [3, 3], [1.0, 2.0])
    with pytest.raises(ArgumentError, match="wavelength"):
        detect_cycle_slips([0.0, 1.0], [0, 1], [3, 3], [1.0, 2.0], carrier2=[1.0, 2.0])
    with pytest.raises(ArgumentError, match="increase"):
        detect_cycle_slips([1.0, 0.0], [0, 1], [3, 3], [1.0, 2.0])


@pytest.mark.skipif(not (URBANNAV / "2020_06_03_TST_03.obs").exists(), reason="urbannav data not present")
def test_urbannav_carrier():
    """The real F9P carrier in Tsim Sha Tsui: the loss-of-lock rule finds exactly the file's
    LLI bit-0 carriers that continue a satellite's track, the Doppler sigma is the u-blox's
    (measured 0.075-0.098 cycles at 1 Hz with the epoch's common part off, 0.11-0.13 with
    it: the receiver clock's phase noise is a third of the variance), and a multipath-rich
    file has slips on every system."""
    from mixnav.gnss.multi_ephemeris import MultiEphemeris
    from mixnav.io.rinex_obs import read_rinex_obs
    systems = ("G", "R", "E", "C", "J")
    obs = read_rinex_obs(URBANNAV / "2020_06_03_TST_03.obs", systems=systems)
    second = read_rinex_obs(URBANNAV / "2020_06_03_TST_03.obs", systems=systems,
                            signals={"G": "C2L", "R": "C2C", "E": "C7Q", "C": "C7I", "J": "C2L"})
    ch = MultiEphemeris.from_rinex(sorted(URBANNAV.glob("hksc155?.20g")))["R"].channels()
    obs, second = obs.with_glonass_channels(ch), second.with_glonass_channels(ch)
    one = slips_of_observations(obs)
    cs = slips_of_observations(obs, second)
    with_clock = slips_of_observations(obs, second, common_mode=False)
    lost = (obs.lli[:, 1] & 1) != 0
    has_prev = one.previous >= 0
    assert ((one.flags & REASONS["loss of lock"]) != 0).sum() == (lost & has_prev & np.isfinite(obs.carrier)).sum()
    for s, c in cs.counts.items():
        assert 0.06 < cs.doppler_sigma[s] < 0.105 < with_clock.doppler_sigma[s] < 0.15
        assert c["Doppler"] > 0
        assert c["continuous"] + c["no carrier"] + c["arc start"] + (cs.slips()[obs.systems() == s]).sum() \
            == c["observations"]
    # the second signal can only add slips
    assert ((cs.flags & one.flags) == one.flags).all()


@pytest.mark.parametrize("n", [3, 4, 7, 8])
def test_leave_one_out_median(n):
    from mixnav.gnss.cycle_slips import _leave_one_out_median
    x = np.random.default_rng(n).standard_normal(n)
    x[1] = x[2]                                   # a tie
    np.testing.assert_array_equal(_leave_one_out_median(x), [np.median(np.delete(x, i)) for i in range(n)])


def test_without_doppler_every_pair_is_counted_untested():
    t = np.arange(5.0)
    cs = detect_cycle_slips(t, np.arange(5), np.zeros(5, int), np.full(5, 3.0))
    assert cs.counts["G"]["no Doppler check"] == 4 and cs.counts["G"]["continuous"] == 4
