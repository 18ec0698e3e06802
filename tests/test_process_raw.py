"""`mixnav process` of a raw-GNSS dataset (android-static): config validation, and
the epoch-by-epoch SPP end to end when ../shared/data is present."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mixnav.cli import app
from mixnav.config import load_dataset
from mixnav.errors import ConfigError

from .conftest import data_file

runner = CliRunner()
DOCS = Path(__file__).resolve().parents[1] / "docs"
LOG = "pseudoranges_log_2016_06_30_21_26_07.txt"
SHIPPED = (Path(__file__).resolve().parents[1] / "src/mixnav/config/datasets/android-static.toml").read_text()


def _cfg(tmp_path, text, name="raw.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_shipped_config_validates():
    ds, src, _ = load_dataset("android-static")
    assert ds.dataset.kind == "gnss-raw" and ds.raw_gnss.format == "android-gnsslogger"
    assert ds.raw_gnss.elevation_mask == pytest.approx(np.deg2rad(10))
    assert ds.raw_gnss.max_sv_time_uncertainty == pytest.approx(5e-7)
    assert ds.reference_point.height == -28.0
    assert not hasattr(ds, "imu") and ds.methods is None
    assert [m.estimator for m in ds.run_methods()] == ["wls"]


@pytest.mark.parametrize("edit, key, message", [
    (('sigma_b = "3 m"', 'sigma_b = "3 m"\nsigma_c = "1 m"'), "raw_gnss.sigma_c", "unknown key"),
    (('elevation_mask = "10 deg"', 'elevation_mask = 10'), "raw_gnss.elevation_mask", "bare number"),
    (('format = "android-gnsslogger"', 'format = "ublox-ubx"'), "raw_gnss.format", "android-gnsslogger"),
    (('height = "-28 m"', 'height = "-28 deg"'), "reference_point.height", "length is expected"),
    (('[raw_gnss]', '[imu]\nformat = "csv"\nfile = "x"\n[raw_gnss]'), "imu", "not used by dataset.kind"),
])
def test_config_errors_name_file_and_key(tmp_path, edit, key, message):
    text = SHIPPED.replace(*edit)
    assert text != SHIPPED
    with pytest.raises(ConfigError, match=message) as ei:
        load_dataset(_cfg(tmp_path, text))
    assert ei.value.key == key and "raw.toml" in str(ei.value)


def test_kind_needs_its_sections(tmp_path):
    text = re.sub(r"\[raw_gnss\].*?\n\n", "", SHIPPED, flags=re.S)
    with pytest.raises(ConfigError, match="required key is missing") as ei:
        load_dataset(_cfg(tmp_path, text))
    assert ei.value.key == "raw_gnss"
    # an INS dataset (the default kind) still needs its IMU
    with pytest.raises(ConfigError, match="required key is missing") as ei:
        load_dataset(_cfg(tmp_path, '[dataset]\nname = "x"\n', "ins.toml"))
    assert ei.value.key == "imu"


def _process(tmp_path, data_dir):
    out = tmp_path / "out"
    res = runner.invoke(app, ["process", "android-static", "--data", str(data_dir), "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out, json.loads((out / "metrics.json").read_text())


def test_android_static_end_to_end(tmp_path):
    folder = data_file("android-static", LOG).parent
    out, m = _process(tmp_path, folder)
    s = m["methods"]["spp"]
    for key in ("horizontal_rmse_m", "horizontal_max_m", "horizontal_p95_m", "vertical_rmse_m",
                "vertical_max_m", "vertical_p95_m"):
        assert np.isfinite(s[key]), key
    assert m["epochs_total"] == 223 and m["epochs_used"] + m["epochs_skipped"] == 223
    assert m["epochs_used"] >= 200
    # a phone's SPP: tens of metres (recorded: 10 m horizontal, 32 m vertical RMSE);
    # a wrong time, clock or Earth-rotation handling gives hundreds of metres or more
    assert 1.0 < s["horizontal_rmse_m"] < 30.0 and s["horizontal_p95_m"] < 50.0
    assert s["vertical_rmse_m"] < 80.0
    assert s["horizontal_max_m"] >= s["horizontal_p95_m"] and s["vertical_max_m"] >= s["vertical_p95_m"]
    assert 4 <= s["n_sat_mean"] <= 12
    csv = pd.read_csv(out / "solution_spp.csv")
    pq = pd.read_parquet(out / "solution_spp.parquet")
    assert len(csv) == len(pq) == 223 and "err_n_m" in csv and "sig_n_m" in pq
    h = np.hypot(csv["err_n_m"], csv["err_e_m"])[csv["status"] == "ok"]
    assert np.sqrt(np.mean(h**2)) == pytest.approx(s["horizontal_rmse_m"], rel=1e-9)
    assert (out / "report.html").exists() and (out / "horizontal_error.png").exists()
    # the map draws the solved epochs (the unsolved have no position)
    from .test_webmap import polylines
    (line,) = polylines((out / "map.html").read_text())
    ok = csv[csv["status"] == "ok"]
    assert len(line) == len(ok)
    np.testing.assert_allclose(line, ok[["lat_deg", "lon_deg"]].to_numpy(), rtol=0, atol=6e-8)
    # and the surveyed point the errors are measured from, with its coordinates in the popup
    from .test_webmap import surveyed_points
    (where, text), = surveyed_points((out / "map.html").read_text())
    rp = load_dataset("android-static")[0].reference_point
    lat, lon = np.degrees([rp.latitude, rp.longitude])
    np.testing.assert_allclose(where, [lat, lon], rtol=0, atol=6e-8)
    assert f"latitude {lat:.7f} deg, longitude {lon:.7f} deg, height {rp.height:.3f} m" in text
    # every metrics key is documented
    doc = (DOCS / "outputs.md").read_text()
    for key in list(m) + list(s):
        assert f"`{key}`" in doc, key


def test_epochs_with_too_few_satellites_are_counted(tmp_path):
    src = data_file("android-static", LOG)
    folder = tmp_path / "data"
    folder.mkdir()
    shutil.copy(src.parent / "hour1820.16n", folder)
    # keep only 3 satellites in the epochs of the first 10 TimeNanos values
    lines = src.read_text().splitlines(keepends=True)
    times = []
    kept = []
    for line in lines:
        if line.startswith("Raw,"):
            f = line.split(",")
            if f[2] not in times:
                times.append(f[2])
            if times.index(f[2]) < 10 and int(f[11]) not in (2, 6, 12):
                continue
        kept.append(line)
    (folder / LOG).write_text("".join(kept))
    out, m = _process(tmp_path, folder)
    assert m["epochs_skipped"] == 10 and m["epoch_status"] == {"ok": 213, "too few satellites": 10}
    assert m["methods"]["spp"]["n_epochs"] == 213
    t = pd.read_csv(out / "solution_spp.csv")
    assert t["lat_deg"][:10].isna().all() and t["lat_deg"][10:].notna().all()


def test_missing_navigation_file_is_a_data_error(tmp_path):
    src = data_file("android-static", LOG)
    folder = tmp_path / "data"
    folder.mkdir()
    shutil.copy(src, folder)
    res = runner.invoke(app, ["process", "android-static", "--data", str(folder), "--out", str(tmp_path / "o")])
    assert res.exit_code != 0 and "hour1820.16n" in res.output and "not found" in res.output
    assert not (tmp_path / "o" / "metrics.json").exists()


def test_reference_point_in_ecef(tmp_path):
    """[reference_point] x, y, z (ECEF, as RINEX headers and survey reports give it) is the
    same point as the geodetic one (lla -> ECEF -> the config -> lla, to 1e-9 rad and 1 mm);
    both forms at once, an incomplete ECEF point, or one far from the Earth's surface are
    errors naming the section."""
    from mixnav.geodesy.frames import lla_to_ecef
    ds, _, _ = load_dataset("android-static")
    rp = ds.reference_point
    x, y, z = lla_to_ecef(np.array([rp.latitude, rp.longitude, rp.height]))
    geo = 'latitude = "37.422578 deg"\nlongitude = "-122.081678 deg"\nheight = "-28 m"'
    assert geo in SHIPPED
    ecef = f'x = "{float(x):.4f} m"\ny = "{float(y):.4f} m"\nz = "{float(z):.4f} m"'
    ds2, _, _ = load_dataset(_cfg(tmp_path, SHIPPED.replace(geo, ecef)))
    r2 = ds2.reference_point
    assert r2.latitude == pytest.approx(rp.latitude, abs=1e-9) and r2.longitude == pytest.approx(rp.longitude, abs=1e-9)
    assert r2.height == pytest.approx(rp.height, abs=1e-3)
    for text, message in ((geo + "\n" + ecef, "not both"), (ecef.rsplit("\n", 1)[0], "all of x, y and z"),
                          (ecef.replace(f"{float(x):.4f} m", f"{float(x):.4f} km"), "Earth's centre")):
        with pytest.raises(ConfigError, match=message) as ei:
            load_dataset(_cfg(tmp_path, SHIPPED.replace(geo, text), "bad.toml"))
        assert ei.value.key.startswith("reference_point"), ei.value.key


def test_missing_ionosphere_coefficients_are_warned_and_reported(tmp_path):
    """A navigation file whose header has no ION ALPHA / ION BETA lines: the ionosphere
    correction is skipped with a warning naming the file, and metrics.json says so
    ("skipped"); with them it says "klobuchar"."""
    from mixnav.experiment.spp_process import ionosphere_applied, process_raw
    from mixnav.io.imu_checks import DataWarning
    folder = data_file("android-static", LOG).parent
    ds, src, _ = load_dataset("android-static")
    nav = folder / ds.raw_gnss.navigation
    lines = nav.read_text().splitlines(keepends=True)
    kept = [ln for ln in lines if "ION ALPHA" not in ln and "ION BETA" not in ln]
    assert len(kept) == len(lines) - 2
    shutil.copy(folder / LOG, tmp_path / LOG)
    (tmp_path / nav.name).write_text("".join(kept))
    with pytest.warns(DataWarning, match=nav.name + ".*ionosphere"):
        po = process_raw(ds, src, tmp_path)
    assert ionosphere_applied(po) == "skipped"
    assert ionosphere_applied(process_raw(ds, src, folder)) == "klobuchar"


def _write_rinex3(path, week, tow, epoch, prn, pseudorange, extra=None):
    """A minimal RINEX 3.03 observation file (C1C only) of these GPS pseudoranges, written
    here (the test's own file, not a vendored one). ``extra``: epoch index -> list of
    (satellite name, C1C value) of other systems (``R07``, ``E11``), written after the GPS
    records of that epoch (the header then lists their systems, type M)."""
    gps0 = np.datetime64("1980-01-06T00:00:00", "ns")
    extra = extra or {}
    systems = sorted({name[0] for recs in extra.values() for name, _ in recs} - {"G"})

    def stamp(k):
        t = gps0 + np.timedelta64(int(round((week[k] * 604800 + tow[k]) * 1e9)), "ns")
        date, clock = str(t).split("T")
        y, mo, d = date.split("-")
        hh, mm, ss = clock.split(":")
        return y, mo, d, hh, mm, float(ss)
    y, mo, d, hh, mm, ss = stamp(0)
    kind = "M (MIXED)" if systems else "G (GPS)"
    head = [(f"     3.03           OBSERVATION DATA    {kind}", "RINEX VERSION / TYPE"),
            ("mixnav test", "PGM / RUN BY / DATE"), ("TEST", "MARKER NAME"), ("G    1 C1C", "SYS / # / OBS TYPES"),
            *[(f"{s}    1 C1C", "SYS / # / OBS TYPES") for s in systems],
            (f"  {y:>4s}    {int(mo):2d}    {int(d):2d}    {int(hh):2d}    {int(mm):2d}   {ss:10.7f}     GPS",
             "TIME OF FIRST OBS"), ("", "END OF HEADER")]
    lines = [f"{a:<60s}{b:<20s}" for a, b in head]
    for k in range(len(tow)):
        sel = epoch == k
        y, mo, d, hh, mm, ss = stamp(k)
        recs = [(f"G{int(p):02d}", r) for p, r in zip(prn[sel], pseudorange[sel])] + list(extra.get(k, []))
        lines.append(f"> {y} {mo} {d} {hh} {mm}{ss:11.7f}  0{len(recs):3d}")
        lines += [f"{name}{r:14.3f}  " for name, r in recs]
    path.write_text("\n".join(lines) + "\n")


def test_rinex_observation_file_gives_the_phone_logs_solution(tmp_path):
    """raw_gnss.format = "rinex-obs": the android-static pseudoranges written as RINEX 3
    (times to 0.1 us, ranges to 1 mm) give the same SPP solutions as the phone log
    (horizontal RMSE within 1 cm, the same epochs solved); a damaged file is a DataError
    naming it."""
    from mixnav.errors import DataError
    from mixnav.experiment.spp_process import process_raw, solution_table
    from mixnav.io.android import read_gnsslogger
    from mixnav.io.rinex_obs import read_rinex_obs
    folder = data_file("android-static", LOG).parent
    ds, src, _ = load_dataset("android-static")
    a = read_gnsslogger(folder / LOG, max_sv_time_uncertainty_ns=ds.raw_gnss.max_sv_time_uncertainty * 1e9)
    _write_rinex3(tmp_path / "phone.rnx", a.week, a.tow, a.epoch, a.prn, a.pseudorange)
    r = read_rinex_obs(tmp_path / "phone.rnx")
    assert r.code == "C1C" and len(r) == len(a)
    np.testing.assert_allclose(r.tow, a.tow, atol=2e-6)
    np.testing.assert_allclose(r.pseudorange, a.pseudorange, atol=6e-4)
    shutil.copy(folder / ds.raw_gnss.navigation, tmp_path)
    text = SHIPPED.replace('format = "android-gnsslogger"', 'format = "rinex-obs"').replace(
        f'file = "{LOG}"', 'file = "phone.rnx"')
    assert "phone.rnx" in text
    ds2, src2, _ = load_dataset(_cfg(tmp_path, text))
    t_a = solution_table(process_raw(ds, src, folder))
    t_r = solution_table(process_raw(ds2, src2, tmp_path))
    assert (t_a.status == "ok").sum() == (t_r.status == "ok").sum() > 200
    ok = t_a.status == "ok"
    h_a = np.sqrt(np.mean(np.hypot(t_a.err_n_m[ok], t_a.err_e_m[ok]) ** 2))
    h_r = np.sqrt(np.mean(np.hypot(t_r.err_n_m[ok], t_r.err_e_m[ok]) ** 2))
    assert abs(h_a - h_r) < 0.01, (h_a, h_r)
    (tmp_path / "bad.rnx").write_text("this is not RINEX\n")
    with pytest.raises(DataError) as e:
        read_rinex_obs(tmp_path / "bad.rnx")
    assert "bad.rnx" in str(e.value)


ROBUST_SPP = """
[[methods]]
name = "spp"
estimator = "wls"

[[methods]]
name = "robust-spp"
estimator = "wls"
[methods.robust]
k0 = 2.5
k1 = 5.0
"""


def test_robust_spp_method_on_the_phone(tmp_path):
    """``wls`` with a ``[methods.robust]`` table is the robust SPP, its own table and metrics
    with the counts. On this phone (6 GPS satellites) an 80 m error on PRN 2 in 30 % of the
    epochs cannot be told from the other rows (test_spp.py has the geometry where it can):
    the robust SPP declines to guess at those epochs (``epochs_not_separable``) and is
    exactly the plain SPP (recorded horizontal RMSE 43.2 m both) rather than worse; a
    ``c`` (the filter's adaptive factor) or a mixture table on ``wls`` is a ConfigError
    naming the key."""
    import dataclasses
    from mixnav.experiment.spp_process import method_metrics, raw_tables, solve_raw
    from .test_raw_filters import _phone
    folder = data_file("android-static", LOG).parent
    ds, src, _ = load_dataset(_cfg(tmp_path, SHIPPED + ROBUST_SPP))
    obs, eph = _phone(ds, folder)
    hit = np.random.default_rng(0).random(len(obs.tow)) < 0.3
    bad = dataclasses.replace(obs, pseudorange=obs.pseudorange + 80.0 * ((obs.prn == 2) & hit[obs.epoch]))
    po = solve_raw(ds, src, folder, bad, eph)
    tables = raw_tables(po)
    m = {name: method_metrics(po, name, t) for name, t in tables.items()}
    rb = m["robust-spp"]["robust"]
    assert rb["epochs_not_separable"] >= hit.sum() * 0.8, rb
    assert sum(v for k, v in rb.items() if k.startswith("epochs_")) == m["robust-spp"]["n_epochs"]
    assert m["robust-spp"]["horizontal_rmse_m"] <= m["spp"]["horizontal_rmse_m"] + 1e-9
    assert "robust" not in m["spp"]
    for edit, key in (("k1 = 5.0\n", "k1 = 5.0\nc = 2.0\n"), ("[methods.robust]\nk0 = 2.5\nk1 = 5.0\n",
                      "[methods.mixture.measurement.pseudorange]\nweights = [1.0]\nscales = [1.0]\n")):
        with pytest.raises(ConfigError) as ei:
            load_dataset(_cfg(tmp_path, SHIPPED + ROBUST_SPP.replace(edit, key), "bad.toml"))
        assert ei.value.key.startswith("methods[1]"), ei.value.key


def test_the_weights_key_reaches_the_spp_and_is_refused_for_smartloc():
    """`[raw_gnss] weights = "rtklib"` is the SppOptions the SPP runs with; a smartLoc log (its
    own variances weigh the rows) refuses it by name."""
    from mixnav.config.loader import load_dataset_text
    from mixnav.errors import ConfigError
    from mixnav.experiment.spp_process import options
    root = Path(__file__).resolve().parents[1] / "src" / "mixnav" / "config" / "datasets"
    text = (root / "urbannav-tst-static.toml").read_text()
    ds, _, _ = load_dataset_text(text.replace("[raw_gnss]\n", "[raw_gnss]\nweights = \"rtklib\"\n", 1), "u.toml")
    assert options(ds).weights == "rtklib"
    ds, _, _ = load_dataset_text(text, "u.toml")
    assert options(ds).weights == "elevation"
    sl = (root / "smartloc-berlin-gnss.toml").read_text().replace("[raw_gnss]\n", "[raw_gnss]\nweights = \"rtklib\"\n", 1)
    with pytest.raises(ConfigError) as e:
        load_dataset_text(sl, "s.toml")
    assert "weights" in str(e.value)
