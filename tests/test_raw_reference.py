"""Scoring a moving receiver: a raw-GNSS dataset's ``[reference]`` trajectory
(experiment/raw_reference.py, io/gps_week_csv.py, the scoring of experiment/spp_process.py).

The oracle is a simulated drive (the simulator's raw pseudoranges exported as RINEX by
``mixnav export``): its true antenna track written as the reference CSV must give the
errors computed directly from the truth at the epochs' simulation times."""

import json
import math

import numpy as np
import pytest

from mixnav.config.loader import load_dataset, load_scenario
from mixnav.errors import ConfigError, DataError
from mixnav.experiment.export import export_dataset
from mixnav.experiment.spp_process import method_metrics, process_raw, raw_tables, solution_table, write_raw
from mixnav.geodesy.frames import lla_to_ecef
from mixnav.io.gps_week_csv import COLUMNS, read_gps_week_csv, write_gps_week_csv
from mixnav.measurements.loose import antenna_lla

from .test_rinex_ins import short_scenario

WEEK = 604800.0

# ------------------------------------------------------------------ the CSV reader


def test_csv_round_trip_with_and_without_header(tmp_path):
    """Written and read back: weeks exact, times of week to 1 ns, positions to the writer's
    digits (1e-12 deg, 1 um); across a week roll-over the times keep increasing."""
    week = np.array([2299, 2299, 2300, 2300])
    tow = np.array([604799.5, 604799.9, 0.3, 0.7])
    lla = np.array([[math.radians(22.3), math.radians(114.17), 3.0 + i] for i in range(4)])
    for header in (True, False):
        p = tmp_path / f"ref{header}.csv"
        write_gps_week_csv(p, week, tow, lla, header=header)
        assert (p.read_text().splitlines()[0] == ",".join(COLUMNS)) is header
        r = read_gps_week_csv(p)
        np.testing.assert_array_equal(r.extra["gps_week"], week)
        np.testing.assert_allclose(r.extra["gps_tow_s"], tow, rtol=0, atol=1e-9)
        np.testing.assert_allclose(r.lla[:, :2], lla[:, :2], rtol=0, atol=1e-14)
        np.testing.assert_allclose(r.lla[:, 2], lla[:, 2], rtol=0, atol=1e-6)
        np.testing.assert_allclose(np.diff(r.time), [0.4, 0.4, 0.4], atol=1e-6)
    # comments and blank lines are skipped
    p = tmp_path / "c.csv"
    p.write_text("# made by hand\n\n" + (tmp_path / "refTrue.csv").read_text())
    assert len(read_gps_week_csv(p)) == 4


@pytest.mark.parametrize("line, message", [
    ("2300,10.0,22.3,114.1", "expected 5"),
    ("2300,10.0,22.3,abc,3.0", "abc"),
    ("2300.5,10.0,22.3,114.1,3.0", "whole number"),
    ("2300,604800.0,22.3,114.1,3.0", "outside 0..604800"),
    ("2300,10.0,95.0,114.1,3.0", "latitude"),
    ("2300,10.0,22.3,114.1,-2000.0", "height"),
    ("2300,4.0,22.3,114.1,3.0", "backwards"),
])
def test_bad_lines_are_named_by_file_and_line(tmp_path, line, message):
    p = tmp_path / "ref.csv"
    p.write_text(",".join(COLUMNS) + "\n2300,5.0,22.3,114.1,3.0\n" + line + "\n")
    with pytest.raises(DataError, match=message) as ei:
        read_gps_week_csv(p)
    assert ei.value.line == 3 and ei.value.file == str(p)


def test_a_header_in_another_order_is_refused(tmp_path):
    p = tmp_path / "ref.csv"
    p.write_text("gps_tow_s,gps_week,lat_deg,lon_deg,height_m\n5.0,2300,22.3,114.1,3.0\n")
    with pytest.raises(DataError, match="header") as ei:
        read_gps_week_csv(p)
    assert ei.value.line == 1


# ------------------------------------------------------------------ a simulated drive


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """The tight-demo drive cut to 85 s (tests/test_rinex_ins.py), exported as RINEX: the
    folder, the export, the true antenna track at the truth's 100 Hz samples, and the GPS
    week / time of week of each sample."""
    root = tmp_path_factory.mktemp("rawref")
    sc, source, _ = load_scenario(str(short_scenario(root)))
    ex = export_dataset(sc, root / "data", source=source)
    tr = ex.sim.truth
    lever = np.asarray(sc.gnss.lever_arm, float)
    nav = np.column_stack([tr.q_nb, tr.v_n, tr.lla])
    ant = np.array([antenna_lla(n, lever) for n in nav])
    t_gps = ex.gps_start_s + tr.time
    week = np.floor(t_gps / WEEK).astype(int)
    tow = (ex.gps_start_s - week * WEEK) + tr.time
    return root / "data", ex, ant, week, tow


def _dataset(folder, reference: str, extra_sections: str = "", methods: bool = True):
    text = f"""[dataset]
name = "sim-drive"
kind = "gnss-raw"
data_dir = "{folder}"

[raw_gnss]
format = "rinex-obs"
file = "obs.rnx"
navigation = "nav.rnx"
elevation_mask = "10 deg"
troposphere = false   # the simulation has no atmosphere
ionosphere = false

[reference]
{reference}
{extra_sections}
[motion]
accel_sigma = "1 m/s^2/sqrt(Hz)"
"""
    if methods:
        text += '\n[[methods]]\nname = "spp"\nestimator = "wls"\n\n[[methods]]\nname = "ekf"\nestimator = "ekf"\n'
    p = folder / "sim.toml"
    p.write_text(text)
    return load_dataset(str(p))


def _direct_errors(ex, ant, pos_ecef, epoch_index):
    """Estimate minus the true antenna at the epochs' own simulation times, NED there:
    written out here from the ECEF rotation (not the code under test)."""
    tr = ex.sim.truth
    obs_t = ex.sim.observations.time[epoch_index]
    k = np.searchsorted(tr.time, obs_t - 1e-9)
    assert np.abs(tr.time[k] - obs_t).max() < 1e-9          # epochs fall on truth samples
    lat, lon = ant[k, 0], ant[k, 1]
    d = pos_ecef - lla_to_ecef(ant[k])
    n = -np.sin(lat) * np.cos(lon) * d[:, 0] - np.sin(lat) * np.sin(lon) * d[:, 1] + np.cos(lat) * d[:, 2]
    e = -np.sin(lon) * d[:, 0] + np.cos(lon) * d[:, 1]
    dn = -np.cos(lat) * np.cos(lon) * d[:, 0] - np.cos(lat) * np.sin(lon) * d[:, 1] - np.sin(lat) * d[:, 2]
    return np.column_stack([n, e, dn])


def test_reference_csv_gives_the_errors_from_the_truth(drive, tmp_path):
    """The true antenna track at 10 Hz written as the CSV: every SPP and filter error equals
    the one computed directly from the truth (epochs fall on samples: exact but for the
    file's digits, 1e-12 deg and 1 um: 1e-6 m); at samples offset by half a step, interpolated:
    off by the chord's sag a*dt^2/8 in the turns, 3.27 mm (a = 15 m/s * 90 deg / 9 s =
    2.62 m/s^2, dt = 0.1 s; 3.5 mm allowed), more than 1 mm there (it is interpolated, not
    snapped: the nearest sample would be up to 0.75 m off at 15 m/s). Every epoch is
    scored; the metrics are those of the direct errors; availability beside them."""
    folder, ex, ant, week, tow = drive
    on = slice(0, None, 10)                         # 10 Hz: the 1 Hz epochs are samples
    write_gps_week_csv(folder / "ref.csv", week[on], tow[on], ant[on])
    ds, src, _ = _dataset(folder, 'format = "gps-week-csv"\nfile = "ref.csv"')
    po = process_raw(ds, src, folder)
    tables = raw_tables(po)
    spp, ekf = tables["spp"], tables["ekf"]
    ok = (spp.status == "ok").to_numpy()
    assert ok.sum() == len(spp) - 10                  # the 10 epochs with 3 satellites
    assert po.reference.counts == {"scored": 85, "before_reference": 0, "after_reference": 0,
                                   "in_reference_gaps": 0, "reference_gaps": 0}
    direct = _direct_errors(ex, ant, po.track.pos_ecef[ok], np.nonzero(ok)[0])
    got = spp.loc[ok, ["err_n_m", "err_e_m", "err_d_m"]].to_numpy()
    np.testing.assert_allclose(got, direct, rtol=0, atol=1e-6)
    # a plain SPP of a 3 m pseudorange sigma: metres, not the tens a 1 s time slip would give at 15 m/s
    h = np.hypot(direct[:, 0], direct[:, 1])
    m = {n: method_metrics(po, n, t) for n, t in tables.items()}
    # (to the errors' 1e-6 m)
    assert m["spp"]["horizontal_rmse_m"] == pytest.approx(np.sqrt(np.mean(h**2)), rel=0, abs=1e-6)
    assert m["spp"]["horizontal_median_m"] == pytest.approx(np.median(h), rel=0, abs=1e-6)
    assert m["spp"]["horizontal_p95_m"] == pytest.approx(np.percentile(h, 95), rel=0, abs=1e-6)
    assert m["spp"]["horizontal_max_m"] == pytest.approx(h.max(), rel=0, abs=1e-6)
    assert m["spp"]["error_3d_rmse_m"] == pytest.approx(np.sqrt(np.mean(np.sum(direct**2, 1))), rel=0, abs=1e-6)
    assert m["spp"]["availability"] == pytest.approx(75 / 85) and m["spp"]["n_scored"] == 75
    assert 0.5 < m["spp"]["horizontal_rmse_m"] < 10.0
    # the filter: its own positions against the same truth
    fok = (ekf.status == "ok").to_numpy()
    f_ecef = lla_to_ecef(np.column_stack([np.radians(ekf.lat_deg[fok]), np.radians(ekf.lon_deg[fok]),
                                          ekf.height_m[fok]]))
    np.testing.assert_allclose(ekf.loc[fok, ["err_n_m", "err_e_m", "err_d_m"]].to_numpy(),
                               _direct_errors(ex, ant, f_ecef, np.nonzero(fok)[0]), rtol=0, atol=1e-6)
    assert m["ekf"]["n_scored"] == fok.sum() and np.isfinite(m["ekf"]["horizontal_rmse_m"])
    # half a step off the epochs: interpolated
    half = slice(5, None, 10)
    write_gps_week_csv(folder / "ref_half.csv", week[half], tow[half], ant[half])
    ds2, src2, _ = _dataset(folder, 'format = "gps-week-csv"\nfile = "ref_half.csv"', methods=False)
    po2 = process_raw(ds2, src2, folder)
    assert po2.reference.counts["after_reference"] == 1      # the last epoch, 85 s, after 84.95 s
    t2 = solution_table(po2)
    d = (t2.loc[ok, ["err_n_m", "err_e_m", "err_d_m"]].to_numpy() - direct)[:-1]
    assert 1e-3 < np.abs(d).max() < 3.5e-3, np.abs(d).max()


def test_other_reference_formats_on_the_same_time_axis(drive):
    """The same truth as mixnav's generic reference CSV (time[s] = GPS seconds of the first
    epoch's week, ``time = "gps-week-seconds"``, the default, or GPS seconds since 1980,
    ``time = "gps-seconds"``) and as an RTKLIB solution (GPST week and time of week, read on
    the Unix scale, 0.24 us steps): the same errors as the GPS week CSV, to 1e-6 m (the
    epochs fall on the samples within the 1 us snap, so they take them exactly)."""
    folder, ex, ant, week, tow = drive
    on = slice(0, None, 10)
    write_gps_week_csv(folder / "ref.csv", week[on], tow[on], ant[on])
    base = solution_table(process_raw(*_dataset(folder, 'format = "gps-week-csv"\nfile = "ref.csv"',
                                                methods=False)[:2], folder))
    rows = [f"{t:.9f},{math.degrees(p[0]):.12f},{math.degrees(p[1]):.12f},{p[2]:.6f}"
            for t, p in zip((week[on] - week[0]) * WEEK + tow[on], ant[on])]
    (folder / "ref_generic.csv").write_text("time[s],lat[deg],lon[deg],height[m]\n" + "\n".join(rows) + "\n")
    rows = [f"{t:.9f},{math.degrees(p[0]):.12f},{math.degrees(p[1]):.12f},{p[2]:.6f}"
            for t, p in zip(week[on] * WEEK + tow[on], ant[on])]
    (folder / "ref_1980.csv").write_text("time[s],lat[deg],lon[deg],height[m]\n" + "\n".join(rows) + "\n")
    # an RTKLIB solution in GPST, week and time of week (Q = 1, fixed: the default qualities)
    pos = ["%  GPST                      latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
           "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio"]
    pos += [f"{w} {t:.3f} {math.degrees(p[0]):.12f} {math.degrees(p[1]):.12f} {p[2]:.6f} 1 9 0.01 0.01 0.01 "
            "0.0 0.0 0.0 0.0 0.0" for w, t, p in zip(week[on], tow[on], ant[on])]
    (folder / "ref.pos").write_text("\n".join(pos) + "\n")
    for ref in ('format = "csv"\nfile = "ref_generic.csv"',
                'format = "csv"\nfile = "ref_1980.csv"\ntime = "gps-seconds"',
                'format = "rtklib-pos"\nfile = "ref.pos"'):
        t = solution_table(process_raw(*_dataset(folder, ref, methods=False)[:2], folder))
        np.testing.assert_allclose(t[["err_n_m", "err_e_m", "err_d_m"]].to_numpy(),
                                   base[["err_n_m", "err_e_m", "err_d_m"]].to_numpy(), rtol=0, atol=1e-6)


def test_epochs_outside_the_reference_or_in_its_gaps_are_counted_not_scored(drive, tmp_path):
    """A reference from 10 s to 70 s with a hole from 30 s to 40 s (10 s > max_gap = 1 s):
    epochs 1-9 s before it, 71-85 s after it, 31-39 s in the gap have NaN errors and are
    counted; the epochs at 30 s and 40 s fall on samples and are scored; availability still
    counts every solved epoch. metrics.json and the report say it."""
    folder, ex, ant, week, tow = drive
    t = ex.sim.truth.time
    keep = (np.arange(len(t)) % 10 == 0) & (t >= 10 - 1e-9) & (t <= 70 + 1e-9) & ~((t > 30 + 1e-9) & (t < 40 - 1e-9))
    write_gps_week_csv(folder / "ref_gap.csv", week[keep], tow[keep], ant[keep])
    ds, src, _ = _dataset(folder, 'format = "gps-week-csv"\nfile = "ref_gap.csv"')
    po = process_raw(ds, src, folder)
    assert po.reference.counts == {"scored": 85 - 9 - 15 - 9, "before_reference": 9, "after_reference": 15,
                                   "in_reference_gaps": 9, "reference_gaps": 1}
    table = solution_table(po)
    obs_t = ex.sim.observations.time
    scored = (obs_t >= 10) & (obs_t <= 70) & ~((obs_t > 30) & (obs_t < 40))
    np.testing.assert_array_equal(np.isfinite(table.err_n_m.to_numpy()), scored & (table.status == "ok").to_numpy())
    # the solution's sigmas do not depend on the reference: kept where it is not scored
    np.testing.assert_array_equal(np.isfinite(table.sig_n_m.to_numpy()), (table.status == "ok").to_numpy())
    out = tmp_path / "out"
    m = write_raw(out, po)
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["reference"]["reference_epochs"]["in_reference_gaps"] == 9 and saved["reference_point"] is None
    s = saved["methods"]["spp"]
    assert s["availability"] == pytest.approx(75 / 85)
    assert s["n_scored"] == int((scored & (table.status == "ok").to_numpy()).sum())
    assert m["methods"]["ekf"]["n_scored"] > 0
    assert "in 1 gap(s) longer than 1 s" in (out / "report.html").read_text()
    # a max_gap beyond the 10 s hole: its epochs are interpolated across it and scored
    ds, src, _ = _dataset(folder, 'format = "gps-week-csv"\nfile = "ref_gap.csv"\nmax_gap = "20 s"', methods=False)
    assert process_raw(ds, src, folder).reference.counts["in_reference_gaps"] == 0


def test_bad_reference_configs_name_the_file_and_key(drive):
    folder, ex, ant, week, tow = drive
    on = slice(0, None, 10)
    write_gps_week_csv(folder / "ref_next_week.csv", week[on] + 1, tow[on], ant[on])
    ds, src, _ = _dataset(folder, 'format = "gps-week-csv"\nfile = "ref_next_week.csv"', methods=False)
    with pytest.raises(ConfigError, match="do not overlap") as ei:
        process_raw(ds, src, folder)
    assert ei.value.key == "reference.file" and "ref_next_week.csv" in str(ei.value) and "sim.toml" in str(ei.value)
    # both a static point and a moving reference
    with pytest.raises(ConfigError, match="not both") as ei:
        _dataset(folder, 'format = "gps-week-csv"\nfile = "ref.csv"',
                 '\n[reference_point]\nlatitude = "22 deg"\nlongitude = "114 deg"\nheight = "3 m"\n')
    assert ei.value.key == "reference"
    for ref, key, message in [
            ('format = "gps-week-csv"\nfile = "ref.csv"\ntime = "gps-seconds"', "reference", "own time axis"),
            ('format = "gps-week-csv"\nfile = "ref.csv"\nqualities = [1]', "reference", "quality"),
            ('format = "smartloc"\nfile = "ref.csv"', "reference.format", "start of the log"),
            ('format = "gps-week-csv"\nfile = "ref.csv"\npoint = "imu"', "reference.point", "unknown key"),
            ('format = "gps-week-csv"\nfile = "ref.csv"\nmax_gap = 1', "reference.max_gap", "bare number")]:
        with pytest.raises(ConfigError, match=message) as ei:
            _dataset(folder, ref)
        assert ei.value.key == key, (ref, ei.value.key)


def test_a_still_trajectory_scores_as_the_surveyed_point(tmp_path):
    """Invariant on real data (android-static): the surveyed point written as a trajectory
    that stands still (a sample every second over the log) scores every SPP epoch as
    ``[reference_point]`` does: the same errors to 1e-6 m (the interpolation's
    ``a (1 - w) + a w`` may differ from ``a`` in the last bit: 1e-9 m), the same metrics,
    every epoch scored."""
    from .conftest import data_file
    import re
    log = data_file("android-static", "pseudoranges_log_2016_06_30_21_26_07.txt")
    ds, src, text = load_dataset("android-static")
    folder = log.parent
    po_point = process_raw(ds, src, folder)
    rp = ds.reference_point
    t0 = po_point.track.week[0] * WEEK + po_point.track.tow[0]
    t = np.arange(np.floor(t0) - 1, t0 + len(po_point.track.tow) * 1.2 + 2)
    week = np.floor(t / WEEK).astype(int)
    write_gps_week_csv(tmp_path / "still.csv", week, t - week * WEEK,
                       np.tile([rp.latitude, rp.longitude, rp.height], (len(t), 1)))
    moving = re.sub(r"\[reference_point\].*", f'[reference]\nformat = "gps-week-csv"\nfile = "{tmp_path / "still.csv"}"\n',
                    text, flags=re.S)
    (tmp_path / "moving.toml").write_text(moving.replace('data_dir = "../shared/data/android-static"',
                                                         f'data_dir = "{folder}"'))
    ds2, src2, _ = load_dataset(str(tmp_path / "moving.toml"))
    assert ds2.reference_point is None and ds2.reference is not None
    po_traj = process_raw(ds2, src2, folder)
    a, b = solution_table(po_point), solution_table(po_traj)
    assert po_traj.reference.counts["scored"] == len(a)
    cols = ["err_n_m", "err_e_m", "err_d_m", "sig_n_m", "sig_e_m", "sig_d_m"]
    np.testing.assert_allclose(b[cols].to_numpy(), a[cols].to_numpy(), rtol=0, atol=1e-6)
    ma, mb = method_metrics(po_point, "spp", a), method_metrics(po_traj, "spp", b)
    for key in ("n_epochs", "availability", "n_scored"):
        assert ma[key] == mb[key], key
    for key in ("horizontal_rmse_m", "horizontal_median_m", "horizontal_p95_m", "horizontal_max_m",
                "error_3d_rmse_m", "vertical_rmse_m", "nees_pos_mean"):
        assert mb[key] == pytest.approx(ma[key], rel=1e-9, abs=1e-6), key


def test_mixnav_process_of_a_moving_receiver(drive, tmp_path):
    """``mixnav process`` end to end: metrics.json names the reference and its epoch counts,
    the map draws the reference (its samples over the log) beside each method's track, the
    API's truth is the reference on the tables' time axis."""
    from typer.testing import CliRunner
    from mixnav.cli import app
    from mixnav.experiment.pipelines import gnss_raw
    from .test_webmap import polylines
    folder, ex, ant, week, tow = drive
    on = slice(0, None, 10)
    write_gps_week_csv(folder / "ref.csv", week[on], tow[on], ant[on])
    _dataset(folder, 'format = "gps-week-csv"\nfile = "ref.csv"')
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["process", str(folder / "sim.toml"), "--out", str(out), "--no-sweeps"])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    assert m["reference"]["format"] == "gps-week-csv" and m["reference"]["reference_epochs"]["scored"] == 85
    # the filter from the epoch after the first fix (1 s) on, through the 3-satellite epochs
    assert set(m["methods"]) == {"spp", "ekf"} and m["methods"]["ekf"]["n_scored"] == 84
    lines = polylines((out / "map.html").read_text())
    ref_line = [ln for ln in lines if len(ln) > 200]      # the 10 Hz reference over 85 s; the tracks have <= 85 points
    assert len(ref_line) == 1 and len(lines) == 3
    po = process_raw(*load_dataset(str(folder / "sim.toml"))[:2], folder)
    truth = gnss_raw.truth(po)
    # the samples from simulation time 0 s to 85 s; the first epoch, time_s = 0, is at 1 s
    np.testing.assert_allclose(truth.time_s.to_numpy()[[0, -1]], [-1.0, 84.0], atol=1e-6)


# ------------------------------------------------------------------ smartLoc: corrected pseudoranges


SMARTLOC_RAW = """[dataset]
name = "sl"
kind = "gnss-raw"
data_dir = "{folder}"

[raw_gnss]
format = "smartloc"
file = "Berlin_Potsdamer_Platz_Input.txt"
systems = ["G", "R"]
elevation_mask = "0 deg"
{extra}
[reference]
format = "smartloc"
file = "Berlin_Potsdamer_Platz_GT.txt"
"""


@pytest.mark.parametrize("extra, key, message", [
    ('navigation = "x.nav"', "raw_gnss", "no navigation file"),
    ('sigma_a = "3 m"', "raw_gnss", "variances"),
    ("troposphere = true", "raw_gnss", "atmosphere"),
    ('signals = { G = "C1C" }', "raw_gnss", "one pseudorange"),
])
def test_smartloc_raw_keys_are_checked(tmp_path, extra, key, message):
    p = tmp_path / "sl.toml"
    p.write_text(SMARTLOC_RAW.format(folder=tmp_path, extra=extra))
    with pytest.raises(ConfigError, match=message) as ei:
        load_dataset(str(p))
    assert ei.value.key == key
    # a RINEX log needs its navigation file; a smartLoc log takes no GPS-time reference
    p.write_text(SMARTLOC_RAW.format(folder=tmp_path, extra="").replace('format = "smartloc"\nfile = "Berl',
                                                                        'format = "rinex-obs"\nfile = "Berl', 1))
    with pytest.raises(ConfigError, match="navigation: required"):
        load_dataset(str(p))
    p.write_text(SMARTLOC_RAW.format(folder=tmp_path, extra="").replace(
        'format = "smartloc"\nfile = "Berlin_Potsdamer_Platz_GT.txt"', 'format = "gps-week-csv"\nfile = "r.csv"'))
    with pytest.raises(ConfigError, match="start of the log") as ei:
        load_dataset(str(p))
    assert ei.value.key == "reference.format"


def _gauss_newton(rho, var, sat, letters):
    """An independent WLS of one epoch, written out here: position, GPS clock and a GLONASS
    offset; each satellite turned by the Earth's rotation during its travel time; weights
    1 / variance; no mask (the dataset's 0 deg)."""
    omega, c = 7.2921151467e-5, 299792458.0
    x = np.zeros(5)
    glo = (letters == "R").astype(float)
    for _ in range(20):
        tau = np.linalg.norm(sat - x[:3], axis=1) / c
        a = omega * tau
        s = np.column_stack([np.cos(a) * sat[:, 0] + np.sin(a) * sat[:, 1],
                             -np.sin(a) * sat[:, 0] + np.cos(a) * sat[:, 1], sat[:, 2]])
        r = np.linalg.norm(s - x[:3], axis=1)
        H = np.column_stack([(x[:3] - s) / r[:, None], np.ones(len(r)), glo])
        dx = np.linalg.solve(H.T @ (H / var[:, None]), H.T @ ((rho - r - x[3] - glo * x[4]) / var))
        x += dx
        if np.linalg.norm(dx[:3]) < 1e-6:
            break
    return x


def test_smartloc_gnss_alone_against_an_independent_wls_and_its_ground_truth():
    """The shipped smartloc-berlin-gnss, SPP only: every epoch (GPS + GLONASS, the file's
    variances) equals an independent Gauss-Newton of its rows to 1 mm (both iterate to
    1e-4 m steps or finer); the ground truth shares the pseudoranges' time stamps, so every
    epoch takes its truth point exactly and the errors are estimate minus truth, to 1e-6 m
    beside an ECEF rotation written out here."""
    from .conftest import data_file
    from mixnav.config.raw_gnss_schema import RawMethod
    from mixnav.io.smartloc import read_ground_truth
    data_file("smartloc-berlin", "Berlin_Potsdamer_Platz_Input.txt")
    ds, src, _ = load_dataset("smartloc-berlin-gnss")
    assert ds.raw_gnss.format == "smartloc" and ds.reference.format == "smartloc"
    ds = ds.model_copy(update={"methods": [RawMethod(name="spp", estimator="wls")]})
    from mixnav.experiment.data_folder import find_data_dir
    folder = find_data_dir(ds, None, src)
    po = process_raw(ds, src, folder)
    from mixnav.gnss.pseudoranges import PseudorangeEpochs
    assert po.observations.corrected
    pe = PseudorangeEpochs.from_raw(po.observations)
    assert po.track.ok.all() and len(pe) == 1372
    letters = np.where(pe.system == 1, "G", "R")
    for e in (0, 1, 500, 1000, 1371):
        r = pe.rows_of(e)
        x = _gauss_newton(pe.pseudorange[r], pe.variance[r], pe.sat_ecef[r], letters[r])
        np.testing.assert_allclose(po.track.pos_ecef[e], x[:3], rtol=0, atol=1e-3)
    gt = read_ground_truth(folder / "Berlin_Potsdamer_Platz_GT.txt")
    np.testing.assert_array_equal(gt.time, pe.time)
    assert po.reference.counts["scored"] == 1372
    table = solution_table(po)
    from mixnav.geodesy.frames import ecef_to_lla
    lat, lon, _ = ecef_to_lla(gt.pos_ecef).T
    d = po.track.pos_ecef - gt.pos_ecef
    n = -np.sin(lat) * np.cos(lon) * d[:, 0] - np.sin(lat) * np.sin(lon) * d[:, 1] + np.cos(lat) * d[:, 2]
    e_ = -np.sin(lon) * d[:, 0] + np.cos(lon) * d[:, 1]
    np.testing.assert_allclose(table.err_n_m, n, rtol=0, atol=1e-6)
    np.testing.assert_allclose(table.err_e_m, e_, rtol=0, atol=1e-6)
    m = method_metrics(po, "spp", table)
    assert m["availability"] == 1.0 and m["n_scored"] == 1372
    # an urban canyon: tens of metres (NLOS), not hundreds (a frame or clock slip)
    assert 10.0 < m["horizontal_rmse_m"] < 60.0


def test_one_sample_reference_scores_only_its_epoch(drive):
    """A reference of one sample (at the epoch of 30 s): that epoch is scored, with the
    error from the truth there; the others are before or after it, counted."""
    folder, ex, ant, week, tow = drive
    k = int(np.searchsorted(ex.sim.truth.time, 30.0 - 1e-9))
    write_gps_week_csv(folder / "ref_one.csv", week[k:k + 1], tow[k:k + 1], ant[k:k + 1])
    ds, src, _ = _dataset(folder, 'format = "gps-week-csv"\nfile = "ref_one.csv"', methods=False)
    po = process_raw(ds, src, folder)
    assert po.reference.counts == {"scored": 1, "before_reference": 29, "after_reference": 55,
                                   "in_reference_gaps": 0, "reference_gaps": 0}
    table = solution_table(po)
    e = np.nonzero(np.isfinite(table.err_n_m.to_numpy()))[0]
    assert list(e) == [29]
    np.testing.assert_allclose(table.loc[29, ["err_n_m", "err_e_m", "err_d_m"]].to_numpy(float),
                               _direct_errors(ex, ant, po.track.pos_ecef[29:30], np.array([29]))[0], atol=1e-6)
