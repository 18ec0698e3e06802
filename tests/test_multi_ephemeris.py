"""Broadcast orbits of every system (gnss/orbits.py, gnss/multi_ephemeris.py, gnss/gnss_time.py).

Oracles: RTKLIB's eph2pos / geph2pos (pins made by
benchmarks/reference/make_rtklib_orbit_pins.py), the GPS kernel as it was
before this change (tests/reference/gps_kepler_2aa3c56.py), and closed-form
identities.
"""

from pathlib import Path

import numpy as np
import pytest

from mixnav.errors import ArgumentError, DataError
from mixnav.gnss import gnss_time, orbits
from mixnav.gnss.ephemeris import BroadcastEphemeris
from mixnav.gnss.geometry import C_LIGHT, SECONDS_PER_WEEK
from mixnav.gnss.multi_ephemeris import NO_SYSTEM_DATA, KeplerEphemeris, MultiEphemeris

from .conftest import data_file
from .reference.gps_kepler_2aa3c56 import old_compute

HERE = Path(__file__).resolve().parent
PINS = HERE / "data" / "rtklib_orbit_pins.txt"
QZSS = HERE / "data" / "qzss_synthetic.rnx"
NAV = [f"hksc155{h}.20{s}" for h in "cd" for s in "nglb"]
WEEK = 2108
TOW0 = 3 * 86400.0 + 3 * 3600.0 + 2 * 60 + 27.0          # first epoch of the urbannav observation file


def _nav(name):
    return data_file("urbannav-tst-static", name)


@pytest.fixture(scope="module")
def multi():
    return MultiEphemeris.from_rinex([_nav(n) for n in NAV] + [QZSS])


def _pins():
    rows = [ln.split() for ln in PINS.read_text().splitlines() if not ln.startswith("#")]
    return {
        "sat": np.array([r[0] for r in rows]),
        "t": np.array([int(r[1]) * SECONDS_PER_WEEK + float(r[2]) for r in rows]),
        "toe": np.array([int(r[3]) * SECONDS_PER_WEEK + float(r[4]) for r in rows]),
        "code": np.array([int(r[5]) for r in rows]),
        "k": np.array([int(r[6]) for r in rows]),
        "pos": np.array([[float(x) for x in r[7:10]] for r in rows]),
        "clk": np.array([float(r[10]) for r in rows]),
    }


def _ref_time_gpst(eph):
    """Each record's reference time (toe / t_b) in continuous GPS seconds."""
    t = eph.rec["week"] * SECONDS_PER_WEEK + eph.rec["toe"]
    return gnss_time.bdt_to_gpst(t) if eph.system == "C" else t


def _rtklib_rows(multi, system):
    """RTKLIB's rows of one system and mixnav's states from the same records, same times."""
    p = _pins()
    rows = np.flatnonzero(np.char.startswith(p["sat"], system))
    eph = multi[system]
    ref = _ref_time_gpst(eph)
    idx = []
    for i in rows:
        m = (eph.rec["prn"] == int(p["sat"][i][1:])) & (np.abs(ref - p["toe"][i]) < 1e-3)
        if system == "E":
            m &= eph.rec["data_source"] == p["code"][i]
        hits = np.flatnonzero(m)
        assert len(hits) >= 1, f"{p['sat'][i]}: no record with RTKLIB's toe {p['toe'][i]}"
        idx.append(hits[0])
    idx = np.array(idx)
    pos, vel, clk, drift = eph._compute(idx, eph._system_time(p["t"][rows]), False)
    return p, rows, pos, clk, idx


@pytest.mark.parametrize("system", ["G", "R", "E", "C", "J"])
def test_orbits_and_clocks_agree_with_rtklib(multi, system):
    p, rows, pos, clk, _ = _rtklib_rows(multi, system)
    assert len(rows) >= 20
    dpos = np.linalg.norm(pos - p["pos"][rows], axis=1)
    dclk = np.abs(clk - p["clk"][rows])
    # RTKLIB prints positions to 0.1 mm; its GLONASS GM (3.9860044e14, ICD 5.0) differs from
    # ICD 5.1's 3.986004418e14 used here: about a millimetre over 15 min
    assert dpos.max() < 0.01, f"{system}: worst {p['sat'][rows][np.argmax(dpos)]} {dpos.max():.4f} m"
    assert dclk.max() < 0.1e-9, f"{system}: worst clock {dclk.max() * 1e9:.4f} ns"


def test_beidou_geo_covered_by_the_rtklib_pins(multi):
    p, rows, pos, _, _ = _rtklib_rows(multi, "C")
    geo = np.isin([int(s[1:]) for s in p["sat"][rows]], [1, 2, 3, 4, 5])
    assert geo.sum() >= 40
    assert np.linalg.norm(pos[geo] - p["pos"][rows][geo], axis=1).max() < 0.01
    # the GEO rotation matters: without it the positions are kilometres off
    eph = multi["C"]
    idx = np.flatnonzero(eph._geo)[:3]
    t = eph.rec["week"][idx] * SECONDS_PER_WEEK + eph.rec["toe"][idx] + 600.0
    r = {k: v[idx] for k, v in eph.rec.items()}
    with_geo = orbits.kepler_states(r, t, orbits.BEIDOU, geo=np.ones(3, bool))[0]
    as_meo = orbits.kepler_states(r, t, orbits.BEIDOU)[0]
    assert np.linalg.norm(with_geo - as_meo, axis=1).min() > 1e5


def test_glonass_with_rtklibs_constants_and_step_agrees_to_the_printed_digits(multi):
    """The GLONASS millimetres are ICD 5.1's constants against RTKLIB's ICD 5.0 ones (and its step)."""
    p, rows, _, _, idx = _rtklib_rows(multi, "R")
    eph = multi["R"]
    r = {k: v[idx] for k, v in eph.rec.items()}
    r["tb"] = r["week"] * SECONDS_PER_WEEK + r["toe"]
    icd50 = orbits.GlonassConstants(3.9860044e14, 6378136.0, 1.0826257e-3, 7.292115e-5)
    pos = orbits.glonass_states(r, p["t"][rows], 60.0, icd50)[0]
    assert np.linalg.norm(pos - p["pos"][rows], axis=1).max() < 5e-4


def test_public_selection_agrees_with_rtklib(multi):
    """states_of (nearest healthy record in date) gives RTKLIB's numbers where both choose a record."""
    p = _pins()
    w, tow = gnss_time.gpst_week_tow(p["t"])
    st, systems, keep, skips = multi.states_of(p["sat"], w, tow, apply_group_delay=False)
    assert keep.sum() >= 0.9 * len(keep)
    d = np.linalg.norm(st.pos_ecef - p["pos"][keep], axis=1)
    assert d.max() < 0.01
    assert np.abs(st.clock_bias - p["clk"][keep]).max() < 0.1e-9
    assert list(systems[:3]) == [s[0] for s in p["sat"][keep][:3]]


def test_glonass_channels_agree_with_rtklib(multi):
    p = _pins()
    rows = np.flatnonzero(np.char.startswith(p["sat"], "R"))
    prns = np.array([int(s[1:]) for s in p["sat"][rows]])
    assert np.array_equal(multi.glonass_channel(prns), p["k"][rows])
    with pytest.raises(DataError, match="R25"):
        multi.glonass_channel([1, 25])


# ---------------------------------------------------------------- GPS unchanged

def test_gps_kernel_bitwise_as_before():
    for path in (_nav("hksc155c.20n"), data_file("android-static", "hour1820.16n")):
        eph = BroadcastEphemeris.from_rinex(path)
        idx = np.repeat(np.arange(len(eph)), 5)
        t = (eph.rec["week"] * SECONDS_PER_WEEK + eph.rec["toe"])[idx] + np.tile([-7000, -60.5, 0, 33.3, 7100], len(eph))
        for tgd in (True, False):
            new = eph._compute(idx, t, tgd)
            old = old_compute(eph.rec, idx, t, tgd)
            for a, b in zip(new, old):
                assert np.array_equal(a, b)


def test_multi_gps_bitwise_as_broadcast_ephemeris():
    for path, week, tows in ((_nav("hksc155c.20n"), WEEK, TOW0 + np.arange(0, 986, 7.0)),
                             (data_file("android-static", "hour1820.16n"), 1903, 411634.5 + np.arange(0, 223, 5.0))):
        old = BroadcastEphemeris.from_rinex(path)
        new = MultiEphemeris.from_rinex(path)
        for tow in tows:
            a, ska = old.states_and_skips(week, tow)
            b, skb = new.states_and_skips("G", None, week, tow)
            assert np.array_equal(a.prn, b.prn) and np.array_equal(ska.prn, skb.prn)
            for f in ("pos_ecef", "vel_ecef", "clock_bias", "clock_drift"):
                assert np.array_equal(getattr(a, f), getattr(b, f))


# ---------------------------------------------------------------- closed-form checks

def _records(eph, n=6):
    idx = np.arange(min(n, len(eph)))
    r = {k: v[idx] for k, v in eph.rec.items()}
    t = r["week"] * SECONDS_PER_WEEK + r["toe"] + np.linspace(-3000.0, 3000.0, len(idx))
    return r, t


def test_qzss_constants_are_gps_ones(multi):
    r, t = _records(multi["J"])
    for a, b in zip(orbits.kepler_states(r, t, orbits.QZSS), orbits.kepler_states(r, t, orbits.GPS)):
        assert np.array_equal(a, b)


def test_galileo_with_gps_gm_is_a_mean_motion_shift(multi):
    """GM enters only through n0 = sqrt(GM / A^3) (and F): swapping GM equals shifting delta_n."""
    r, t = _records(multi["E"])
    gps_gm = orbits.KeplerConstants(orbits.GPS.gm, orbits.GALILEO.omega_e, orbits.GALILEO.f_rel)
    p_gps = orbits.kepler_states(r, t, gps_gm)[0]
    p_gal = orbits.kepler_states(r, t, orbits.GALILEO)[0]
    A = r["sqrt_a"] ** 2
    shifted = dict(r, delta_n=r["delta_n"] + np.sqrt(orbits.GPS.gm / A**3) - np.sqrt(orbits.GALILEO.gm / A**3))
    assert np.abs(orbits.kepler_states(shifted, t, orbits.GALILEO)[0] - p_gps).max() < 1e-6
    # along-track: |dM| * a, with dM = dn0 * tk (about 0.9 m an hour at Galileo's altitude)
    tk = t - (r["week"] * SECONDS_PER_WEEK + r["toe"])
    dm = (np.sqrt(orbits.GPS.gm / A**3) - np.sqrt(orbits.GALILEO.gm / A**3)) * tk
    d = np.linalg.norm(p_gps - p_gal, axis=1)
    assert np.allclose(d, np.abs(dm) * A, rtol=0.05, atol=1e-6)
    assert abs(orbits.GALILEO.f_rel / orbits.GPS.f_rel - np.sqrt(orbits.GALILEO.gm / orbits.GPS.gm)) < 1e-9


def test_beidou_with_gps_earth_rate_is_a_rotation(multi):
    """Omega_e enters MEO/IGSO orbits as -Omega_e (tk + toe) in the node: a rotation about z."""
    eph = multi["C"]
    idx = np.flatnonzero(~eph._geo)[:6]
    r = {k: v[idx] for k, v in eph.rec.items()}
    t = r["week"] * SECONDS_PER_WEEK + r["toe"] + np.linspace(-3000.0, 3000.0, len(idx))
    other = orbits.KeplerConstants(orbits.BEIDOU.gm, orbits.GPS.omega_e, orbits.BEIDOU.f_rel)
    p_bds = orbits.kepler_states(r, t, orbits.BEIDOU)[0]
    p_oth = orbits.kepler_states(r, t, other)[0]
    tk = t - (r["week"] * SECONDS_PER_WEEK + r["toe"])
    a = -(orbits.GPS.omega_e - orbits.BEIDOU.omega_e) * (tk + r["toe"])
    rot = np.stack([p_bds[:, 0] * np.cos(a) - p_bds[:, 1] * np.sin(a),
                    p_bds[:, 0] * np.sin(a) + p_bds[:, 1] * np.cos(a), p_bds[:, 2]], -1)
    assert np.abs(rot - p_oth).max() < 1e-6
    assert np.abs(p_bds - p_oth).max() > 0.1            # and the difference is not nothing


def test_beidou_geo_rotation_orthonormal():
    ang = np.linspace(-0.5, 0.5, 7)
    R, dR = orbits.beidou_geo_rotation(ang)
    assert np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() < 1e-15
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-15)
    h = 1e-6
    fd = (orbits.beidou_geo_rotation(ang + h)[0] - orbits.beidou_geo_rotation(ang - h)[0]) / (2 * h)
    assert np.abs(fd - dR).max() < 1e-9
    # zero angle: R_X(-5 deg) alone
    R0 = orbits.beidou_geo_rotation(np.zeros(1))[0][0]
    assert np.isclose(R0[1, 2], np.sin(np.deg2rad(-5.0))) and np.isclose(R0[2, 1], -np.sin(np.deg2rad(-5.0)))


def test_glonass_step_halving_below_a_tenth_of_a_millimetre(multi):
    eph = multi["R"]
    idx = np.repeat(np.arange(len(eph)), 4)
    r = {k: v[idx] for k, v in eph.rec.items()}
    r["tb"] = r["week"] * SECONDS_PER_WEEK + r["toe"]
    t = r["tb"] + np.tile([-1800.0, -900.0, 417.3, 1800.0], len(eph))
    p60 = orbits.glonass_states(r, t, 60.0)[0]
    p30, v30 = orbits.glonass_states(r, t, 30.0)[:2]           # the default step
    p15, v15 = orbits.glonass_states(r, t, 15.0)[:2]
    assert np.linalg.norm(p30 - p15, axis=1).max() < 1e-4
    assert np.linalg.norm(v30 - v15, axis=1).max() < 1e-7
    # the ICD's 60 s: within a millimetre while |t - tb| <= 15 min, 1-2 mm at 30 min
    near = np.abs(t - r["tb"]) <= 900.0
    assert np.linalg.norm(p60 - p30, axis=1)[near].max() < 1e-3
    assert np.linalg.norm(p60 - p30, axis=1).max() < 2e-3
    # a zero-length integration returns the broadcast state
    p0, v0 = orbits.glonass_states(r, r["tb"])[:2]
    assert np.array_equal(p0, r["pos"]) and np.array_equal(v0, r["vel"])


@pytest.mark.parametrize("system", ["G", "R", "E", "C", "J"])
def test_velocity_and_drift_are_derivatives(multi, system):
    eph = multi[system]
    s0 = multi.states(system, None, WEEK, TOW0 + 300.0)
    assert len(s0) >= 2
    h = 0.5
    sm = multi.states(system, s0.prn, WEEK, TOW0 + 300.0 - h)
    sp = multi.states(system, s0.prn, WEEK, TOW0 + 300.0 + h)
    assert np.abs(s0.vel_ecef - (sp.pos_ecef - sm.pos_ecef) / (2 * h)).max() < 1e-3
    assert C_LIGHT * np.abs(s0.clock_drift - (sp.clock_bias - sm.clock_bias) / (2 * h)).max() < 1e-4
    assert eph.system == system


def test_group_delays(multi):
    """T_GD (G, J), BGD(E1,E5b) (E, I/NAV), T_GD1 (C) are subtracted; GLONASS has none."""
    for system, field in (("G", "tgd"), ("J", "tgd"), ("E", "bgd_e5b"), ("C", "tgd")):
        eph = multi[system]
        s1, s0 = (multi.states(system, None, WEEK, TOW0 + 60.0, apply_group_delay=g) for g in (True, False))
        idx, _, _ = eph._select(WEEK, TOW0 + 60.0, s0.prn)
        assert np.array_equal(s0.clock_bias - s1.clock_bias, eph.rec[field][idx]) or \
            np.allclose(s0.clock_bias - s1.clock_bias, eph.rec[field][idx], rtol=0, atol=1e-20)
    s1, s0 = (multi.states("R", None, WEEK, TOW0, apply_group_delay=g) for g in (True, False))
    assert np.array_equal(s1.clock_bias, s0.clock_bias)


def test_galileo_fnav_uses_bgd_e1_e5a():
    paths = [_nav("hksc155c.20l"), _nav("hksc155d.20l")]
    inav = MultiEphemeris.from_rinex(paths)
    fnav = MultiEphemeris.from_rinex(paths, galileo_nav="fnav")
    assert set(np.unique(inav["E"].rec["data_source"])) == {517}
    assert set(np.unique(fnav["E"].rec["data_source"])) == {258}
    assert np.array_equal(fnav["E"].rec["tgd"], fnav["E"].rec["bgd_e5a"])
    assert inav.dropped == {"Galileo F/NAV records": len(fnav["E"])}
    with pytest.raises(ArgumentError, match="galileo_nav"):
        MultiEphemeris.from_rinex(paths, galileo_nav="cnav")


# ---------------------------------------------------------------- time

def test_time_conversions_round_trip():
    t = np.array([1.0, 1356 * SECONDS_PER_WEEK + 13.0, 2108 * SECONDS_PER_WEEK + 270147.004, 1.5e9])
    assert np.array_equal(gnss_time.bdt_to_gpst(gnss_time.gpst_to_bdt(t)), t)
    assert np.allclose(gnss_time.glonasst_to_gpst(gnss_time.gpst_to_glonasst(t, 18.0), 18.0), t, rtol=0, atol=1e-6)
    assert np.array_equal(gnss_time.utc_to_gpst(gnss_time.gpst_to_utc(t, 18.0), 18.0), t)
    w, s = gnss_time.gpst_week_tow(t)
    assert np.allclose(gnss_time.gpst_seconds(w, s), t, rtol=0, atol=1e-6)
    # BDT week and seconds; the first 14 s of a GPS week belong to the previous BDT week
    bw, bs = gnss_time.gps_week_tow_to_bdt(np.array([2108, 2108]), np.array([270014.0, 5.0]))
    assert list(bw) == [752, 751] and list(bs) == [270000.0, SECONDS_PER_WEEK - 9.0]
    # GLONASST = UTC + 3 h: 03:00:00 GPST on 2020-06-03 is 05:59:42 GLONASST
    t_gps = 2108 * SECONDS_PER_WEEK + 3 * 86400 + 3 * 3600.0
    assert gnss_time.gpst_to_glonasst(t_gps, 18.0) - (2108 * SECONDS_PER_WEEK + 3 * 86400) == 6 * 3600 - 18


def test_leap_second_table():
    def at(date):
        return float(gnss_time.leap_seconds((np.datetime64(date, "s") - np.datetime64("1980-01-06", "s"))
                                            / np.timedelta64(1, "s")))
    assert at("1980-06-01") == 0 and at("1981-07-01") == 1
    assert at("2016-12-31T23:59:59") == 17 and at("2017-01-01") == 18 and at("2020-06-03") == 18


def test_leap_seconds_from_header_not_from_beidou(multi):
    assert multi.leap_seconds == 18.0 and multi.leap_seconds_source.endswith("hksc155c.20n")
    only_bds = MultiEphemeris.from_rinex(_nav("hksc155c.20b"))   # its header says 4 (BDT - UTC)
    assert only_bds.leap_seconds == 18.0 and only_bds.leap_seconds_source == "table"
    glo = MultiEphemeris.from_rinex(_nav("hksc155c.20g"), leap_seconds=17)
    ref = MultiEphemeris.from_rinex(_nav("hksc155c.20g"))
    assert np.array_equal(ref["R"].rec["toe"] - glo["R"].rec["toe"], np.ones(len(glo["R"])))


# ---------------------------------------------------------------- files and errors

def _rinex2_glonass(src: Path, dst: Path):
    """The records of a RINEX 3 GLONASS file rewritten as RINEX 2.11 (same values)."""
    lines = src.read_text().splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    out = ["     2.11           G: GLONASS NAV DATA                     RINEX VERSION / TYPE",
           "    18                                                      LEAP SECONDS",
           "                                                            END OF HEADER"]
    for ln in lines[end + 1:]:
        if ln[:1] == "R":
            y, mo, d, h, mi, s = (int(x) for x in ln[4:23].split())
            out.append(f"{int(ln[1:3]):2d} {y % 100:02d}{mo:3d}{d:3d}{h:3d}{mi:3d}{s:5.1f}" + ln[23:80])
        elif ln.strip():
            out.append("   " + ln[4:80])
    dst.write_text("\n".join(out) + "\n")


def test_rinex2_glonass_equals_rinex3(tmp_path):
    src = _nav("hksc155c.20g")
    _rinex2_glonass(src, tmp_path / "hksc155c.20g")
    a = MultiEphemeris.from_rinex(src)
    b = MultiEphemeris.from_rinex(tmp_path / "hksc155c.20g")
    for k in a["R"].rec:
        assert np.array_equal(a["R"].rec[k], b["R"].rec[k]), k


def test_rinex2_galileo_and_qzss_with_rinex3_style_records(tmp_path, multi):
    """RINEX 2.12 'L' (Galileo) and RTKLIB's 'J' (QZSS) files write RINEX 3 style records."""
    for src, ftype, system in ((_nav("hksc155c.20l"), "L: GALILEO NAV DATA", "E"),
                               (QZSS, "J: QZSS NAV DATA    ", "J")):
        lines = src.read_text().splitlines()
        end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
        dst = tmp_path / f"v2_{system}.nav"
        dst.write_text("\n".join([f"     2.12           {ftype:<40}RINEX VERSION / TYPE",
                                   "                                                            END OF HEADER"]
                                  + lines[end + 1:]) + "\n")
        a = MultiEphemeris.from_rinex(src)[system]
        b = MultiEphemeris.from_rinex(dst)[system]
        for k in a.rec:
            assert np.array_equal(a.rec[k], b.rec[k]), k


def test_mixed_rinex3_equals_per_system_files(tmp_path):
    body = []
    for name in NAV[:4]:
        lines = _nav(name).read_text().splitlines()
        end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
        body += lines[end + 1:]
    mixed = tmp_path / "mixed.rnx"
    mixed.write_text("\n".join(["     3.02           N: GNSS NAV DATA    M: Mixed            RINEX VERSION / TYPE",
                                "    18                                                      LEAP SECONDS",
                                "                                                            END OF HEADER"]
                               + body) + "\n")
    m = MultiEphemeris.from_rinex(mixed)
    per = MultiEphemeris.from_rinex([_nav(n) for n in NAV[:4]])
    assert m.summary() == per.summary() and m.summary()["QZSS"] == 0
    for s in "GREC":
        a = m.states(s, None, WEEK, TOW0)
        b = per.states(s, None, WEEK, TOW0)
        assert len(a) >= 4 and np.array_equal(a.pos_ecef, b.pos_ecef) and np.array_equal(a.clock_bias, b.clock_bias)


def test_system_without_navigation_data_is_counted_not_raised():
    m = MultiEphemeris.from_rinex([_nav("hksc155c.20n"), _nav("hksc155c.20l")])
    st, systems, keep, skips = m.states_of(["G01", "R12", "C08", "C09", "J01", "E13"], WEEK, TOW0)
    assert set(systems) <= {"G", "E"}
    counts = m.skip_counts(skips)
    assert counts["GLONASS"] == {NO_SYSTEM_DATA: 1} and counts["BeiDou"] == {NO_SYSTEM_DATA: 2}
    assert counts["QZSS"] == {NO_SYSTEM_DATA: 1}
    s, sk = m.states_and_skips("R", [1, 2], WEEK, TOW0)
    assert len(s) == 0 and sk.counts() == {NO_SYSTEM_DATA: 2}
    assert m.summary()["BeiDou"] == 0
    with pytest.raises(DataError, match="no GLONASS frequency channel number for R01"):
        m.glonass_channel(1)
    with pytest.raises(ArgumentError, match="unknown satellite system"):
        m.states("X", [1], WEEK, TOW0)


def test_unreadable_files_name_the_file(tmp_path):
    with pytest.raises(DataError, match="not found"):
        MultiEphemeris.from_rinex(tmp_path / "absent.20n")
    bad = tmp_path / "garbage.20n"
    bad.write_text("hello\n")
    with pytest.raises(DataError, match="garbage.20n"):
        MultiEphemeris.from_rinex(bad)
    obs = tmp_path / "obs.20o"
    obs.write_text("     3.02           OBSERVATION DATA    M: Mixed            RINEX VERSION / TYPE\n")
    with pytest.raises(DataError, match="not a navigation file"):
        MultiEphemeris.from_rinex(obs)
    # a record cut short: named by satellite and line
    lines = _nav("hksc155c.20b").read_text().splitlines()
    cut = tmp_path / "cut.20b"
    cut.write_text("\n".join(lines[:7 + 8 + 3]) + "\n")
    with pytest.raises(DataError, match=r"C02 .*missing") as e:
        MultiEphemeris.from_rinex(cut)
    assert e.value.line == 16 and "cut.20b" in str(e.value)
    # an unreadable number
    lines[9] = lines[9][:30] + "x" + lines[9][31:]
    broken = tmp_path / "broken.20b"
    broken.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match="broken.20b") as e:
        MultiEphemeris.from_rinex(broken)
    assert e.value.line == 8


def test_kepler_ephemeris_is_a_broadcast_ephemeris(multi):
    """Each system works where a BroadcastEphemeris does (e.g. spp.satellites_at_transmit)."""
    from mixnav.gnss.spp import satellites_at_transmit
    eph = multi["C"]
    assert isinstance(eph, KeplerEphemeris) and isinstance(eph, BroadcastEphemeris)
    prn = np.array([7, 8, 99])
    st, keep, skips = satellites_at_transmit(eph, prn, np.full(3, 3.8e7), WEEK, TOW0)
    assert list(keep) == [True, True, False] and skips.counts() == {"no ephemeris": 1}
