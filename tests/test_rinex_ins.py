"""IMU + RINEX datasets through the tight INS: RINEX writers, the simulator's export and the
round trip back through ``mixnav process`` (experiment/rinex_ins.py, experiment/export.py)."""

import math
import re

import numpy as np
import pytest

from mixnav.config.loader import load_dataset, load_scenario, resolve
from mixnav.errors import ArgumentError, ConfigError, DataError
from mixnav.experiment import methods
from mixnav.experiment.export import export_dataset, gps_seconds
from mixnav.experiment.process import process
from mixnav.geodesy.frames import ned_displacement
from mixnav.gnss.constellation import NominalConstellation
from mixnav.gnss.ephemeris import BroadcastEphemeris
from mixnav.gnss.geometry import SECONDS_PER_WEEK
from mixnav.ins.error_model import ClockModel
from mixnav.io.rinex_obs import read_rinex_obs
from mixnav.io.rinex_write import write_rinex_nav, write_rinex_obs

# ------------------------------------------------------------------ writers


def test_nav_file_gives_the_constellation_positions():
    """Satellites from the written navigation file (georinex + IS-GPS-200 orbit) equal the
    nominal constellation's to < 1 cm (D19.12 keeps 13 digits: ~0.1 mm of a 26 560 km
    orbit), over 3 h that cross a GPS week roll-over (records in both weeks), with the
    Klobuchar coefficients read back from the header."""
    const = NominalConstellation.gps(5)
    t0 = 2305 * SECONDS_PER_WEEK - 5400.0 + 0.0      # 1.5 h before the week ends
    toe = np.arange(np.floor(t0 / 7200.0), np.ceil((t0 + 3 * 3600.0) / 7200.0) + 1) * 7200.0
    alpha, beta = [1.1e-8, 7.5e-9, -6.0e-8, -6.0e-8], [9.0e4, 4.9e4, -1.3e5, -2.6e5]
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "nav.rnx"
        write_rinex_nav(path, const.broadcast_records(t0, toe), iono_alpha=alpha, iono_beta=beta)
        eph = BroadcastEphemeris.from_rinex(path)
    assert len(eph) == len(toe) * 30
    np.testing.assert_allclose(eph.iono_alpha, alpha, rtol=1e-4)
    np.testing.assert_allclose(eph.iono_beta, beta, rtol=1e-4)
    worst_p = worst_v = 0.0
    for t in np.linspace(0.0, 3 * 3600.0, 13):
        s = const.states(t)
        week = np.floor((t0 + t) / SECONDS_PER_WEEK)
        b = eph.states(week, (t0 - week * SECONDS_PER_WEEK) + t, s.prn)
        assert len(b) == 30
        worst_p = max(worst_p, np.abs(b.pos_ecef - s.pos_ecef).max())
        worst_v = max(worst_v, np.abs(b.vel_ecef - s.vel_ecef).max())
        assert np.all(b.clock_bias == 0.0)
    assert worst_p < 0.01 and worst_v < 1e-3


def test_obs_file_read_back_by_the_reader_and_georinex(tmp_path):
    """Pseudoranges and Doppler written with sub-millimetre digits come back from our reader
    and from georinex rounded to the file's 1 mm (1 mHz): |difference| <= 0.5 mm; epoch
    times exact; a blank pseudorange is counted, not read."""
    import georinex as gr
    rng = np.random.default_rng(2)
    k, per = 5, 6
    week = np.full(k, 2305)
    tow = 295200.0 + np.arange(k) * 0.5
    epoch = np.repeat(np.arange(k), per)
    prn = np.tile(np.arange(3, 3 + per), k)
    rho = 2.0e7 + rng.uniform(0, 5e6, k * per)
    dop = rng.uniform(-4000, 4000, k * per)
    rho[7] = np.nan
    write_rinex_obs(tmp_path / "o.rnx", week, tow, epoch, prn, rho, doppler=dop)
    r = read_rinex_obs(tmp_path / "o.rnx")
    np.testing.assert_array_equal(r.tow, tow)
    np.testing.assert_array_equal(r.week, week)
    ok = np.isfinite(rho)
    assert r.rejected == {"no C1C pseudorange": 1}
    np.testing.assert_array_equal(r.prn, prn[ok])
    assert np.abs(r.pseudorange - rho[ok]).max() <= 0.5e-3 + 1e-8
    assert np.abs(r.doppler - dop[ok]).max() <= 0.5e-3 + 1e-8
    ds = gr.load(tmp_path / "o.rnx")
    g = ds["C1C"].values
    sv = [int(s[1:]) for s in ds.sv.values]
    for i in np.nonzero(ok)[0]:
        assert abs(g[epoch[i], sv.index(prn[i])] - rho[i]) <= 0.5e-3 + 1e-8
    # without Doppler the reader says so
    write_rinex_obs(tmp_path / "p.rnx", week, tow, epoch, prn, rho)
    assert read_rinex_obs(tmp_path / "p.rnx").doppler is None


def test_writers_refuse_what_the_format_cannot_hold(tmp_path):
    """PRN 33, repeated epoch times, a clock epoch off the second, a start off the second:
    ArgumentErrors naming the argument, and no file left behind."""
    with pytest.raises(ArgumentError) as exc:
        write_rinex_obs(tmp_path / "o.rnx", [2305], [1.0], [0], [33], [2e7])
    assert exc.value.argument == "prn"
    with pytest.raises(ArgumentError) as exc:
        write_rinex_obs(tmp_path / "o.rnx", [2305, 2305], [1.0, 1.0], [0, 1], [3, 3], [2e7, 2e7])
    assert exc.value.argument == "tow"
    rec = NominalConstellation.gps(4).broadcast_records(0.0, [7200.5])
    with pytest.raises(ArgumentError, match="whole seconds"):
        write_rinex_nav(tmp_path / "n.rnx", rec)
    assert not (tmp_path / "n.rnx").exists() and not (tmp_path / "o.rnx").exists()
    with pytest.raises(ArgumentError) as exc:
        gps_seconds("2024-03-13T10:00:00.5")
    assert exc.value.argument == "start"


# ------------------------------------------------------------------ the round trip

SHORT_SEGMENTS = """segments = [
  { type = "static",     duration = "15 s" },
  { type = "accelerate", duration = "10 s", acceleration = "1.5 m/s^2" },
  { type = "uniform",    duration = "15 s" },
  { type = "turn",       duration = "9 s",  angle = "90 deg" },
  { type = "uniform",    duration = "15 s" },
  { type = "turn",       duration = "10 s", angle = "-60 deg" },
  { type = "uniform",    duration = "11 s" },
]"""


def short_scenario(folder):
    """tight-demo cut to 85 s: 15 s at rest, then a drive with two turns; 3 satellites only
    from 55 s to 65 s (the tight filter's case)."""
    text, _ = resolve("tight-demo")
    a = text.index("segments = [")
    b = text.index("]", text.index('{ type = "static",     duration = "25 s" }')) + 1
    text = text[:a] + SHORT_SEGMENTS + text[b:]
    text = text.replace('window = ["300 s", "360 s"]', 'window = ["55 s", "65 s"]')
    text = text.replace('name = "tight-demo"', 'name = "tight-short"')
    p = folder / "tight-short.toml"
    p.write_text(text)
    return p


def export_and_process(scenario, root, hole: bool = True):
    """``scenario`` (a name or a file) exported into ``root / "data"`` and the written dataset
    processed back: ``(scenario, its source, the export, the processed output)``. ``hole``:
    the run has a 10 s stretch without a fix, which processing must say (a warning)."""
    sc, source, _ = load_scenario(str(scenario))
    ex = export_dataset(sc, root / "data", source=source)
    ds, dsrc, _ = load_dataset(str(ex.files["dataset"]))
    if hole:
        with pytest.warns(Warning, match="hole"):     # the 10 s without a fix is said
            return sc, source, ex, process(ds, dsrc)
    return sc, source, ex, process(ds, dsrc)


def simulated_and_read_back_runs(exported, pick):
    """The scenario's method chosen by ``pick`` (a predicate on the method) built twice, on the
    simulated observables and on those read back from the RINEX files, and run from the
    simulation's start on its IMU: ``(results, measurement lists)``, simulated first."""
    sc, source, ex, po = exported
    sim = ex.sim
    m = next(x for x in sc.methods if pick(x))
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    lever = np.asarray(sc.gnss.lever_arm)
    res, meas_used = [], []
    for obs in (sim.observations, po.observations):
        f, meas = methods.build(m, sim.imu_model, sim.fixes, lever, source, 1, observations=obs, clock=clock)
        res.append(f.run(sim.imu, sim.init, meas))
        meas_used.append(meas)
    np.testing.assert_allclose(res[0].time, res[1].time, atol=1e-9)
    return res, meas_used


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    root = tmp_path_factory.mktemp("rinexins")
    return export_and_process(short_scenario(root), root)


def test_export_writes_a_dataset_of_the_run(exported):
    sc, _, ex, po = exported
    assert set(ex.files) == {"imu", "observations", "navigation", "reference", "dataset"}
    assert ex.methods == ["loose", "tight"] and not ex.skipped_methods
    ds = po.dataset
    assert ds.raw_gnss is not None and ds.gnss is None
    np.testing.assert_allclose(ds.installation.antenna_position, sc.gnss.lever_arm)
    # the IMU read back is the simulated one (17 digits) on the same time axis
    sim = ex.sim
    np.testing.assert_array_equal(po.imu.dtheta, sim.imu.dtheta)
    np.testing.assert_array_equal(po.imu.dvel, sim.imu.dvel)
    assert np.abs(po.imu.time - sim.imu.time).max() < 1e-9
    c = po.checks["rinex"]
    assert c["doppler"] and c["ionosphere"] == "off" and c["observations_not_filtered"].get("no ephemeris", 0) == 0
    assert c["spp_status"]["too few satellites"] == 10      # the 10 epochs with 3 satellites


def test_rinex_observables_equal_the_simulated_ones(exported):
    """The tight filter's observables rebuilt from the RINEX files (corrections, Earth
    rotation from the SPP position, Doppler) equal the simulator's: pseudoranges to the
    file's 1 mm rounding (0.5 mm), range rates to 1 mHz (0.2 mm/s), satellite positions to
    < 1 cm (the transmit time from the pseudorange carries the receiver clock, tens of
    metres: 0.1 us of orbit, a few mm), velocities to 1 mm/s; the same satellites at the
    same epochs."""
    _, _, ex, po = exported
    a, b = ex.sim.observations, po.observations
    np.testing.assert_array_equal(a.time, b.time)
    worst = np.zeros(4)
    for k in range(len(a)):
        pa, pb = a.prn[k][a.valid[k]], list(b.prn[k][b.valid[k]])
        assert sorted(pa) == sorted(pb)
        for j, p in enumerate(pa):
            i = pb.index(p)
            worst = np.maximum(worst, [abs(a.pseudorange[k, j] - b.pseudorange[k, i]),
                                       abs(a.range_rate[k, j] - b.range_rate[k, i]),
                                       np.linalg.norm(a.sat_pos[k, j] - b.sat_pos[k, i]),
                                       np.linalg.norm(a.sat_vel[k, j] - b.sat_vel[k, i])])
    assert worst[0] <= 0.5e-3 + 1e-7 and worst[1] <= 2e-4 and worst[2] < 0.01 and worst[3] < 1e-3


def test_tight_ekf_on_rinex_equals_the_in_simulation_one(exported):
    """Same start (the simulation's initial estimate), same IMU: the tight EKF on the RINEX
    observables follows the in-simulation tight EKF to < 1 cm at every epoch (the
    observables agree to millimetres, above)."""
    res, _ = simulated_and_read_back_runs(exported, lambda x: x.type == "tight-ekf")
    d = ned_displacement(res[1].nav[:, 7:10], res[0].nav[:, 7:10])
    assert np.abs(d).max() < 0.01


def test_processed_dataset_scores_like_the_simulation(exported):
    """``mixnav process`` of the export (SPP, level-then-gnss alignment at the first fix at
    2 m/s, clock from the SPP and Doppler) against the in-simulation tight EKF on the same
    draws (started at t = 0 from truth plus a draw): the two start differently, so they
    differ by metres at the alignment (measured 3.0 m); both then follow the same
    measurements and the difference decays: below 0.5 m horizontally from 30 s after the
    alignment on (measured 0.29 m; 0.42 m from 20 s, 0.18 m from 60 s: what is left is the
    different error-state covariance and sensor-bias estimates the two starts give). The
    processed tight filter is consistent: mean position NEES in (1, 6) (3 if exact; the
    errors of 70 epochs are correlated in time; measured 1.6)."""
    sc, source, ex, po = exported
    sim = ex.sim
    m = next(x for x in sc.methods if x.type == "tight-ekf")
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    f, meas = methods.build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), source, 1,
                            observations=sim.observations, clock=clock)
    ref = f.run(sim.imu, sim.init, meas)
    got = po.results["tight"]
    assert po.init.time < 25.0
    t = np.round(got.time, 6)
    k = np.searchsorted(np.round(ref.time, 6), t)
    d = ned_displacement(got.nav[:, 7:10], ref.nav[k, 7:10])
    h = np.hypot(d[:, 0], d[:, 1])
    assert h[t >= po.init.time + 30.0].max() < 0.5
    assert h[t >= po.init.time + 30.0].max() < 0.25 * h[t < po.init.time + 5.0].max()
    from mixnav.experiment.process import process_tables
    from mixnav.experiment.run import method_metrics
    tables = process_tables(po)
    mt = method_metrics(got, tables["tight"], ())
    assert 1.0 < mt["nees_pos_mean"] < 6.0
    assert mt["horizontal_rmse_m"] < 1.5


# ------------------------------------------------------------------ bad input


def _rewrite(src, dst, **subs):
    text = src.read_text()
    for old, new in subs.items():
        assert old in text, old
        text = text.replace(old, new)
    dst.write_text(text)
    return dst


def test_time_axes_that_do_not_overlap_name_both_files(exported, tmp_path):
    """IMU stamps read as GPS seconds since 1980 while they are seconds of week: a DataError
    naming both files. (Asked for the ionosphere without coefficients in the header: warned.)"""
    _, _, ex, _ = exported
    p = _rewrite(ex.files["dataset"], tmp_path / "d.toml",
                 **{'imu_time = "gps-week-seconds"': 'imu_time = "gps-seconds"',
                    "ionosphere = false": "ionosphere = true"})
    ds, src, _ = load_dataset(str(p))
    with pytest.raises(DataError) as exc, pytest.warns(Warning, match="Klobuchar"):
        process(ds, src)
    msg = str(exc.value)
    assert "obs.rnx" in msg and "imu.csv" in msg and "do not overlap" in msg


def test_missing_navigation_missing_ephemeris_and_klobuchar(exported, tmp_path):
    """No navigation file: a DataError naming it. A navigation file without one observed
    satellite: its observations are counted (SPP and the tight rows), not an error. With
    the header's Klobuchar coefficients and ``ionosphere = true`` the correction function
    takes the broadcast delay off every pseudorange: the tight observables are the
    simulated ones minus the delay evaluated independently at the true antenna (to 5 mm:
    the 1 mm file rounding plus the delay's change between the SPP fix and the truth)."""
    from mixnav.gnss.spp import klobuchar
    from mixnav.gnss.geometry import elevation_azimuth
    from mixnav.geodesy.frames import ecef_to_lla, lla_to_ecef
    from mixnav.measurements.loose import antenna_lla
    _, _, ex, _ = exported
    folder = ex.files["dataset"].parent
    p = _rewrite(ex.files["dataset"], tmp_path / "d.toml", **{'navigation = "nav.rnx"': 'navigation = "none.rnx"'})
    ds, src, _ = load_dataset(str(p))
    with pytest.raises(DataError, match="none.rnx"):
        process(ds, src)
    # drop one satellite's records (8 lines each) from the navigation file, add iono coefficients
    obs = read_rinex_obs(folder / "obs.rnx")
    prn = int(np.bincount(obs.prn).argmax())
    lines = (folder / "nav.rnx").read_text().splitlines()
    end = lines.index(next(ln for ln in lines if "END OF HEADER" in ln)) + 1
    body = lines[end:]
    kept = [ln for i, ln in enumerate(body) if not body[i - i % 8].startswith(f"G{prn:02d} ")]
    alpha, beta = [1.1176e-08, 7.4506e-09, -5.9605e-08, -5.9605e-08], [9.0112e+04, 4.9152e+04, -1.3107e+05, -2.6214e+05]
    iono = ["GPSA " + "".join(f"{x:12.4E}" for x in alpha), "GPSB " + "".join(f"{x:12.4E}" for x in beta)]
    iono = [f"{x:<60}IONOSPHERIC CORR" for x in iono]
    nav = tmp_path / "nav-less.rnx"
    nav.write_text("\n".join(lines[:end - 1] + iono + lines[end - 1:end] + kept) + "\n")
    p = _rewrite(ex.files["dataset"], tmp_path / "e.toml",
                 **{'navigation = "nav.rnx"': f'navigation = "{nav}"', "ionosphere = false": "ionosphere = true"})
    ds, src, _ = load_dataset(str(p))
    with pytest.warns(Warning):
        po = process(ds, src)
    n = int((obs.prn == prn).sum())
    c = po.checks["rinex"]
    assert c["satellites_skipped_by_spp"]["no ephemeris"] == n
    assert c["observations_not_filtered"]["no ephemeris"] == n
    assert not (po.observations.prn == prn).any()
    assert c["ionosphere"] == "klobuchar"
    a, b, truth = ex.sim.observations, po.observations, ex.sim.truth
    worst, seen = 0.0, 0
    for k in range(0, len(a), 7):
        kt = int(np.searchsorted(truth.time, a.time[k] - 1e-9))
        nav_t = np.concatenate([truth.q_nb[kt], truth.v_n[kt], truth.lla[kt]])
        r = lla_to_ecef(antenna_lla(nav_t, po.lever))
        lla = ecef_to_lla(r)
        pb = list(b.prn[k][b.valid[k]])
        for j, p_ in enumerate(a.prn[k][a.valid[k]]):
            if p_ not in pb:
                continue
            i = pb.index(p_)
            el, az = elevation_azimuth(r, a.sat_pos[k, j][None])
            tow = (ex.gps_start_s + a.time[k]) % SECONDS_PER_WEEK
            d = klobuchar(lla[0], lla[1], el, az, tow, alpha, beta)[0]
            assert d > 1.0                     # metres: the check has something to see
            worst = max(worst, abs((a.pseudorange[k, j] - d) - b.pseudorange[k, i]))
            seen += 1
    assert seen > 50 and worst < 0.005


def test_dataset_sections_and_methods_are_checked(exported, tmp_path):
    """Config errors naming the key: fixes and RINEX together, neither, a TDCP or tight
    method without the clock states, a phone log format, no navigation file
    named, an empty file list."""
    _, _, ex, _ = exported
    d = ex.files["dataset"]
    cases = [
        ({"[raw_gnss]": '[gnss]\nformat = "csv"\nfile = "x.csv"\n\n[raw_gnss]'}, "raw_gnss", "not both"),
        ({'type = "tight-ekf"\nstates = 17': 'type = "tdcp-ekf"\nstates = 15'}, "methods[1].states", "clock"),
        ({'type = "tight-ekf"\nstates = 17': 'type = "tight-ekf"\nstates = 15'}, "methods[1].states", "clock"),
        ({'format = "rinex-obs"': 'format = "android-gnsslogger"'}, "raw_gnss.format", None),
        ({'navigation = "nav.rnx"': ''}, "raw_gnss.navigation", None),
        ({'file = "obs.rnx"': 'file = []'}, "raw_gnss.file", "at least one"),
    ]
    text = d.read_text()
    a, b = text.index("[raw_gnss]"), text.index("[reference]")
    (tmp_path / "none.toml").write_text(text[:a] + text[b:])      # neither [gnss] nor [raw_gnss]
    with pytest.raises(ConfigError) as exc:
        load_dataset(str(tmp_path / "none.toml"))
    assert exc.value.key == "gnss" and "raw_gnss" in str(exc.value)
    for i, (subs, key, match) in enumerate(cases):
        p = _rewrite(d, tmp_path / f"c{i}.toml", **subs)
        with pytest.raises(ConfigError) as exc:
            load_dataset(str(p))
        if key is not None:
            assert exc.value.key == key, (i, exc.value)
        if match is not None:
            assert re.search(match, str(exc.value)), (i, exc.value)


def test_range_rates_without_doppler_are_refused(exported, tmp_path):
    """A tight method using range rates on a file without D1C: a config error naming its key."""
    _, _, ex, _ = exported
    folder = ex.files["dataset"].parent
    obs = read_rinex_obs(folder / "obs.rnx")
    write_rinex_obs(tmp_path / "nodop.rnx", obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange)
    p = _rewrite(ex.files["dataset"], tmp_path / "d.toml",
                 **{'file = "obs.rnx"': f'file = "{tmp_path / "nodop.rnx"}"'})
    ds, src, _ = load_dataset(str(p))
    with pytest.raises(ConfigError) as exc:
        process(ds, src)
    assert exc.value.key == "methods[1].use_range_rate" and "Doppler" in str(exc.value)


def test_export_needs_raw_satellites(tmp_path):
    """A scenario with fixes only has nothing to write as RINEX."""
    sc, src, _ = load_scenario("loose-demo")
    with pytest.raises(ConfigError) as exc:
        export_dataset(sc, tmp_path / "x", source=src)
    assert exc.value.key == "gnss.satellites"


def test_export_from_python_and_the_command(tmp_path):
    """``mixnav.export_rinex`` writes the files (and the folder is the export's own); the
    command refuses a folder holding other files before simulating anything (exit 2)."""
    import mixnav
    from typer.testing import CliRunner

    from mixnav.cli import app
    from mixnav.io.outdir import read_marker
    scen = short_scenario(tmp_path)
    files = mixnav.export_rinex(str(scen), tmp_path / "out", seed=3)
    assert sorted(files) == ["dataset", "imu", "navigation", "observations", "reference"]
    assert all(p.is_file() for p in files.values())
    assert read_marker(tmp_path / "out")["command"] == "export"
    with pytest.raises(ArgumentError) as exc:
        mixnav.export_rinex(str(scen), tmp_path / "out2", seed=-1)
    assert exc.value.argument == "seed"
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "mine.txt").write_text("x")
    r = CliRunner().invoke(app, ["export", str(scen), "--out", str(tmp_path / "busy")])
    assert r.exit_code == 2 and "not empty" in r.output
    r = CliRunner().invoke(app, ["export", str(scen), "--out", str(tmp_path / "c"), "--start", "yesterday"])
    assert r.exit_code == 2 and "start" in r.output


def test_observation_and_navigation_files_in_parts(exported, tmp_path):
    """The observation file cut in two (and a second, unrelated navigation file) gives the
    same tight observables as the one file; parts out of time order: a DataError naming
    the one that starts too early."""
    _, _, ex, po = exported
    folder = ex.files["dataset"].parent
    obs = read_rinex_obs(folder / "obs.rnx")
    half = len(obs.tow) // 2
    for name, sel in (("a.rnx", obs.epoch < half), ("b.rnx", obs.epoch >= half)):
        ep = obs.epoch[sel]
        write_rinex_obs(tmp_path / name, obs.week[np.unique(ep)], obs.tow[np.unique(ep)], ep - ep.min(),
                        obs.prn[sel], obs.pseudorange[sel], doppler=obs.doppler[sel])
    other = NominalConstellation.gps(5).broadcast_records(gps_seconds("2020-01-01T00:00:00"), [1.2618e9])
    write_rinex_nav(tmp_path / "old.rnx", other)
    p = _rewrite(ex.files["dataset"], tmp_path / "d.toml",
                 **{'file = "obs.rnx"': f'file = ["{tmp_path / "a.rnx"}", "{tmp_path / "b.rnx"}"]',
                    'navigation = "nav.rnx"': f'navigation = ["nav.rnx", "{tmp_path / "old.rnx"}"]'})
    ds, src, _ = load_dataset(str(p))
    with pytest.warns(Warning, match="hole"):
        got = process(ds, src)
    a, b = po.observations, got.observations
    for k in ("time", "valid", "prn", "pseudorange", "range_rate", "sat_pos"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    assert len(got.checks["rinex"]["observation_files"]) == 2
    p = _rewrite(p, tmp_path / "e.toml", **{f'"{tmp_path / "a.rnx"}", "{tmp_path / "b.rnx"}"':
                                            f'"{tmp_path / "b.rnx"}", "{tmp_path / "a.rnx"}"'})
    ds, src, _ = load_dataset(str(p))
    with pytest.raises(DataError) as exc:
        process(ds, src)
    assert exc.value.file.endswith("a.rnx") and "time order" in str(exc.value)


def test_rinex2_doppler_is_read(tmp_path):
    """RINEX 2's ``D1`` beside ``C1``, blank where the receiver gave none (NaN)."""
    from .test_rinex_obs import _time, _write_rinex2
    times = [_time(2305, 295200.0 + k) for k in range(3)]
    recs = [[("G05", {"C1": 2.1e7 + k, "D1": -1500.25 + k}), ("G12", {"C1": 2.3e7 + k})] for k in range(3)]
    _write_rinex2(tmp_path / "o.11o", times, recs, types=("C1", "D1"), kind="G (GPS)")
    r = read_rinex_obs(tmp_path / "o.11o")
    assert r.code == "C1"
    np.testing.assert_array_equal(r.prn, [5, 12] * 3)
    np.testing.assert_allclose(r.doppler[0::2], -1500.25 + np.arange(3))
    assert np.isnan(r.doppler[1::2]).all()


def test_elevation_weights_reach_the_tight_rows(exported):
    """``pseudorange_weights = "elevation"``: each pseudorange row's variance is SPP's
    ``sigma_a^2 + sigma_b^2 / sin^2 el`` (3 m and 3 m) at the slot's elevation, in the
    compiled rows, the numpy oracle and the batch prediction alike; innovations, Jacobians
    and the range-rate variances are those of constant weights."""
    from dataclasses import replace

    from mixnav.gnss.raw_observations import tight_observations
    from mixnav.gnss.spp import SppOptions, corrected_pseudoranges
    from mixnav.ins.error_model import get_layout
    from mixnav.measurements.tight import TightGnss
    _, _, ex, po = exported
    folder = ex.files["dataset"].parent
    obs = read_rinex_obs(folder / "obs.rnx")
    eph = BroadcastEphemeris.from_rinex(folder / "nav.rnx")
    rx = np.tile(_ecef(ex), (len(obs.tow), 1))   # the start point: elevations to 1e-4 rad
    ep, _ = corrected_pseudoranges(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange, rx,
                                   SppOptions(troposphere=False, ionosphere=False), doppler=obs.doppler)
    const, _ = tight_observations(ep, rx, 3.0, 0.1)
    elev, _ = tight_observations(ep, rx, 3.0, 0.1, weights="elevation")
    assert const.pr_variance is None
    v = elev.valid
    np.testing.assert_allclose(elev.pr_variance[v], 9.0 + 9.0 / np.sin(elev.elevation[v]) ** 2, rtol=1e-12)
    lay = get_layout(17)
    nav = np.concatenate([ex.sim.truth.q_nb[0], ex.sim.truth.v_n[0], ex.sim.truth.lla[0]])
    w, clock = np.array([0.01, 0.0, 0.02]), np.array([5.0, 0.1])
    a, b = TightGnss(const, [0.5, 0.2, -1.0], lay), TightGnss(elev, [0.5, 0.2, -1.0], lay)
    k = 3
    ra, rb = a.rows(k, nav, w, clock), b.rows(k, nav, w, clock)
    n = int(v[k].sum())
    np.testing.assert_array_equal(ra.z, rb.z)
    np.testing.assert_array_equal(ra.H, rb.H)
    np.testing.assert_allclose(rb.R[:n], elev.pr_variance[k, v[k]])
    np.testing.assert_array_equal(rb.R[n:], ra.R[n:])
    np.testing.assert_allclose(b.measure_numpy(k, nav, w, clock)[2], rb.R)
    np.testing.assert_allclose(b.predict_batch(k, nav[None], w)[2], rb.R)
    assert replace(po.observations).pr_variance is None      # the export's dataset: constant weights


def _ecef(ex):
    from mixnav.geodesy.frames import lla_to_ecef
    return lla_to_ecef(ex.sim.truth.lla[0])


def test_outputs_are_those_of_an_ins_dataset(exported, tmp_path):
    """write_process: solution tables scored against the reference, metrics.json with the
    RINEX counts, the report."""
    import json

    from mixnav.experiment.process import write_process
    _, _, _, po = exported
    write_process(tmp_path / "out", po)
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert set(m["methods"]) == {"loose", "tight"}
    assert m["rinex"]["spp_status"] == po.checks["rinex"]["spp_status"]
    assert m["methods"]["tight"]["horizontal_rmse_m"] < 1.5
    assert (tmp_path / "out" / "report.html").is_file()
    assert "of the week of the first RINEX epoch" in (tmp_path / "out" / "report.html").read_text()


def test_outage_sweep_withholds_the_rinex_observations(exported):
    """The outage sweep on a RINEX dataset withholds the observation epochs ([raw_gnss]
    withhold): the tight filter coasts through each window on the IMU alone. A window that
    starts at the alignment is left out and said (the alignment needs the GNSS in it)."""
    from mixnav.experiment.sweep import run_outage_sweep
    _, _, ex, po = exported
    res = run_outage_sweep(str(ex.files["dataset"]), "10 s", "10 s", (math.ceil(po.init.time), 80.0), workers=1)
    assert res.settings["skipped_windows_alignment"] == [[math.ceil(po.init.time), math.ceil(po.init.time) + 10.0]]
    tight = res.rows[res.rows["method"] == "tight"]
    assert len(tight) == len(res.rows) / 2 >= 1
    # coasting 10 s on a tactical-grade IMU: worse than with GNSS, far from lost
    assert (tight["horizontal_max_m"] > po_error(po, "tight")).all() and (tight["horizontal_max_m"] < 20).all()


def po_error(po, name):
    """The largest horizontal error of a method with every GNSS epoch used (the run without windows)."""
    from mixnav.experiment.pipelines import pipeline
    return pipeline(po.dataset).metrics(po, pipeline(po.dataset).tables(po))[name]["horizontal_rmse_m"]
