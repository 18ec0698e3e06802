"""Bad inputs and faults, as a demanding new user tries them (issue 22; docs/validation.md).

Organised by class: configs, data files, units, CLI misuse, output folders,
interruption. Every case asserts the exit status, that the message names the
file and line or key (or the option), and that nothing is left outside
``--out`` and nothing half written (no temporary file or sibling folder).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mixnav.cli import app
from mixnav.config.loader import resolve

from .conftest import DATA_DIR

runner = CliRunner()
SRC = str(Path(__file__).resolve().parents[1] / "src")
DRIVE = DATA_DIR / "drive-0708"
ANDROID = DATA_DIR / "android-static"
SMARTLOC = DATA_DIR / "smartloc-berlin"

# ----------------------------------------------------------------------------- helpers

#: a 60 s version of the demo (about a second per run)
TINY = (resolve("loose-demo")[0]
        .split("segments = [")[0]
        + """segments = [
  { type = "static",     duration = "15 s" },
  { type = "accelerate", duration = "10 s", acceleration = "1.5 m/s^2" },
  { type = "turn",       duration = "9 s",  angle = "90 deg" },
  { type = "uniform",    duration = "26 s" },
]
""" + "[imu]" + resolve("loose-demo")[0].split("[imu]", 1)[1]).replace(
    'outages = [["300 s", "360 s"]]', 'outages = [["40 s", "50 s"]]')


def tiny(**repl) -> str:
    text = TINY
    for old, new in repl.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


def invoke(*args, cwd: Path | None = None):
    """Run the CLI in this process; returns (exit code, all output)."""
    old = os.getcwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        res = runner.invoke(app, [str(a) for a in args])
    finally:
        os.chdir(old)
    return res.exit_code, res.output


def files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


class Sandbox:
    """A folder with the inputs in ``in/`` and ``--out`` at ``out/``; :meth:`check` asserts
    that nothing appeared outside ``out`` and that nothing half written is anywhere."""

    def __init__(self, root: Path):
        self.root = root
        self.inp = root / "in"
        self.inp.mkdir()
        self.out = root / "out"

    def write(self, name: str, content) -> Path:
        p = self.inp / name
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(content)
        return p

    def snapshot(self):
        self.before = files(self.root)

    def check(self):
        now = files(self.root)
        new = {f for f in now - self.before if not f.startswith("out")}
        assert not new, f"written outside --out: {sorted(new)}"
        half = [f for f in now if f.endswith(".tmp") or re.match(r"^\.[^/]*\.(mixnav|old)-", f)]
        assert not half, f"half-written or temporary files left: {half}"


@pytest.fixture
def box(tmp_path):
    b = Sandbox(tmp_path)
    b.snapshot()
    return b


def expect_error(code, output, *names, status=2):
    assert code == status, output
    assert "Traceback" not in output, output
    assert "error" in output.lower(), output
    flat = " ".join(output.split())
    for n in names:
        assert str(n) in flat, f"{n!r} not named in: {output}"


def refuse_run(box, text, *names, name="sc.toml"):
    p = box.write(name, text)
    box.snapshot()
    code, out = invoke("run", p, "--out", box.out, cwd=box.root)
    expect_error(code, out, p, *names)
    assert not box.out.exists()
    box.check()


# ----------------------------------------------------------------------------- configs

@pytest.mark.parametrize("repl, key", [
    ({'start = ["34.4 deg"': 'start = ["95 deg"'}, "trajectory.start"),
    ({'start = ["34.4 deg"': 'start = ["-90 deg"'}, "trajectory.start"),
    ({'"113.5 deg"': '"1e300 deg"'}, "trajectory.start"),
    ({'"113.5 deg"': '"720 deg"'}, "trajectory.start"),
    ({'"100 m"]': '"1e6 m"]'}, "trajectory.start"),
    ({'name = "ekf"': 'name = "../escaped"'}, "methods[0].name"),
    ({'name = "ekf"': 'name = "a/b"'}, "methods[0].name"),
    ({'name = "ekf"': 'name = ""'}, "methods[0].name"),
    ({'name = "ekf"': 'name = "a\\u0000b"'}, "methods[0].name"),
    ({'name = "ekf"': 'name = ".hidden"'}, "methods[0].name"),
    ({'name = "ekf"': 'name = "' + "x" * 300 + '"'}, "methods[0].name"),
    ({'name = "ekf"': 'name = "C:\\\\evil"'}, "methods[0].name"),
    ({'rate = "1 Hz"': 'rate = "1000 Hz"'}, "gnss.rate"),
    ({'rate = "1 Hz"': 'rate = "3 Hz"'}, "gnss.rate"),
    ({'outages = [["40 s", "50 s"]]': 'outages = [["50 s", "500 s"]]'}, "gnss.outages[0]"),
    ({'outages = [["40 s", "50 s"]]': 'outages = [["40 s", "30 s"]]'}, "gnss.outages"),
    ({'position_sigma = ["1.5 m"': 'position_sigma = ["1e300 m"'}, "gnss.position_sigma"),
    ({'position_sigma = ["1.5 m"': 'position_sigma = ["-1 m"'}, "gnss.position_sigma"),
    ({'[[methods]]': '[bogus]\nx = 1\n\n[[methods]]'}, "bogus"),
    ({'states = 15': 'states = 16'}, "methods[0].states"),
    ({'rate = "100 Hz"': 'rate = "0 Hz"'}, "imu.rate"),
    ({'rate = "100 Hz"': 'rate = "1e6 Hz"'}, "imu.rate"),
    ({'rate = "100 Hz"': 'rate = "0.5 Hz"'}, "imu.rate"),     # was blamed on gnss.rate
    ({'rate = "100 Hz"': 'rate = "1e-9 Hz"'}, "imu.rate"),
    ({'"26 s" }': '"1e9 s" }'}, "trajectory.segments"),
    ({'angle = "90 deg"': 'angle = "1e9 deg"'}, "trajectory.segments[2]"),
    ({'lever_arm = ["0.5 m"': 'lever_arm = ["1e9 m"'}, "gnss.lever_arm"),
], ids=lambda v: str(v)[:40])
def test_config_values_refused_with_key(box, repl, key):
    refuse_run(box, tiny(**repl), key)
    assert not list(box.root.rglob("solution_*"))   # no escape anywhere


def test_config_duplicate_method_names(box):
    text = TINY + '\n[[methods]]\nname = "ekf"\ntype = "loose-ekf"\n'
    refuse_run(box, text, "methods", "unique")


@pytest.mark.parametrize("estimator", ["pf", "gmpf"])
def test_config_particles_beyond_memory_name_the_key(box, estimator):
    """A particle cloud larger than the memory available ended in "out of memory" naming no setting;
    refused when the filter is built, with the estimate (particles x (4 x states + 28) x 8 bytes)."""
    text = TINY + (f'\n[[methods]]\nname = "{estimator}"\ntype = "loose-ekf"\nestimator = "{estimator}"\n'
                   "options = { particles = 1000000000000 }\n")
    refuse_run(box, text, "methods[1].options.particles", "1000000000000 particles of 15 states", "GB",
               "memory available")


def test_particle_memory_estimate_and_check(monkeypatch):
    from mixnav.errors import ArgumentError
    from mixnav.filters import particle
    assert particle.particle_memory(1000, 15) == 1000 * 8 * (4 * 15 + 28)
    lay = type("M", (), {"layout": type("L", (), {"n": 15})()})()
    monkeypatch.setattr(particle, "available_memory", lambda: 10 ** 6)
    particle.check_particle_memory(1000, lay)                    # 0.7 MB: fits
    with pytest.raises(ArgumentError, match="particles of 15 states"):
        particle.check_particle_memory(2000, lay)
    monkeypatch.setattr(particle, "available_memory", lambda: None)
    particle.check_particle_memory(10 ** 12, lay)                # the system does not say: no check


@pytest.mark.parametrize("content, words", [
    (b"\x00\x01\x02binary\xff", ["binary", "line 1"]),
    ("[scenario]\nname = \"caf\xe9\"\n".encode("latin-1"), ["UTF-8", "line 2"]),
    (b"[scenario\nname = 1\n", ["TOML", "line 1"]),
    (b"", ["scenario"]),
    (b"[scenario]\nname = 'x'\nname = 'y'\n", ["TOML", "line 3"]),
], ids=["binary", "latin-1", "bad-toml", "empty", "duplicate-key"])
def test_config_files_unreadable(box, content, words):
    refuse_run(box, content, *words)


def test_config_missing_file_and_folder(box):
    box.snapshot()
    code, out = invoke("run", box.inp / "nope.toml", "--out", box.out, cwd=box.root)
    expect_error(code, out, "nope.toml", "no such scenario file")
    (box.inp / "dir.toml").mkdir()
    box.snapshot()
    code, out = invoke("run", box.inp / "dir.toml", "--out", box.out, cwd=box.root)
    expect_error(code, out, "dir.toml")
    box.check()


def _dataset(**repl) -> str:
    text = resolve("android-static", "datasets", "dataset")[0]
    for old, new in repl.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


@pytest.mark.parametrize("repl, key", [
    ({'latitude = "': 'latitude = "1e300 deg" #'}, "reference_point"),
    ({'latitude = "': 'latitude = "91 deg" #'}, "reference_point"),
    ({'height = "': 'height = "-1e5 m" #'}, "reference_point"),
    ({'[raw_gnss]': '[raw_gnss]\nunknown_key = 1'}, "raw_gnss.unknown_key"),
    ({'elevation_mask = "10 deg"': 'elevation_mask = "100 deg"'}, "raw_gnss.elevation_mask"),   # was "no epoch
    ({'elevation_mask = "10 deg"': 'elevation_mask = "90 deg"'}, "raw_gnss.elevation_mask"),    # could be solved"
], ids=["lat-1e300", "lat-91", "height", "unknown-key", "mask-100", "mask-90"])
def test_dataset_values_refused_with_key(box, repl, key):
    p = box.write("ds.toml", _dataset(**repl))
    box.snapshot()
    code, out = invoke("process", p, "--out", box.out, cwd=box.root)
    expect_error(code, out, p, key)
    assert not box.out.exists()
    box.check()


# ----------------------------------------------------------------------------- data files

def _imu_csv(n=6000, rate=100.0, w=None, f=None, header="time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],fz[m/s^2]"):
    t = np.arange(n) / rate
    w = np.zeros((n, 3)) + [0.001, -0.002, 0.0005] if w is None else w
    f = np.zeros((n, 3)) + [0.0, 0.0, -9.8] if f is None else f
    rows = [header] + [f"{t[k]:.3f},{w[k, 0]:.6g},{w[k, 1]:.6g},{w[k, 2]:.6g},{f[k, 0]:.6g},{f[k, 1]:.6g},"
                       f"{f[k, 2]:.6g}" for k in range(n)]
    return rows


def _gnss_csv(n=60, lat=34.4, h=100.0, dt=1.0, sd=1.0):
    rows = ["time[s],lat[deg],lon[deg],height[m],sd_n[m],sd_e[m],sd_d[m]"]
    rows += [f"{(k + 1) * dt:.3f},{lat:.9f},113.5,{h:.3f},{sd},{sd},{2 * sd}" for k in range(n)]
    return rows


DATASET = """[dataset]
name = "static-csv"
data_dir = "."

[imu]
format = "csv"
file = "imu.csv"
grade = "mems"
spike_action = "{spike}"

[gnss]
format = "csv"
file = "gnss.csv"
{gnss_extra}

[alignment]
method = "static"
static_duration = "10 s"
attitude_sigma = ["1 deg", "1 deg", "5 deg"]
velocity_sigma = ["0.1 m/s", "0.1 m/s", "0.1 m/s"]
position_sigma = ["2 m", "2 m", "3 m"]

[[methods]]
name = "ekf"
type = "loose-ekf"
"""


def _process(box, imu_rows, gnss_rows, spike="fail", gnss_extra="", expect=2, names=()):
    box.write("imu.csv", "\n".join(imu_rows) + "\n")
    box.write("gnss.csv", "\n".join(gnss_rows) + "\n")
    ds = box.write("ds.toml", DATASET.format(spike=spike, gnss_extra=gnss_extra))
    box.snapshot()
    code, out = invoke("process", ds, "--data", box.inp, "--out", box.out, cwd=box.root)
    if expect == 0:
        assert code == 0, out
    else:
        expect_error(code, out, *names, status=expect)
        assert not box.out.exists()
    box.check()
    return out


def _bad_line(rows, k, text):
    rows = list(rows)
    rows[k] = text
    return rows


@pytest.mark.parametrize("which, k, make, words", [
    ("imu", 3001, lambda r: r.replace("0.001,", "5000,", 1), ["imu.csv", "line 3002", "spike"]),
    ("imu", 2001, lambda r: "0.5,abc,0,0,0,0,-9.8", ["imu.csv", "line 2002"]),
    ("imu", 2001, lambda r: "1.0,0,0,0,0,0,-9.8", ["imu.csv", "line 2002", "backwards"]),
    ("imu", 2001, lambda r: "19.990,0,0,0,0,0,-9.8", ["imu.csv", "line 2002", "repeats"]),
    ("imu", 2001, lambda r: "20.000,0,0", ["imu.csv", "line 2002"]),
    ("imu", 2001, lambda r: "20.000,nan,0,0,0,0,-9.8", ["imu.csv", "line 2002"]),
    ("gnss", 11, lambda r: r.replace(",1.0,1.0,2.0", ",-1,1.0,2.0"), ["gnss.csv", "line 12"]),
    ("gnss", 11, lambda r: r.replace(",1.0,1.0,2.0", ",1e300,1.0,2.0"), ["gnss.csv", "line 12"]),
    ("gnss", 11, lambda r: r.replace("34.400000000", "95.0"), ["gnss.csv", "line 12", "latitude"]),
    ("gnss", 11, lambda r: r.replace(",100.000,", ",1e9,"), ["gnss.csv", "line 12", "height"]),
    ("gnss", 11, lambda r: "10.000,34.4,113.5,100,1,1,2", ["gnss.csv", "line 12", "repeats"]),
    ("gnss", 1, lambda r: r + ",7", ["gnss.csv", "line 2"]),
], ids=["imu-spike", "imu-text", "imu-backwards", "imu-duplicate", "imu-short-line", "imu-nan",
        "gnss-negative-sigma", "gnss-huge-sigma", "gnss-lat-95", "gnss-height", "gnss-duplicate",
        "gnss-extra-field"])
def test_data_file_errors_name_file_and_line(box, which, k, make, words):
    imu, gnss = _imu_csv(), _gnss_csv()
    if which == "imu":
        imu = _bad_line(imu, k, make(imu[k]))
    else:
        gnss = _bad_line(gnss, k, make(gnss[k]))
    _process(box, imu, gnss, names=words)


def test_data_truncated_mid_line_and_empty(box):
    imu = _imu_csv()
    box.write("imu.csv", "\n".join(imu)[:-9])   # the last line cut in the middle
    box.write("gnss.csv", "\n".join(_gnss_csv()) + "\n")
    ds = box.write("ds.toml", DATASET.format(spike="fail", gnss_extra=""))
    box.snapshot()
    code, out = invoke("process", ds, "--data", box.inp, "--out", box.out, cwd=box.root)
    expect_error(code, out, "imu.csv", f"line {len(imu)}")
    box.write("imu.csv", "\n".join(imu) + "\n")
    box.write("gnss.csv", "")
    code, out = invoke("process", ds, "--data", box.inp, "--out", box.out, cwd=box.root)
    expect_error(code, out, "gnss.csv")
    box.check()


def test_data_non_utf8_bytes(box):
    imu = "\n".join(_imu_csv()).encode() + b"\n"
    imu = imu.replace(b"\n20.000,", b"\n2\xff.000,", 1)
    box.write("imu.csv", imu)
    box.write("gnss.csv", "\n".join(_gnss_csv()) + "\n")
    ds = box.write("ds.toml", DATASET.format(spike="fail", gnss_extra=""))
    box.snapshot()
    code, out = invoke("process", ds, "--data", box.inp, "--out", box.out, cwd=box.root)
    expect_error(code, out, "imu.csv", "line 2002")
    box.check()


def test_data_spike_rejected_counted_and_gap_reported(box):
    """spike_action = "reject": replaced and counted; a GNSS hole listed in metrics.json."""
    imu = _imu_csv()
    imu[3001] = imu[3001].replace("0.001,", "5000,", 1)
    gnss = [r for r in _gnss_csv() if not (25.0 <= float(r.split(",")[0] if r[0].isdigit() else -1) <= 40.0)]
    out = _process(box, imu, gnss, spike="reject", expect=0)
    m = json.loads((box.out / "metrics.json").read_text())
    assert m["imu_spikes_rejected"] == 2   # the two increments the spike sample ends and opens
    assert m["gnss_gaps_s"] == [[24.0, 41.0]]
    assert "warning" in out and "gnss.max_gap" in out
    sol = pd.read_csv(box.out / "solution_ekf.csv")
    assert np.isfinite(sol.select_dtypes("number").to_numpy()).all()


def test_data_gnss_gap_fail(box):
    gnss = [r for r in _gnss_csv() if not r.startswith(("30.", "31.", "32.", "33.", "34.", "35.", "36."))]
    _process(box, _imu_csv(), gnss, gnss_extra='gap_action = "fail"', names=["gnss.csv", "gnss.max_gap"])


def test_data_gnss_in_another_time_base(box):
    gnss = [r if not r[0].isdigit() else f"{float(r.split(',')[0]) + 400000:.3f}," + r.split(",", 1)[1]
            for r in _gnss_csv()]
    _process(box, _imu_csv(), gnss, names=["gnss.csv", "time span"])


def test_data_withhold_outside_the_data(box):
    _process(box, _imu_csv(), _gnss_csv(), gnss_extra='withhold = [["500 s", "600 s"]]',
             names=["ds.toml", "gnss.withhold[0]"])


# --- real files (copies; skipped without the shared data)

needs_drive = pytest.mark.skipif(not DRIVE.is_dir(), reason="drive-0708 data not found")
needs_android = pytest.mark.skipif(not ANDROID.is_dir(), reason="android-static data not found")
needs_smartloc = pytest.mark.skipif(not SMARTLOC.is_dir(), reason="smartloc-berlin data not found")


def _drive_copy(box) -> Path:
    d = box.inp / "drive"
    d.mkdir()
    for f in ("imu_1934.csv", "imu_1934.csv.tag", "gnss_1934_sf.pos"):
        shutil.copy(DRIVE / f, d / f)
    return d


@needs_drive
def test_real_truncated_tag_refused(box):
    d = _drive_copy(box)
    b = (d / "imu_1934.csv.tag").read_bytes()
    n = (len(b) - 76) // 8
    (d / "imu_1934.csv.tag").write_bytes(b[:76 + 8 * (n // 3)])   # record-aligned cut
    box.snapshot()
    code, out = invoke("process", "drive-0708-plain", "--data", d, "--out", box.out, cwd=box.root)
    expect_error(code, out, "imu_1934.csv.tag", "truncated")
    box.check()


@needs_drive
def test_real_tag_truncated_slightly_refused(box):
    """A record-aligned cut of 0.8 % of the tag (4.4 s) was within the old 1 % tolerance: the IMU
    time was stretched and the run ended normally (72 m RMSE instead of 5 m)."""
    d = _drive_copy(box)
    b = (d / "imu_1934.csv.tag").read_bytes()
    n = (len(b) - 76) // 8
    (d / "imu_1934.csv.tag").write_bytes(b[:76 + 8 * int(n * 0.992)])
    box.snapshot()
    code, out = invoke("process", "drive-0708-plain", "--data", d, "--out", box.out, cwd=box.root)
    expect_error(code, out, "imu_1934.csv.tag", "truncated", "548.590 s")
    box.check()


@needs_drive
@pytest.mark.parametrize("cut, where", [
    (lambda s: s[:-4], "the last line (line 54860)"),          # the tick cut: "810496" -> "810"
    (lambda s: s[8:], "the first line (line 1)"),               # six fields left
    (lambda s: s[8:-4], "the first line (line 1) and the last line (line 54860)"),
], ids=["last-tick-cut", "first", "both"])
def test_real_partial_edge_lines_skipped_and_counted(box, cut, where):
    """The data README: the first and last lines may be partial, skip them. A last line cut in its
    tick was read as whole and refused as "ticks do not increase"."""
    d = _drive_copy(box)
    p = d / "imu_1934.csv"
    p.write_text(cut(p.read_text()))
    box.snapshot()
    code, out = invoke("process", "drive-0708-plain", "--data", d, "--out", box.out, cwd=box.root)
    assert code == 0, out
    flat = " ".join(out.split())
    assert "imu_1934.csv" in flat and where in flat and "partial" in flat, out
    m = json.loads((box.out / "metrics.json").read_text())
    assert m["imu_partial_lines_skipped"] == where.count("line (")
    box.check()


@needs_drive
def test_real_partial_line_inside_refused_with_line(box):
    d = _drive_copy(box)
    lines = (d / "imu_1934.csv").read_text().splitlines(keepends=True)
    lines[3000] = lines[3000][:12] + "\n"
    (d / "imu_1934.csv").write_text("".join(lines))
    box.snapshot()
    code, out = invoke("process", "drive-0708-plain", "--data", d, "--out", box.out, cwd=box.root)
    expect_error(code, out, "imu_1934.csv", "line 3001", "partial line inside")
    box.check()


@needs_drive
def test_real_gyro_spike_refused_with_line(box):
    d = _drive_copy(box)
    lines = (d / "imu_1934.csv").read_text().splitlines(keepends=True)
    parts = lines[5000].split(",")
    parts[4] = "5000.0"
    lines[5000] = ",".join(parts)
    (d / "imu_1934.csv").write_text("".join(lines))
    box.snapshot()
    code, out = invoke("process", "drive-0708-plain", "--data", d, "--out", box.out, cwd=box.root)
    expect_error(code, out, "imu_1934.csv", "line 5001", "spike")
    box.check()


@needs_drive
def test_real_gnss_hole_reported(box):
    d = _drive_copy(box)
    lines = (d / "gnss_1934_sf.pos").read_text().splitlines(keepends=True)
    head = [ln for ln in lines if ln.startswith("%")]
    data = [ln for ln in lines if not ln.startswith("%")]
    data = data[:1800] + data[2040:]            # 60 s of 4 Hz epochs removed, outside the withheld windows
    (d / "gnss_1934_sf.pos").write_text("".join(head + data))
    box.snapshot()
    code, out = invoke("process", "drive-0708-plain", "--data", d, "--out", box.out, cwd=box.root)
    assert code == 0, out
    m = json.loads((box.out / "metrics.json").read_text())
    assert len(m["gnss_gaps_s"]) == 1 and m["gnss_gaps_s"][0][1] - m["gnss_gaps_s"][0][0] > 59
    assert not any(a <= m["gnss_gaps_s"][0][0] <= b for a, b in m["gnss_withheld_s"])
    flat = " ".join(out.split())
    assert "warning" in flat and "gnss_1934_sf.pos" in flat and "gnss.max_gap" in flat, out
    box.check()


@needs_android
def test_real_android_duplicated_epoch_refused(box):
    d = box.inp / "android"
    d.mkdir()
    for f in ANDROID.iterdir():
        shutil.copy(f, d / f.name)
    log = d / "pseudoranges_log_2016_06_30_21_26_07.txt"
    lines = log.read_text().splitlines(keepends=True)
    raw = [i for i, ln in enumerate(lines) if ln.startswith("Raw,")]
    k = raw[len(raw) // 2]
    lines.insert(k + 1, lines[k])                # the same measurement twice
    log.write_text("".join(lines))
    box.snapshot()
    code, out = invoke("process", "android-static", "--data", d, "--out", box.out, cwd=box.root)
    expect_error(code, out, log.name, f"line {k + 2}", "twice")
    box.check()


def _smartloc_copy(box) -> Path:
    d = box.inp / "smartloc"
    d.mkdir()
    for f in SMARTLOC.iterdir():
        if f.is_file():
            shutil.copy(f, d / f.name)
    return d


@needs_smartloc
@pytest.mark.parametrize("value, words", [
    ("nan", ["not finite"]),
    ("", ["empty", "non-finite"]),          # a NaN written as nothing (pandas): was "has 11 fields, found 10"
], ids=["nan", "nan-as-nothing"])
def test_real_smartloc_nan_pseudorange_named(box, value, words):
    d = _smartloc_copy(box)
    inp = d / "Berlin_Potsdamer_Platz_Input.txt"
    lines = inp.read_text().splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if ln.startswith("pseudorange3"))
    toks = lines[k].split(" ")
    toks[2] = value                              # the pseudorange (column 3)
    lines[k] = " ".join(toks)
    inp.write_text("".join(lines))
    box.snapshot()
    code, out = invoke("process", "smartloc-berlin", "--data", d, "--out", box.out, cwd=box.root)
    expect_error(code, out, inp.name, f"line {k + 1}", "column 3", *words)
    box.check()


@needs_smartloc
@pytest.mark.parametrize("drop, words, key", [
    (lambda t: t > 150.0, ["the odometry ends at t = 150.0 s", "282.8 s"], "pseudorange_epochs_after_odometry"),
    (lambda t: 100.0 < t < 160.0, ["hole", "from t = 100.0 s", "holds the last speed"], "odometry_gaps_s"),
], ids=["odometry-stops", "odometry-hole"])
def test_real_smartloc_odometry_stops_while_pseudoranges_go_on(box, drop, words, key):
    """The dead reckoning held the last odometry across a hole, or the solution ended with the
    odometry while the pseudoranges went on, without a word."""
    d = _smartloc_copy(box)
    inp = d / "Berlin_Potsdamer_Platz_Input.txt"
    lines = inp.read_text().splitlines(keepends=True)
    inp.write_text("".join(ln for ln in lines if not (ln.startswith("odom3") and drop(float(ln.split()[1])))))
    box.snapshot()
    code, out = invoke("process", "smartloc-berlin", "--data", d, "--out", box.out, "--no-sweeps", cwd=box.root)
    assert code == 0, out
    flat = " ".join(out.split())
    assert "warning" in flat and inp.name in flat, out
    for w in words:
        assert w in flat, out
    m = json.loads((box.out / "metrics.json").read_text())
    assert m[key]
    box.check()


# ----------------------------------------------------------------------------- units

@pytest.mark.parametrize("repl, key", [
    ({'rate = "1 Hz"': 'rate = "1 m"'}, "gnss.rate"),
    ({'"100 m"]': '100]'}, "trajectory.start"),
    ({'"100 m"]': '"1e999 m"]'}, "trajectory.start"),
    ({'"100 m"]': '"5 furlongs"]'}, "trajectory.start"),
    ({'attitude = ["0 deg"': 'attitude = ["nan deg"'}, "trajectory.attitude"),
    ({'speed = "0 m/s"': 'speed = "0 deg/s"'}, "trajectory.speed"),
], ids=["hz-as-m", "bare-number", "overflow", "unknown-unit", "nan", "wrong-dimension"])
def test_unit_errors_name_the_key(box, repl, key):
    refuse_run(box, tiny(**repl), key)


def _moving_imu(declared: str, scale: float):
    """A vehicle's IMU (turning at up to 0.3 rad/s, accelerating +-2 m/s^2), written in
    ``scale`` x rad/s under the header unit ``declared``."""
    n = 6000
    t = np.arange(n) / 100.0
    w = np.column_stack([0.02 * np.sin(t), 0.02 * np.cos(t), 0.3 * np.sin(0.3 * t)]) * scale
    f = np.column_stack([2.0 * np.sin(0.2 * t), 0.5 * np.cos(0.3 * t), -9.8 + 1.0 * np.sin(5 * t)])
    return _imu_csv(w=w, f=f, header=f"time[s],wx[{declared}],wy[{declared}],wz[{declared}],"
                                     "fx[m/s^2],fy[m/s^2],fz[m/s^2]")


@pytest.mark.parametrize("imu, words", [
    (lambda: _moving_imu("deg/s", 1.0), ["imu.csv", "rad/s declared as deg/s"]),
    (lambda: _moving_imu("rad/s", np.degrees(1.0) * 20), ["imu.csv", "deg/s declared as rad/s"]),
    (lambda: [r.replace("m/s^2", "g") if i == 0 else r for i, r in enumerate(_imu_csv())],
     ["imu.csv", "gravity"]),
    (lambda: [r.replace("wx[deg/s]", "wx[m]") if i == 0 else r for i, r in enumerate(_imu_csv())],
     ["imu.csv", "line 1", "wx"]),
], ids=["rad-as-deg", "deg-as-rad", "g-as-mps2", "header-dimension"])
def test_unit_plausibility_of_data(box, imu, words):
    _process(box, imu(), _gnss_csv(), names=words)


# ----------------------------------------------------------------------------- CLI misuse

@pytest.mark.parametrize("args, words", [
    (["experiment", "loose-demo", "--runs", str(10 ** 9)], ["--runs", "at most"]),
    (["experiment", "loose-demo", "--runs", "0"], ["--runs"]),
    (["experiment", "loose-demo", "--runs", "2", "--workers", "0"], ["--workers"]),
    (["experiment", "loose-demo", "--runs", "2", "--seeds-from", "-1"], ["--seeds-from"]),
    (["experiment", "loose-demo", "--runs", "2", "--seeds-from", str(10 ** 23)], ["--seeds-from"]),
    (["experiment", "loose-demo", "--runs", "2", "--resume", "--overwrite"], ["--resume", "--overwrite"]),
    (["experiment", "loose-demo", "--runs", "2", "--scheduler", " "], ["--scheduler"]),
    (["run", "no-such-scenario"], ["unknown scenario", "no-such-scenario"]),
    (["run", "../etc/passwd"], ["passwd"]),
    (["run", "loose\x00demo"], ["not a scenario name"]),
    (["process", "no-such-dataset"], ["unknown dataset"]),
    (["process", "drive-0708-plain", "--data", "/nonexistent/folder"], ["/nonexistent/folder"]),
    (["run", "loose-demo", "--seed", "-1"], ["--seed"]),
    (["run", "loose-demo", "--bogus"], ["--bogus"]),
], ids=["runs-1e9", "runs-0", "workers-0", "seeds-from", "seeds-from-1e23", "resume-overwrite", "scheduler",
        "unknown-scenario", "path-escape", "nul-name", "unknown-dataset", "no-data", "seed", "option"])
def test_cli_misuse(box, args, words):
    box.snapshot()
    code, out = invoke(*args, *([] if "--out" in args else ["--out", box.out]), cwd=box.root)
    assert code == 2, out
    assert "Traceback" not in out
    flat = " ".join(out.split())
    for w in words:
        assert w in flat, out
    assert not box.out.exists()
    box.check()


def _series(box, n=100):
    return box.write("res.csv", "t,res\n" + "".join(f"{i},{v}\n" for i, v in
                                                   enumerate(np.random.default_rng(1).standard_normal(n))))


@pytest.mark.parametrize("extra, words", [
    (["--column", "res", "--max-lag", "500"], ["--max-lag", "100"]),
    (["--column", "res", "--components", "1000"], ["--components"]),
    (["--column", "nope"], ["res.csv", "nope"]),
], ids=["max-lag", "components", "column"])
def test_cli_diagnose_misuse(box, extra, words):
    p = _series(box)
    box.snapshot()
    code, out = invoke("diagnose", p, *extra, "--out", box.out, cwd=box.root)
    expect_error(code, out, *words)
    assert not box.out.exists()
    box.check()


def _documented_examples():
    """The rows of docs/validation.md's "Examples the tests feed to the validator" table."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "validation.md").read_text(encoding="utf-8")
    part = doc.split("## Examples the tests feed to the validator", 1)[1].split("\n## ", 1)[0]
    rows = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in part.splitlines()
            if ln.startswith("| ") and not ln.startswith("| input") and not ln.startswith("| ---")]
    assert len(rows) >= 10, rows
    return rows


@pytest.mark.parametrize("what, example, outcome", _documented_examples(), ids=lambda v: str(v)[:24])
def test_documented_examples_agree_with_validation(box, what, example, outcome):
    """Every documented example of accepted (and refused) input is fed to the validator: method
    names with non-ASCII letters were "letters" in the docs and refused by the validation."""
    assert outcome in ("accepted", "refused")
    if what == "method name":
        name = example.strip("`")
        p = box.write("sc.toml", tiny(**{'name = "ekf"': f'name = "{name}"'}))
        from mixnav.config.loader import load_scenario
        from mixnav.errors import ConfigError
        if outcome == "accepted":
            load_scenario(str(p))
        else:
            with pytest.raises(ConfigError) as ei:
                load_scenario(str(p))
            assert ei.value.key == "methods[0].name" and "ASCII" in ei.value.message
        return
    m = re.match(r"`diagnose --max-lag`, (\d+) values", what)
    assert m, what
    p = _series(box, int(m.group(1)))
    lag = [] if example.startswith("(") else ["--max-lag", example.strip("`")]
    box.snapshot()
    code, out = invoke("diagnose", p, "--column", "res", *lag, "--out", box.out, cwd=box.root)
    if outcome == "accepted":
        assert code == 0, out
        if not lag:   # the default, clipped
            assert json.loads((box.out / "diagnostics.json").read_text())["acf"]["max_lag"] == int(m.group(1)) - 1
    else:
        expect_error(code, out, "--max-lag", m.group(1))
        assert not box.out.exists()
    box.check()


@pytest.mark.parametrize("make, words", [
    (lambda b: b.write("afile", "x"), ["--out", "not a folder"]),
    (lambda b: "bad\x00name", ["--out", "null byte"]),
    (lambda b: b.root / ("x" * 300), ["--out", "255"]),
], ids=["file", "nul", "too-long"])
def test_cli_bad_out(box, make, words):
    out_arg = make(box)
    box.snapshot()
    p = box.write("sc.toml", TINY)
    box.snapshot()
    code, out = invoke("run", p, "--out", out_arg, cwd=box.root)
    expect_error(code, out, *words)
    box.check()


def test_cli_debug_shows_traceback_and_internal_errors_are_one_line(box, monkeypatch):
    p = box.write("sc.toml", TINY)
    box.snapshot()
    import mixnav.experiment.run as run_mod

    def boom(*a, **k):
        raise RuntimeError("simulated bug")
    monkeypatch.setattr(run_mod, "run_scenario", boom)
    code, out = invoke("run", p, "--out", box.out, cwd=box.root)
    assert code == 3 and "internal error" in out and "simulated bug" in out and "Traceback" not in out
    code, out = invoke("--debug", "run", p, "--out", box.out, cwd=box.root)
    assert code == 1   # the exception propagates: CliRunner keeps it
    assert not box.out.exists()
    box.check()


# ----------------------------------------------------------------------------- output folders

def _run(box, text=TINY, *extra, out=None):
    p = box.inp / "sc.toml"
    if not p.exists() or p.read_text() != text:
        box.write("sc.toml", text)
    return invoke("run", p, "--out", out or box.out, *extra, cwd=box.root)


def test_out_same_command_is_replaced_whole(box):
    two = TINY + '\n[[methods]]\nname = "second"\ntype = "loose-ekf"\n'
    code, out = _run(box, two)
    assert code == 0, out
    assert (box.out / "solution_second.csv").exists()
    box.snapshot()
    code, out = _run(box, TINY)
    assert code == 0, out
    assert not (box.out / "solution_second.csv").exists()     # nothing of the old run mixed in
    assert (box.out / "solution_ekf.csv").exists() and (box.out / "metrics.json").exists()
    box.check()


def test_out_foreign_files_refused_then_overwrite_clears(box):
    box.out.mkdir()
    (box.out / "notes.txt").write_text("mine")
    box.write("sc.toml", TINY)
    box.snapshot()
    code, out = _run(box)
    expect_error(code, out, "--out", "notes.txt", "--overwrite")
    assert (box.out / "notes.txt").read_text() == "mine" and len(list(box.out.iterdir())) == 1
    code, out = _run(box, TINY, "--overwrite")
    assert code == 0, out
    assert not (box.out / "notes.txt").exists() and (box.out / "metrics.json").exists()
    box.check()


def test_out_run_folder_plus_a_foreign_file_refused(box):
    assert _run(box)[0] == 0
    (box.out / "extra.csv").write_text("1")
    before = files(box.out)
    code, out = _run(box)
    expect_error(code, out, "extra.csv", "--overwrite")
    assert files(box.out) == before


def test_out_experiment_into_run_folder_and_back(box):
    assert _run(box)[0] == 0
    before = files(box.out)
    p = box.inp / "sc.toml"
    code, out = invoke("experiment", p, "--runs", "1", "--workers", "1", "--out", box.out, cwd=box.root)
    expect_error(code, out, "mixnav run", "--overwrite")
    assert files(box.out) == before
    exp = box.root / "exp"
    code, out = invoke("experiment", p, "--runs", "1", "--workers", "1", "--no-progress", "--no-figures",
                       "--out", exp, cwd=box.root)
    assert code == 0, out
    before = files(exp)
    code, out = invoke("run", p, "--out", exp, cwd=box.root)
    expect_error(code, out, "mixnav experiment", "--overwrite")
    assert files(exp) == before
    code, out = invoke("diagnose", box.out / "solution_ekf.csv", "--column", "err_n_m", "--out", exp,
                       cwd=box.root)
    expect_error(code, out, "mixnav experiment")
    assert files(exp) == before


def test_out_overwrite_refused_for_the_current_folder(box):
    (box.root / "keep.txt").write_text("x")
    p = box.write("sc.toml", TINY)
    box.snapshot()
    code, out = invoke("run", p, "--out", ".", "--overwrite", cwd=box.root)
    expect_error(code, out, "--out", "current folder")
    assert (box.root / "keep.txt").exists()
    box.check()


def test_out_overwrite_refused_when_it_holds_the_input(box):
    p = box.write("sc.toml", TINY)
    box.snapshot()
    code, out = invoke("run", p, "--out", box.inp, "--overwrite", cwd=box.root)
    expect_error(code, out, "--out", "sc.toml")
    assert p.exists()
    box.check()


def test_out_files_follow_the_umask(box):
    old = os.umask(0o027)
    try:
        code, out = _run(box)
    finally:
        os.umask(old)
    assert code == 0, out
    # the mode is read once at import: compare with what the process's umask was then
    from mixnav.io.atomic import default_mode
    modes = {oct(p.stat().st_mode & 0o777) for p in box.out.iterdir()}
    assert modes == {oct(default_mode())}, modes
    assert default_mode() != 0o600


def _experiment(box, *extra, runs=2):
    p = box.inp / "sc.toml"
    if not p.exists():
        box.write("sc.toml", TINY)
    # without figures: these tests are about the records and the folder (figures: tests/test_cli.py)
    return invoke("experiment", p, "--runs", runs, "--workers", "1", "--no-progress", "--no-figures",
                  "--out", box.out, *extra, cwd=box.root)


def test_resume_redoes_a_planted_record_of_another_scenario(box):
    assert _experiment(box)[0] == 0
    other = box.root / "other"
    box.write("other.toml", tiny(**{'seed = 1': 'seed = 7', 'rate = "1 Hz"': 'rate = "2 Hz"'}))
    assert invoke("experiment", box.inp / "other.toml", "--runs", "2", "--workers", "1", "--no-progress", "--no-figures",
                  "--out", other, cwd=box.root)[0] == 0
    shutil.copy(other / "runs" / "run_1.parquet", box.out / "runs" / "run_1.parquet")
    code, out = _experiment(box, "--resume")
    assert code == 0, out
    assert "run_1.parquet" in out and "redone" in out
    rec = pd.read_parquet(box.out / "runs" / "run_1.parquet")
    man = json.loads((box.out / "manifest.json").read_text())
    assert set(rec["scenario_sha256"]) == {man["scenario_sha256"]}


def test_resume_recreates_a_deleted_series_and_a_truncated_record(box):
    assert _experiment(box)[0] == 0
    (box.out / "runs" / "series_0.parquet").unlink()
    rec = box.out / "runs" / "run_1.parquet"
    rec.write_bytes(rec.read_bytes()[:100])
    code, out = _experiment(box, "--resume")
    assert code == 0, out
    assert (box.out / "runs" / "series_0.parquet").exists()
    assert len(pd.read_parquet(rec)) == 1
    assert "Traceback" not in out
    assert json.loads((box.out / ".mixnav-output.json").read_text())["complete"] is True


def test_resume_keeps_valid_records_of_smoothed_methods(box):
    box.write("sc.toml", TINY.replace('covariance_interval = "1 s"', 'covariance_interval = "1 s"\nsmooth = true'))
    assert _experiment(box, runs=1)[0] == 0
    rec = box.out / "runs" / "run_0.parquet"
    assert "ekf-smoothed" in set(pd.read_parquet(rec)["method"])
    t = rec.stat().st_mtime_ns
    code, out = _experiment(box, "--resume", runs=1)
    assert code == 0 and "redone" not in out, out
    assert rec.stat().st_mtime_ns == t


@pytest.mark.parametrize("name", ["notes.txt", "run_99.parquet"])
def test_resume_refuses_files_not_of_the_experiment(box, name):
    assert _experiment(box, runs=1)[0] == 0
    (box.out / "runs" / name).write_text("x")
    code, out = _experiment(box, "--resume", runs=1)
    expect_error(code, out, name)


def test_experiment_folder_refused_without_resume_and_cleared_with_overwrite(box):
    assert _experiment(box)[0] == 0
    code, out = _experiment(box)
    expect_error(code, out, "--resume")
    code, out = _experiment(box, "--overwrite", runs=1)
    assert code == 0, out
    assert sorted(p.name for p in (box.out / "runs").glob("run_*")) == ["run_0.parquet"]


# ----------------------------------------------------------------------------- interruption

def _cli(*args, cwd, env=None):
    return subprocess.Popen([sys.executable, "-m", "mixnav.cli", *map(str, args)], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": SRC, **(env or {})}, start_new_session=True)


def _wait_for(pred, timeout=60.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if pred():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.parametrize("sig, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_interrupted_rewrite_keeps_the_old_complete_folder(box, sig, status):
    assert _run(box)[0] == 0
    old = {p.name: p.read_bytes() for p in box.out.iterdir()}
    long = resolve("loose-demo")[0]      # 600 s: long enough to be interrupted
    p = box.write("long.toml", long)
    box.snapshot()
    proc = _cli("run", p, "--out", box.out, cwd=box.root)
    # interrupted as soon as it writes its temporary sibling (writing the folder, figures
    # included, takes over a second: a fixed wait after it let a fast machine finish first);
    # still running without one after 60 s (a cold cache compiling): interrupted while running
    _wait_for(lambda: any(".mixnav-" in n for n in os.listdir(box.root)), timeout=60)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("the run finished before the signal")
    assert proc.returncode == status, err
    assert "Traceback" not in err and "interrupted" in err
    assert {p.name: p.read_bytes() for p in box.out.iterdir()} == old   # the old complete folder
    box.check()


def _children(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:   # a zombie has ended
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_experiment_workers_end_with_their_parent(box, sig):
    p = box.write("long.toml", resolve("loose-demo")[0])
    proc = _cli("experiment", p, "--runs", "4", "--workers", "2", "--no-progress", "--out", box.out,
                cwd=box.root)
    assert _wait_for(lambda: len(_children(proc.pid)) >= 2, timeout=60), proc.communicate()[1]
    time.sleep(1.0)
    kids = _children(proc.pid)
    proc.send_signal(sig)
    proc.communicate(timeout=60)
    assert _wait_for(lambda: not any(_alive(k) for k in kids), timeout=15), \
        f"workers still running: {[k for k in kids if _alive(k)]}"
    for k in kids:   # in case: never leave them behind
        if _alive(k):
            os.kill(k, signal.SIGKILL)
    if sig == signal.SIGTERM:
        assert proc.returncode == 143
    # whatever finished is complete: each record readable; no temporary file is left after a TERM
    for f in (box.out / "runs").glob("run_*.parquet"):
        assert len(pd.read_parquet(f))
    if sig == signal.SIGTERM:
        assert not [f for f in files(box.out) if f.endswith(".tmp")]


def test_numba_cache_unwritable_falls_back_with_one_warning(tmp_path):
    """No writable cache folder: one warning, the kernels compile without a cache."""
    code = (
        "import warnings, mixnav\n"
        "mixnav._numba_cache_usable = lambda: False\n"
        "from numba.core import caching\n"
        "def nope(self): raise PermissionError('read-only')\n"
        "caching._CacheLocator.ensure_cache_path = nope\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    mixnav._numba_without_cache()\n"
        "    mixnav._numba_without_cache()\n"
        "    import numba\n"
        "    @numba.njit(cache=True)\n"
        "    def f(x):\n"
        "        return x + 1\n"
        "    assert f(1) == 2\n"
        "print(sum('numba' in str(x.message) for x in w))\n")
    src = tmp_path / "probe.py"
    src.write_text(code)
    res = subprocess.run([sys.executable, str(src)], capture_output=True, text=True, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": SRC})
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "1"
    assert "Traceback" not in res.stderr


def test_interrupt_inside_the_writer_leaves_no_trace(box, monkeypatch):
    """A KeyboardInterrupt while the files are written: the old folder stays whole."""
    assert _run(box)[0] == 0
    old = {p.name: p.read_bytes() for p in box.out.iterdir()}
    import mixnav.experiment.outputs as run_mod
    real = run_mod.atomic_write_dataframe
    calls = []

    def interrupted(path, df):
        calls.append(path)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(path, df)
    monkeypatch.setattr(run_mod, "atomic_write_dataframe", interrupted)
    box.snapshot()
    code, out = _run(box)
    assert code == 130 and "interrupted" in out
    assert {p.name: p.read_bytes() for p in box.out.iterdir()} == old
    box.check()


def test_no_write_lands_outside_the_folder(tmp_path):
    """The writer's own guard, below the schema's name rule."""
    from mixnav.errors import ArgumentError
    from mixnav.io.outdir import OutputFolder
    f = OutputFolder(tmp_path)
    for bad in ("../x.csv", "a/b.csv", "..", "", ".hidden", "x\x00y", "y" * 300):
        with pytest.raises(ArgumentError):
            f.file(bad)
    (tmp_path / "link").symlink_to("/tmp")
    with pytest.raises(ArgumentError, match="outside"):
        f.file("link", "x.csv")
    assert re.match(r".*/ok\.csv$", str(f.file("ok.csv")))


def test_full_disk_is_one_line_and_keeps_the_old_folder(box, monkeypatch):
    import errno
    assert _run(box)[0] == 0
    old = {p.name: p.read_bytes() for p in box.out.iterdir()}
    import mixnav.experiment.outputs as run_mod

    def full(path, df):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))
    monkeypatch.setattr(run_mod, "atomic_write_dataframe", full)
    box.snapshot()
    code, out = _run(box)
    expect_error(code, out, "No space left on device", "solution_ekf.csv")
    assert {p.name: p.read_bytes() for p in box.out.iterdir()} == old
    box.check()


# ----------------------------------------------------------------------------- counting and consistency

def test_gnss_used_when_output_epochs_miss_the_gnss_epochs():
    """Outputs between GNSS epochs: gnss_used marks an update since the previous output."""
    from mixnav.config.loader import load_scenario
    from mixnav.experiment import methods
    from mixnav.sim.scenario import simulate
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.toml"
        p.write_text(TINY)
        sc, src, _ = load_scenario(str(p))
        sim = simulate(sc, 1, src)
    m = sc.methods[0]
    filt, meas = methods.build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0)
    out_t = np.arange(sim.init.time + 0.505, float(sim.imu.time[-1]) - 1, 0.5)   # never on a GNSS epoch
    res = methods.run_method(m, filt, sim.imu, sim.init, meas, src, 0, [m.name], output_times=out_t)[m.name]
    fix_t = sim.fixes.time[(sim.fixes.time > out_t[0]) & (sim.fixes.time <= out_t[-1])]
    expect = np.array([np.any((fix_t > a) & (fix_t <= b)) for a, b in zip(out_t[:-1], out_t[1:])])
    assert res.gnss_used.any()
    np.testing.assert_array_equal(res.gnss_used[1:], expect)


def test_outage_scored_up_to_the_next_update_with_its_rms():
    from mixnav.experiment.metrics import compute_metrics
    t = np.arange(0.0, 30.0, 0.5)
    err = np.where((t >= 10) & (t < 22), t - 9.0, 0.1)       # grows until the fix at 22 s
    used = (t % 1 == 0) & ~((t >= 10) & (t < 22))            # fixes each second, none in [10, 22)
    table = pd.DataFrame({"time_s": t, "err_n_m": err, "err_e_m": 0.0 * t, "err_d_m": 0.0 * t, "gnss_used": used})
    w = compute_metrics(table, outages=[(10.0, 20.0)])["outages"][0]
    assert w["unaided_end_s"] == 22.0
    assert w["horizontal_max_m"] == pytest.approx(21.5 - 9.0)    # the stretch after the window counts
    sel = (t >= 10) & (t < 22)
    assert w["horizontal_rmse_m"] == pytest.approx(float(np.sqrt(np.mean(err[sel] ** 2))))
    assert "vertical_rmse_m" in w
    # without gnss_used (an older table) the window alone, as before
    w0 = compute_metrics(table.drop(columns="gnss_used"), outages=[(10.0, 20.0)])["outages"][0]
    assert w0["horizontal_max_m"] == pytest.approx(11.0)


def test_nis_far_above_one_is_warned_with_causes(box):
    """An IMU that turns and accelerates beside fixes that stand still: NIS per dof far above 1."""
    out = _process(box, _moving_imu("rad/s", 1.0), _gnss_csv(), expect=0)
    m = json.loads((box.out / "metrics.json").read_text())
    ekf = m["methods"]["ekf"]
    assert ekf["nis_median_per_dof"] > 5
    assert m["warnings"] and "installation" in m["warnings"][0] and "unit" in m["warnings"][0]
    flat = " ".join(out.split())
    assert "warning: method 'ekf': median NIS" in flat
    html = (box.out / "report.html").read_text()
    assert "NIS/dof median" in html and "Likely causes" in html


def test_nis_quiet_for_a_consistent_run(box):
    code, out = _run(box)
    assert code == 0 and "NIS" not in out
    m = json.loads((box.out / "metrics.json").read_text())
    assert "warnings" not in m and m["methods"]["ekf"]["nis_median_per_dof"] < 2


@needs_android
def test_raw_gnss_epochs_with_every_measurement_rejected_are_counted(box):
    from mixnav.io.android import read_gnsslogger
    d = box.inp / "android"
    d.mkdir()
    for f in ANDROID.iterdir():
        shutil.copy(f, d / f.name)
    log = d / "pseudoranges_log_2016_06_30_21_26_07.txt"
    lines = log.read_text().splitlines(keepends=True)
    header = next(ln for ln in lines if ln.startswith("# Raw,")).strip().split(",")[1:]
    col = header.index("ReceivedSvTimeUncertaintyNanos")
    tcol = header.index("TimeNanos")
    raw = [i for i, ln in enumerate(lines) if ln.startswith("Raw,")]
    t_mid = lines[raw[len(raw) // 2]].split(",")[tcol + 1]
    for i in raw:
        parts = lines[i].rstrip("\n").split(",")
        if parts[tcol + 1] == t_mid:
            parts[col + 1] = "1e6"      # every measurement of this epoch rejected
            lines[i] = ",".join(parts) + "\n"
    log.write_text("".join(lines))
    assert read_gnsslogger(log).epochs_all_rejected == 1
    box.snapshot()
    code, out = invoke("process", "android-static", "--data", d, "--out", box.out, cwd=box.root)
    assert code == 0, out
    m = json.loads((box.out / "metrics.json").read_text())
    assert m["epoch_status"]["all measurements rejected"] == 1
    assert m["epochs_total"] == m["epochs_used"] + m["epochs_skipped"]
    box.check()


def test_parent_not_writable_rewrites_in_place_marker_first(box, monkeypatch):
    """No temporary sibling possible (a read-only parent): the folder is rewritten in place,
    its marker and metrics.json removed first, so an interrupted rewrite is never marked complete."""
    import tempfile as tf
    import mixnav.experiment.outputs as run_mod
    import mixnav.io.outdir as outdir
    assert _run(box)[0] == 0

    def no_sibling(*a, **k):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(outdir.tempfile, "mkdtemp", no_sibling)
    code, out = _run(box)
    assert code == 0, out
    assert (box.out / "metrics.json").exists() and json.loads((box.out / ".mixnav-output.json").read_text())["complete"]
    real = run_mod.atomic_write_dataframe
    calls = []

    def interrupted(path, df):
        calls.append(path)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(path, df)
    monkeypatch.setattr(run_mod, "atomic_write_dataframe", interrupted)
    code, out = _run(box)
    assert code == 130
    assert not (box.out / "metrics.json").exists()
    assert json.loads((box.out / ".mixnav-output.json").read_text())["complete"] is False
    monkeypatch.setattr(run_mod, "atomic_write_dataframe", real)
    code, out = _run(box)                      # the half-written folder is this command's: rewritten
    assert code == 0, out
    assert json.loads((box.out / ".mixnav-output.json").read_text())["complete"] is True
    assert tf.mkdtemp is no_sibling


def test_out_through_a_symbolic_link_writes_into_its_folder(box):
    real = box.root / "real"
    real.mkdir()
    (box.root / "link").symlink_to(real)
    p = box.write("sc.toml", TINY)
    code, out = invoke("run", p, "--out", box.root / "link", cwd=box.root)
    assert code == 0, out
    assert (box.root / "link").is_symlink() and (real / "metrics.json").exists()
    code, out = invoke("run", p, "--out", box.root / "link", cwd=box.root)   # rewritten through the link
    assert code == 0, out
    assert (box.root / "link").is_symlink() and (real / "metrics.json").exists()


@needs_android
def test_raw_gnss_with_no_solvable_epoch_is_refused(box):
    """A navigation file cut before the log's satellites: nothing solved, refused (was NaN metrics)."""
    d = box.inp / "android"
    d.mkdir()
    for f in ANDROID.iterdir():
        shutil.copy(f, d / f.name)
    nav = d / "hour1820.16n"
    lines = nav.read_text().splitlines(keepends=True)
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    nav.write_text("".join(lines[:end + 1 + 8]))      # the header and one ephemeris
    box.snapshot()
    code, out = invoke("process", "android-static", "--data", d, "--out", box.out, cwd=box.root)
    expect_error(code, out, "pseudoranges_log", "no epoch could be solved")
    assert not box.out.exists()
    box.check()


def test_sibling_left_by_a_killed_run_is_removed_by_the_next(box):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = box.root / f".out.mixnav-{dead.pid}-abc123"
    stale.mkdir()
    (stale / "solution_ekf.csv").write_text("half")
    alive = box.root / f".out.mixnav-{os.getpid()}-def456"     # a run still going: kept
    alive.mkdir()
    assert _run(box)[0] == 0
    assert not stale.exists() and alive.exists()
    alive.rmdir()


def test_stale_temporary_files_go_a_live_writers_stay(tmp_path):
    """io.atomic: a write's temporary file carries its writer's pid; the clean-up removes those
    of ended processes, of this process, of processes it is told have ended and of names
    without a pid (an older mixnav's), keeps a file whose writer still runs (another command
    writing the same folder), and leaves what is not a file without raising."""
    from mixnav.io.atomic import _atomic, remove_stale_temporaries
    # the name a real write gives, seen from inside the write
    with _atomic(tmp_path / "r.parquet") as fh:
        name = Path(fh.name).name
        assert name.startswith(f".r.parquet.{os.getpid()}.") and name.endswith(".tmp")
        fh.write(b"x")
    assert (tmp_path / "r.parquet").read_bytes() == b"x" and not list(tmp_path.glob(".*.tmp"))
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    try:
        names = {"live": f".a.parquet.{live.pid}.k2j4h5g6.tmp", "dead": f".b.parquet.{dead.pid}.k2j4h5g6.tmp",
                 "own": f".c.json.{os.getpid()}.abcdefgh.tmp", "old": ".d.csv.abcdefgh.tmp"}
        for n in names.values():
            (tmp_path / n).write_bytes(b"half")
        (tmp_path / ".cache.tmp").mkdir()                     # not a file: left, no error
        (tmp_path / ".run.20261126123456.abcdefgh.tmp").write_bytes(b"")   # no pid: a date
        assert remove_stale_temporaries(tmp_path) == 4
        assert sorted(p.name for p in tmp_path.glob(".*.tmp")) == sorted([".cache.tmp", names["live"]])
        # a writer known to have ended (a pool's worker; on Windows the only way to know)
        assert remove_stale_temporaries(tmp_path, ended=[live.pid]) == 1
    finally:
        live.kill()
        live.wait()
    assert [p.name for p in tmp_path.glob(".*.tmp")] == [".cache.tmp"]


@pytest.mark.parametrize("key, line", [("tag", 'tag = "imu_1934.csv.tag"'), ("tag_start", 'tag_start = "first-bytes"')])
def test_time_tag_keys_with_another_imu_format_are_refused(tmp_path, key, line):
    """``tag`` and ``tag_start`` are drive-0708's reader's (its time-tag file): with another IMU
    format they would be ignored without a word, so the file is refused, naming the key; the
    same keys with format = "drive-0708" load."""
    from mixnav.config import load_dataset
    from mixnav.errors import ConfigError
    text, _ = resolve("drive-0708", "datasets", "dataset")
    text = text.replace('tag = "imu_1934.csv.tag"\n', line + "\n", 1)
    p = tmp_path / "d.toml"
    p.write_text(text)
    ds, _, _ = load_dataset(str(p))
    assert ds.imu.format == "drive-0708"
    p.write_text(text.replace('format = "drive-0708"', 'format = "psins"', 1))
    with pytest.raises(ConfigError, match=rf"{key}: read by format = \"drive-0708\" only") as ei:
        load_dataset(str(p))
    assert ei.value.key == "imu" and str(p) in str(ei.value)
