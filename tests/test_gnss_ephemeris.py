"""GPS broadcast ephemeris (gnss/ephemeris.py): oracles, invariants, selection, bad files."""

import numpy as np
import pytest

from mixnav.errors import DataError
from mixnav.gnss.ephemeris import BroadcastEphemeris
from mixnav.gnss.geometry import C_LIGHT, GM_GPS, OMEGA_E_GPS

from .conftest import data_file

NAV = ("android-static", "hour1820.16n")
WEEK, TOW = 1903, 410400.0 + 1234.5

# Independent reference: gnss-lib-py 1.1.0 (`sv_models.find_sv_states` on its own
# RINEX parser), run once in a separate environment (it pins pandas < 3, so it is
# not a test dependency), for hour1820.16n, the records with toe = 410400 s of
# week 1903, at week 1903, tow 411634.5 s. Columns: x, y, z [m], vx, vy, vz [m/s],
# c * (satellite clock incl. relativistic term, minus TGD) [m].
GLP_REFERENCE = {
    28: [-3909963.478936448, -14354130.696535619, 22631673.98133321,
         2615.5125602718026, -721.9488828917105, -10.239752821615252, 160060.91105999838],
    32: [14899327.686407056, 20253923.053862564, 8598271.537168989,
         -1004.7081171514112, -496.5363039033425, 2913.148896949308, -10978.208609292746],
    31: [9086889.032137755, 16870242.215164203, -18131763.449745998,
         -643.4933603633067, 2249.040970317226, 1795.4270711261793, 78328.01540456896],
    2: [-14562335.90977839, -5871877.3378987, -21012224.325100023,
        412.0665106092014, -2744.573389097807, 433.3165181920923, 174221.82908931293],
    16: [24737238.679663382, 28189.16627711989, -10290161.84972356,
         -1190.0173956567694, 474.96549930830133, -2852.1464511882873, -2265.761794926988],
}


@pytest.fixture(scope="module")
def eph():
    return BroadcastEphemeris.from_rinex(data_file(*NAV))


def test_positions_agree_with_gnss_lib_py(eph):
    prns = np.array(sorted(GLP_REFERENCE))
    s, skips = eph.states_and_skips(WEEK, TOW, prns)
    assert len(skips) == 0 and np.array_equal(s.prn, prns)
    ref = np.array([GLP_REFERENCE[p] for p in prns])
    # gnss-lib-py evaluates the harmonic corrections at the corrected argument of
    # latitude (IS-GPS-200 uses the uncorrected one): a few mm. Tolerance 1 cm.
    assert np.abs(s.pos_ecef - ref[:, :3]).max() < 0.01
    assert np.abs(s.vel_ecef - ref[:, 3:6]).max() < 1e-3
    assert np.abs(C_LIGHT * s.clock_bias - ref[:, 6]).max() < 1e-3


def test_velocity_and_drift_are_derivatives(eph):
    h = 0.5
    s0 = eph.states(WEEK, TOW)
    sm, sp = eph.states(WEEK, TOW - h, s0.prn), eph.states(WEEK, TOW + h, s0.prn)
    fd_vel = (sp.pos_ecef - sm.pos_ecef) / (2 * h)
    assert np.abs(s0.vel_ecef - fd_vel).max() < 1e-3          # 1 mm/s
    fd_drift = (sp.clock_bias - sm.clock_bias) / (2 * h)
    assert np.abs(s0.clock_drift - fd_drift).max() * C_LIGHT < 1e-4


def test_orbit_radius_and_energy(eph):
    s = eph.states(WEEK, TOW)
    assert len(s) >= 28
    r = np.linalg.norm(s.pos_ecef, axis=1)
    assert np.all((r > 25.9e6) & (r < 27.2e6))              # GPS: A = 26560 km, e < 0.03
    v_i = s.vel_ecef + np.cross([0, 0, OMEGA_E_GPS], s.pos_ecef)   # inertial velocity
    idx, _, _ = eph._select(WEEK, TOW, s.prn)
    a = eph.rec["sqrt_a"][idx] ** 2
    energy = 0.5 * np.sum(v_i**2, axis=1) - GM_GPS / r
    # vis-viva: energy = -GM / (2 A); J2 perturbs the osculating energy by
    # ~ J2 (R_e / r)^2 ~ 7e-5 relative
    assert np.abs(energy / (-GM_GPS / (2 * a)) - 1).max() < 3e-4


def _record(**over):
    rec = dict(prn=[5], af0=[1e-4], af1=[0.0], af2=[0.0], crs=[0.0], delta_n=[0.0], m0=[0.3], cuc=[0.0],
               e=[0.0], cus=[0.0], sqrt_a=[5153.7], toe=[345600.0], cic=[0.0], omega0=[1.1], cis=[0.0],
               i0=[0.95], crc=[0.0], omega=[0.4], omega_dot=[0.0], idot=[0.0], week=[1903], health=[0],
               tgd=[5e-9], toc_week=[1903], toc=[345600.0])
    rec.update(over)
    return {k: np.asarray(v, float if k not in ("prn", "health") else int) for k, v in rec.items()}


def test_circular_orbit_closed_form():
    eph = BroadcastEphemeris(_record())
    tk = 1000.0
    s = eph.states(1903, 345600.0 + tk, [5], apply_tgd=False)
    a = 5153.7**2
    n = np.sqrt(GM_GPS / a**3)
    u = 0.3 + n * tk + 0.4
    big_omega = 1.1 - OMEGA_E_GPS * (345600.0 + tk)
    rz = np.array([[np.cos(big_omega), -np.sin(big_omega), 0], [np.sin(big_omega), np.cos(big_omega), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(0.95), -np.sin(0.95)], [0, np.sin(0.95), np.cos(0.95)]])
    expected = rz @ rx @ (a * np.array([np.cos(u), np.sin(u), 0.0]))
    assert np.abs(s.pos_ecef[0] - expected).max() < 1e-6
    assert s.clock_bias[0] == pytest.approx(1e-4, abs=1e-18)    # e = 0: no relativistic term
    assert eph.states(1903, 345600.0 + tk, [5]).clock_bias[0] == pytest.approx(1e-4 - 5e-9, abs=1e-18)


def test_kepler_and_relativistic_term_eccentric():
    e, m0 = 0.02, 0.7
    eph = BroadcastEphemeris(_record(e=[e], m0=[m0]))
    s = eph.states(1903, 345600.0, [5], apply_tgd=False)
    # at toe: M = m0; solve Kepler independently by bisection
    lo, hi = 0.0, np.pi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid - e * np.sin(mid) < m0 else (lo, mid)
    big_e = 0.5 * (lo + hi)
    r = np.linalg.norm(s.pos_ecef[0])
    assert r == pytest.approx(5153.7**2 * (1 - e * np.cos(big_e)), abs=1e-6)
    rel = -4.442807633e-10 * e * 5153.7 * np.sin(big_e)
    assert s.clock_bias[0] == pytest.approx(1e-4 + rel, abs=1e-16)


def test_nearest_toe_stale_unhealthy_and_missing():
    rec = _record(prn=[5, 5, 7, 9], af0=[1.0, 2.0, 3.0, 4.0], toe=[345600.0, 352800.0, 345600.0, 345600.0],
                  toc=[345600.0, 352800.0, 345600.0, 345600.0], health=[0, 0, 0, 63],
                  **{k: [v] * 4 for k, v in dict(af1=0.0, af2=0.0, crs=0.0, delta_n=0.0, m0=0.3, cuc=0.0, e=0.0,
                                                 cus=0.0, sqrt_a=5153.7, cic=0.0, omega0=1.1, cis=0.0,
                                                 i0=0.95, crc=0.0, omega=0.4, omega_dot=0.0, idot=0.0,
                                                 week=1903, tgd=0.0, toc_week=1903).items()})
    eph = BroadcastEphemeris(rec, max_age=7200.0)
    s, skips = eph.states_and_skips(1903, 345600.0 + 3000.0, [5, 7, 9, 11])
    assert list(s.prn) == [5, 7] and s.clock_bias[0] == pytest.approx(1.0)
    assert dict(zip(skips.prn.tolist(), skips.reason)) == {9: "unhealthy", 11: "no ephemeris"}
    s = eph.states(1903, 345600.0 + 4000.0, [5])
    assert s.clock_bias[0] == pytest.approx(2.0)                # the nearer toe
    s, skips = eph.states_and_skips(1903, 345600.0 + 7300.0, [7])
    assert len(s) == 0 and skips.reason == ("stale ephemeris",) and skips.counts() == {"stale ephemeris": 1}
    # per-satellite times
    s = eph.states(1903, np.array([345600.0 + 3000.0, 345600.0 + 4000.0]), [5, 5])
    assert s.clock_bias.tolist() == pytest.approx([1.0, 2.0])


def test_real_file_header(eph):
    assert eph.iono_alpha is not None and eph.iono_alpha[0] == pytest.approx(0.4657e-08)
    assert eph.iono_beta[3] == pytest.approx(-0.5243e06)
    s, skips = eph.states_and_skips(WEEK, TOW)
    assert set(skips.prn.tolist()) == {4}                          # G04 is flagged unhealthy all day
    assert skips.reason == ("unhealthy",)


# ---------------------------------------------------------------- bad input
def test_missing_file(tmp_path):
    with pytest.raises(DataError, match="not found") as ei:
        BroadcastEphemeris.from_rinex(tmp_path / "nope.16n")
    assert "nope.16n" in str(ei.value)


def test_random_text(tmp_path):
    f = tmp_path / "random.16n"
    f.write_text("hello world\nthis is not rinex\n")
    with pytest.raises(DataError, match="not a RINEX file") as ei:
        BroadcastEphemeris.from_rinex(f)
    assert "random.16n" in str(ei.value)


def test_empty_file(tmp_path):
    f = tmp_path / "empty.16n"
    f.write_text("")
    with pytest.raises(DataError, match="empty"):
        BroadcastEphemeris.from_rinex(f)


def test_observation_file(tmp_path):
    f = tmp_path / "obs.16o"
    f.write_text("     2.11           OBSERVATION DATA    G (GPS)             RINEX VERSION / TYPE\n"
                 "                                                            END OF HEADER\n")
    with pytest.raises(DataError, match="not a GPS navigation file") as ei:
        BroadcastEphemeris.from_rinex(f)
    assert "obs.16o" in str(ei.value)


def test_garbage_after_header(tmp_path):
    lines = data_file(*NAV).read_text().splitlines(keepends=True)
    f = tmp_path / "garbage.16n"
    f.write_text("".join(lines[:8]) + " 1 16  6 30  0  0  0.0 abcdefghijklmnopqrstuvwxyz\n   xx\n")
    with pytest.raises(DataError) as ei:
        BroadcastEphemeris.from_rinex(f)
    assert "garbage.16n" in str(ei.value)


def test_truncated_file(tmp_path):
    text = data_file(*NAV).read_bytes()[:5000]
    f = tmp_path / "trunc.16n"
    f.write_bytes(text)
    with pytest.raises(DataError, match="truncated") as ei:
        BroadcastEphemeris.from_rinex(f)
    assert "trunc.16n" in str(ei.value)


def test_header_only(tmp_path):
    lines = data_file(*NAV).read_text().splitlines(keepends=True)
    f = tmp_path / "header.16n"
    f.write_text("".join(lines[:8]))
    with pytest.raises(DataError, match="no complete GPS ephemeris"):
        BroadcastEphemeris.from_rinex(f)
