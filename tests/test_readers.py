"""Readers of mixnav.io: round trips through each file format, and bad input.

Every test writes its own small files into ``tmp_path`` from data built here
in numpy, reads them back and compares with what was written (or with a
closed form). Bad-input tests check the exception type, the file and the
1-based line that :class:`mixnav.errors.DataError` names, and what it says.
The last group reads the real drive-0708 files from ``../shared/data`` when
they are there (skipped otherwise).

Motion used for the IMU round trips (all formats): 100 Hz for 2 s, a constant
10 deg/s about z, a ramp of 3 deg/s^2 about x (the trapezoid rule is exact
for a linear rate, a rectangle rule would be off by 0.5 * slope * dt * T,
i.e. 0.5 % of the x increment sum) and specific force (0, 0, -9.80665) m/s^2.
"""

from __future__ import annotations

import math
import re
import struct
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest

from mixnav.attitude import euler_to_quat
from mixnav.data import ImuData
from mixnav.errors import ArgumentError, DataError
from mixnav.geodesy.earth import A_WGS84
from mixnav.geodesy.frames import lla_to_ecef
from mixnav.io.drive0708 import read_drive_imu, read_time_tag
from mixnav.io.generic_csv import read_gnss_csv, read_imu_csv, read_reference_csv
from mixnav.io.imu_checks import check_plausible, rates_to_increments
from mixnav.io.kfgins import read_kfgins_gnss, read_kfgins_imu, read_kfgins_nav
from mixnav.io.psins import read_psins_imu
from mixnav.io.rtklib import read_pos
from mixnav.io.tables import check_times, read_numeric

from .conftest import data_file

# Constants written here, not imported from the readers, so a wrong constant
# in a reader is caught.
G0 = 9.80665                      # standard gravity [m/s^2]
DEG = math.pi / 180.0
ARCSEC = DEG / 3600.0
GPS_EPOCH_UNIX = 315964800.0      # 1980-01-06 00:00:00 UTC in Unix seconds

FS = 100.0                        # IMU rate [Hz]
DUR = 2.0                         # record length [s]
N = int(DUR * FS) + 1             # 201 samples -> 200 intervals covering 2 s
RATE_Z = 10.0                     # [deg/s]
RAMP_X = 3.0                      # [deg/s^2]


# ---------------------------------------------------------------------------
# Known data
# ---------------------------------------------------------------------------
def motion_deg(s):
    """Gyro [deg/s] and accelerometer [m/s^2] at times ``s`` [s] after the ramp starts."""
    s = np.asarray(s, float)
    w = np.column_stack([RAMP_X * s, np.zeros_like(s), np.full_like(s, RATE_Z)])
    f = np.tile([0.0, 0.0, -G0], (len(s), 1))
    return w, f


def exact_increments(s):
    """Closed-form integrals of :func:`motion_deg` over each ``(s[k-1], s[k]]``: rad, m/s."""
    a, b = np.asarray(s[:-1], float), np.asarray(s[1:], float)
    dth = np.column_stack([0.5 * RAMP_X * (b**2 - a**2), 0 * a, RATE_Z * (b - a)]) * DEG
    dv = np.column_stack([0 * a, 0 * a, -G0 * (b - a)])
    return dth, dv


def assert_motion(imu, t_start, atol_t=1e-9):
    """``imu`` holds the N-1 increments of the 2 s motion that starts at ``t_start``."""
    assert len(imu) == N - 1
    s = np.arange(N) / FS
    np.testing.assert_allclose(imu.time, t_start + s[1:], rtol=0, atol=atol_t)
    np.testing.assert_allclose(imu.dt, 1 / FS, rtol=0, atol=2 * atol_t)
    dth, dv = exact_increments(s)
    # dt carries the rounding of the times: scale the tolerance with it.
    np.testing.assert_allclose(imu.dtheta, dth, rtol=0, atol=1e-12 + 2 * atol_t * 0.2)
    np.testing.assert_allclose(imu.dvel, dv, rtol=0, atol=1e-12 + 2 * atol_t * 10)
    # The sums are the closed forms of the whole record: rate * duration.
    tot = imu.dtheta.sum(0)
    assert tot[2] == pytest.approx(RATE_Z * DEG * DUR, rel=1e-6)
    assert tot[0] == pytest.approx(0.5 * RAMP_X * DEG * DUR**2, rel=1e-5)
    assert imu.dvel.sum(0)[2] == pytest.approx(-G0 * DUR, rel=1e-6)


def assert_data_error(excinfo, path, line, pattern):
    """The DataError names ``path`` and ``line`` (None: no line) and matches ``pattern``."""
    exc = excinfo.value
    assert type(exc) is DataError
    assert exc.file == str(path)
    assert exc.line == line
    where = f"{path}, line {line}: " if line else f"{path}: "
    assert str(exc).startswith(where), str(exc)
    assert re.search(pattern, str(exc), re.IGNORECASE), str(exc)


def write_lines(path, lines):
    Path(path).write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    return Path(path)


# ---------------------------------------------------------------------------
# Writers, one per format
# ---------------------------------------------------------------------------
# --- drive-0708: CSV + RTKLIB .tag ----------------------------------------
TAG_SEC, TAG_FRAC = 1752003261, 0.854   # start of the tag: GPS s since 1970
TICK0 = 5000                             # IMU tick [ms] of the first CSV line


def drive_rows(n_lines=N + 2):
    """CSV lines ``ax,ay,az[g],gx,gy,gz[deg/s],tick_ms`` of the motion, 10 ms apart.

    Line 0 and the last line are dropped by the reader, so the kept samples
    1..N are the 2 s motion that starts one tick after the first line.
    """
    s = np.arange(n_lines) / FS
    w, f = motion_deg(s - s[1])
    acc_g = f / G0
    return [",".join(f"{v:.9f}" for v in (*acc_g[i], *w[i])) + f",{TICK0 + 10 * i}"
            for i in range(n_lines)]


def tag_bytes(sec=TAG_SEC, frac=TAG_FRAC, ticks=(0, 1000, 2020), header=b"TIMETAG RTKLIB demo5", tick0=TICK0):
    """An RTKLIB time-tag file: 60-byte header, tick, seconds, fraction, (tick_ms, file_pos) pairs."""
    body = struct.pack("<II", tick0, sec) + struct.pack("<d", frac)
    pairs = b"".join(struct.pack("<II", t, 37 * k) for k, t in enumerate(ticks))
    return header.ljust(60, b"\0") + body + pairs


def write_drive(path, rows, tag_end_ms=None, **tag):
    """Write the CSV and its ``.tag``; by default the tag spans the CSV's tick span."""
    write_lines(path, rows)
    if tag_end_ms is None:
        tag_end_ms = int(rows[-1].split(",")[-1]) - int(rows[0].split(",")[-1])
    Path(str(path) + ".tag").write_bytes(tag_bytes(ticks=(0, tag_end_ms // 2, tag_end_ms), **tag))
    return Path(path)


# --- RTKLIB .pos -------------------------------------------------------------
POS_PREAMBLE = ["% program   : RTKPOST ver.demo5 b34",
                "% obs start : 2025/07/08 19:34:18.5 GPST (week2374 243258.5s)"]
POS_COLS = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)"
            "   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio")
POS_VEL = ("    vn(m/s)      ve(m/s)      vu(m/s)      sdvn     sdve     sdvu    sdvne    sdveu    sdvun")
POS_COLS_ECEF = ("%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)"
                 "   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio")
POS_FIRST_LINE = 3  # 2 preamble lines + the column header

# Five epochs at 4 Hz from 2025/07/08 19:34:18.499 GPST = week 2374, tow 243258.499.
GNSS_T0_MS = 1752003258499
GNSS_T = GPS_EPOCH_UNIX + 2374 * 604800 + 243258.499 + 0.25 * np.arange(5)
GNSS_LLA_DEG = np.column_stack([40.0966268 + 1e-5 * np.arange(5), -105.1474483 - 2e-5 * np.arange(5),
                                1601.474 + 0.1 * np.arange(5)])
GNSS_Q = np.array([1, 1, 2, 5, 1])
GNSS_NS = np.array([21, 20, 19, 8, 21])
GNSS_SD = np.array([[0.0099, 0.0098, 0.0100]]) * (1 + np.arange(5))[:, None]
GNSS_VNEU = np.column_stack([1.0 + np.arange(5), np.full(5, -2.0), np.full(5, 0.5)])  # north, east, UP
GNSS_SDV = np.tile([0.0587, 0.0588, 0.0589], (5, 1))


def gpst_label(ms, fmt):
    """RTKLIB time label of ``ms`` GPS milliseconds since 1970 (integer: no rounding)."""
    if fmt == "calendar":
        d = datetime(1970, 1, 1) + timedelta(milliseconds=int(ms))
        return d.strftime("%Y/%m/%d %H:%M:%S") + f".{int(ms) % 1000:03d}"
    week, tow_ms = divmod(int(ms) - int(GPS_EPOCH_UNIX) * 1000, 604800 * 1000)
    return f"{week:4d} {tow_ms / 1000:10.3f}"


def pos_lines(fmt="calendar", vel=True, ecef=False, t_ms=None):
    """Header and data lines of a .pos file holding the five GNSS epochs."""
    t_ms = GNSS_T0_MS + 250 * np.arange(5) if t_ms is None else t_ms
    head = POS_COLS_ECEF if ecef else POS_COLS + (POS_VEL if vel else "")
    lines = POS_PREAMBLE + [head]
    for k in range(5):
        if ecef:
            xyz = lla_to_ecef([GNSS_LLA_DEG[k, 0] * DEG, GNSS_LLA_DEG[k, 1] * DEG, GNSS_LLA_DEG[k, 2]])
            pos = [f"{v:14.4f}" for v in xyz]
        else:
            pos = [f"{GNSS_LLA_DEG[k, 0]:14.9f}", f"{GNSS_LLA_DEG[k, 1]:14.9f}", f"{GNSS_LLA_DEG[k, 2]:10.4f}"]
        cols = [gpst_label(t_ms[k], fmt), *pos, f"{GNSS_Q[k]:3d}", f"{GNSS_NS[k]:3d}",
                *(f"{v:8.4f}" for v in GNSS_SD[k]), *["  0.0000"] * 3, "  0.00", "   0.0"]
        if vel and not ecef:
            cols += [f"{v:10.5f}" for v in GNSS_VNEU[k]] + [f"{v:8.5f}" for v in GNSS_SDV[k]] + ["0.00000"] * 3
        lines.append(" ".join(cols))
    return lines


# --- KF-GINS -----------------------------------------------------------------
SOW0 = 356400.0  # GPS seconds of week of the first KF-GINS / generic sample


def kfgins_imu_lines():
    """``time dtheta[rad] dvel[m/s]`` lines; the first line's increments are a decoy."""
    s = np.arange(N) / FS
    dth, dv = exact_increments(s)
    rows = [[SOW0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]]  # must be dropped: opens the first interval
    rows += [[SOW0 + s[k], *dth[k - 1], *dv[k - 1]] for k in range(1, N)]
    return [" ".join(f"{v:.17g}" for v in r) for r in rows]


# --- generic CSV --------------------------------------------------------------
IMU_RATE_HEAD = "time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],fz[m/s^2]"


def generic_imu_rate_lines(header=IMU_RATE_HEAD, gyro_scale=1.0, acc_scale=1.0):
    """Rate layout; the values are written in the units the header declares."""
    s = np.arange(N) / FS
    w, f = motion_deg(s)
    cols = {"time[s]": SOW0 + s, "time[ms]": (SOW0 + s) * 1e3}
    for i, ax in enumerate("xyz"):
        cols[f"w{ax}[deg/s]"] = w[:, i] * gyro_scale
        cols[f"w{ax}[rad/s]"] = w[:, i] * DEG * gyro_scale
        cols[f"f{ax}[m/s^2]"] = f[:, i] * acc_scale
        cols[f"f{ax}[g]"] = f[:, i] / G0 * acc_scale
    names = [c.strip() for c in header.split(",")]
    return [header] + [",".join(repr(float(cols[c][k])) for c in names) for k in range(N)]


def generic_imu_inc_lines(header="time[s],dthx[rad],dthy[rad],dthz[rad],dvx[m/s],dvy[m/s],dvz[m/s]"):
    """Increment layout; the first row only opens the first interval (zeros)."""
    s = np.arange(N) / FS
    dth, dv = exact_increments(s)
    dth, dv = np.vstack([np.zeros(3), dth]), np.vstack([np.zeros(3), dv])
    cols = {"time[s]": SOW0 + s}
    for i, ax in enumerate("xyz"):
        cols[f"dth{ax}[rad]"], cols[f"dth{ax}[deg]"] = dth[:, i], dth[:, i] / DEG
        cols[f"dv{ax}[m/s]"], cols[f"dv{ax}[km/h]"] = dv[:, i], dv[:, i] * 3.6
    names = [c.strip() for c in header.split(",")]
    return [header] + [",".join(repr(float(cols[c][k])) for c in names) for k in range(N)]


# --- PSINS -------------------------------------------------------------------
PSINS_COMMENTS = ["% PSINS-format SIMU log file.", "%   [pitch0(deg), roll0(deg), yaw0(deg), VE0, VN0, VU0]", ""]
PSINS_H1 = "1.0 2.0 -90.6 0.1 0.2 0.3"                  # pitch roll yaw [deg], VE VN VU
PSINS_H2 = "34.246 108.91 380.0 100.0 10.0 9.7936"       # lat lon [deg] h, t0 [s], dt [ms], g
PSINS_H3 = "0.1 0.1 0.1 125 125 125"                     # gyro [arcsec], accel [ug*s] per count
PSINS_DATA_LINE = len(PSINS_COMMENTS) + 4                # 1-based line of the first sample
# Sensor axes right, forward, up; per 10 ms: x 100, y 200 counts, z 10 deg/s = 360" = 3600 counts;
# accelerometer up +1 g * 10 ms = 10000 ug*s = 80 counts.
PSINS_COUNTS = [100, 200, 3600, 0, 0, 80]


def psins_lines(n=N - 1, counts=PSINS_COUNTS):
    return PSINS_COMMENTS + [PSINS_H1, PSINS_H2, PSINS_H3] + [" ".join(map(str, counts))] * n


# ===========================================================================
# 1. Round trips and closed forms
# ===========================================================================
# --- imu_checks -------------------------------------------------------------
def test_rates_to_increments_is_the_trapezoid_rule():
    s = np.arange(N) / FS
    w, f = motion_deg(s)
    imu = rates_to_increments(SOW0 + s, w * DEG, f, source="x")
    assert_motion(imu, SOW0)
    assert imu.source == "x"


def test_rates_to_increments_needs_two_samples():
    with pytest.raises(DataError, match="at least two") as ei:
        rates_to_increments(np.array([1.0]), np.zeros((1, 3)), np.zeros((1, 3)), source="f.csv")
    assert ei.value.file == "f.csv"


def _imu(rate_rad_s, f_m_s2, n=100):
    dt = np.full(n, 0.01)
    return ImuData(time=np.arange(1, n + 1) * 0.01, dt=dt, dtheta=np.tile(rate_rad_s, (n, 1)) * 0.01,
                   dvel=np.tile(f_m_s2, (n, 1)) * 0.01, source="imu.csv")


def test_check_plausible_accepts_vehicle_data():
    check_plausible(_imu([0.1, 0.0, 0.5], [0.3, 0.1, -G0]), "rad/s", "m/s^2")


@pytest.mark.parametrize("rate, force, words", [
    ([0.0, 0.0, 30.0], [0, 0, -G0], r"rad/s.*deg/s declared as rad/s"),  # 30 "rad/s" = a deg/s record
    ([0.0, 0.0, 0.1], [0, 0, -1.0], r"median specific force is 1 m/s\^2.*'m/s\^2'"),  # g record
    ([0.0, 0.0, 0.1], [0, 0, -G0 * G0], r"median specific force is 96.17.*unit is probably wrong"),
])
def test_check_plausible_refuses_wrong_units(rate, force, words):
    with pytest.raises(DataError, match=words) as ei:
        check_plausible(_imu(rate, force), "rad/s", "m/s^2")
    assert ei.value.file == "imu.csv"


# --- tables ---------------------------------------------------------------------
def test_read_numeric_counts_lines_past_header_comments_and_blanks(tmp_path):
    p = write_lines(tmp_path / "t.txt", ["skip me", "# c", "1 2", "", "3 4", "# c", "5 6", "7 8"])
    tab = read_numeric(p, 2, comment="#", skip_lines=1)
    np.testing.assert_array_equal(tab.values, [[1, 2], [3, 4], [5, 6], [7, 8]])
    np.testing.assert_array_equal(tab.lines, [3, 5, 7, 8])
    edges = read_numeric(p, 2, comment="#", skip_lines=1, drop_edges=True)
    np.testing.assert_array_equal(edges.values, [[3, 4], [5, 6]])
    np.testing.assert_array_equal(edges.lines, [5, 7])


def test_read_numeric_column_count_change_names_the_line(tmp_path):
    p = write_lines(tmp_path / "t.txt", ["1 2 3", "4 5 6", "7 8 9 10 11", "1 2 3"])
    with pytest.raises(DataError) as ei:
        read_numeric(p, (3, 5))
    assert_data_error(ei, p, 3, r"column count changes from 3 to 5")


def test_read_numeric_converter_failure_names_the_line(tmp_path):
    p = write_lines(tmp_path / "t.txt", ["a 1", "b 2", "zz 3"])

    def conv(toks):
        return [{"a": 1.0, "b": 2.0}[toks[0]] if toks[0] in "ab" else float(toks[0]), float(toks[1])]

    with pytest.raises(DataError) as ei:
        read_numeric(p, 2, converters=conv, what="thing")
    assert_data_error(ei, p, 3, r"cannot read this thing line .*'zz'")


@pytest.mark.parametrize("lines, skip, line, words", [
    (["a,b"], 1, 1, r"thing file is empty: no data line after the header"),
    (["# h1", "# h2", "", "% c"], 2, 2, r"no data line after the header"),   # blank and comment lines
    (["a,b"], 2, None, r"thing file is empty \(no data lines\)"),            # shorter than its header
    ([], 0, None, r"thing file is empty \(no data lines\)"),
])
def test_read_numeric_names_the_header_of_a_file_without_data(tmp_path, lines, skip, line, words):
    """After ``skip_lines`` header lines, no data line is an error naming the header's last line."""
    p = write_lines(tmp_path / "t.csv", lines)
    with pytest.raises(DataError) as ei:
        read_numeric(p, 2, delimiter=",", comment="%", skip_lines=skip, what="thing")
    assert_data_error(ei, p, line, words)


def test_check_times_counts_gaps_and_warns_with_the_line():
    t = np.array([0.0, 0.1, 0.2, 0.5, 0.6, 1.6])
    lines = np.arange(10, 16)
    with pytest.warns(UserWarning, match=r"f\.txt, line 13: 2 gap\(s\) longer than 0.2 s.*0\.300 s"):
        out = check_times(t, lines, "f.txt", max_gap=0.2)
    assert out.gaps == 2 and out.largest_gap == pytest.approx(1.0)
    with pytest.raises(DataError) as ei:
        check_times(t, lines, "f.txt", max_gap=0.2, gap_action="fail")
    assert_data_error(ei, "f.txt", 13, r"gap")
    assert check_times(t, lines, "f.txt").gaps == 0  # no max_gap: gaps are not looked for


@pytest.mark.parametrize("gap_action", ["ignore", "Warn", "", None, 1])
@pytest.mark.parametrize("max_gap", [0.2, None])
def test_check_times_refuses_an_unknown_gap_action(gap_action, max_gap):
    """An unknown gap_action is an error naming the argument and the allowed values (it used
    to warn like "warn"), with or without a gap to act on."""
    t = np.array([0.0, 0.1, 0.2, 0.5])
    with pytest.raises(ArgumentError, match=r"'warn' or 'fail'") as ei:
        check_times(t, np.arange(1, 5), "f.txt", max_gap=max_gap, gap_action=gap_action)
    assert ei.value.argument == "gap_action"


def test_readers_pass_gap_action_to_the_check(tmp_path):
    p = write_lines(tmp_path / "imu.csv", [IMU_RATE_HEAD, "0.01,0,0,0,0,0,9.8", "0.02,0,0,0,0,0,9.8"])
    with pytest.raises(ArgumentError) as ei:
        read_imu_csv(p, max_gap=0.1, gap_action="skip")
    assert ei.value.argument == "gap_action"


@pytest.mark.parametrize("t, line, kind", [([0, 1, 2, 1.5, 3], 13, "goes backwards"),
                                           ([0, 1, 1, 2], 12, "repeats")])
def test_check_times_refuses_non_increasing(t, line, kind):
    with pytest.raises(DataError) as ei:
        check_times(np.array(t, float), np.arange(10, 10 + len(t)), "f.txt", what="GNSS")
    assert_data_error(ei, "f.txt", line, rf"GNSS time {kind}")


# --- drive-0708 -------------------------------------------------------------------
def test_read_time_tag_start_end_count(tmp_path):
    p = tmp_path / "a.tag"
    p.write_bytes(tag_bytes(sec=1752003261, frac=0.854, ticks=(0, 131, 146, 548731)))
    tag = read_time_tag(p)
    assert tag.start == 1752003261 + 0.854
    assert tag.end == pytest.approx(1752003261.854 + 548.731, abs=1e-6)  # 1.75e9 s: ulp 2.4e-7 s
    assert tag.n_tags == 4


def test_drive_imu_round_trip(tmp_path):
    p = write_drive(tmp_path / "imu.csv", drive_rows())
    imu = read_drive_imu(p)
    # Kept line i sits at start + 10 ms * i - 0.125 s; the first kept line is i = 1.
    # Times near 1.75e9 s carry ~1e-7 s of float rounding.
    assert_motion(imu, TAG_SEC + TAG_FRAC + 0.01 - 0.125, atol_t=1e-6)
    assert imu.source == str(p)


def test_drive_imu_time_offset_and_explicit_tag_path(tmp_path):
    p = write_drive(tmp_path / "imu.csv", drive_rows())
    other = tmp_path / "elsewhere.tag"
    other.write_bytes(Path(str(p) + ".tag").read_bytes())
    Path(str(p) + ".tag").unlink()
    a = read_drive_imu(p, other)
    b = read_drive_imu(p, other, time_offset=0.5)
    np.testing.assert_allclose(b.time - a.time, 0.625, atol=1e-6)
    np.testing.assert_allclose(b.dtheta, a.dtheta, rtol=1e-5)


def test_drive_imu_ticks_are_spread_linearly_over_the_tag(tmp_path):
    # The CSV ticks span 2020 ms but the tag says 2030 ms passed: the IMU
    # clock runs slow and every time stretches by 2030/2020.
    rows = drive_rows()
    p = write_drive(tmp_path / "imu.csv", rows, tag_end_ms=2030)
    imu = read_drive_imu(p, time_offset=0.0)
    ticks = np.array([int(r.split(",")[-1]) for r in rows[2:-1]])
    expect = TAG_SEC + TAG_FRAC + (ticks - TICK0) / 2020 * 2.030
    np.testing.assert_allclose(imu.time, expect, rtol=0, atol=1e-6)
    np.testing.assert_allclose(imu.dt, 0.01 * 2030 / 2020, rtol=0, atol=1e-6)


def test_drive_imu_first_bytes_puts_the_first_tick_at_the_tags_first_pair(tmp_path):
    """tag_start="first-bytes": the first tick at the tag's start plus its first pair's tick (the
    stream's first bytes), the ticks spread from there to the tag's end; "tag" (the default) is
    the README's rule, and another word is refused by name."""
    rows = drive_rows()
    p = write_drive(tmp_path / "imu.csv", rows)
    end = int(rows[-1].split(",")[-1]) - int(rows[0].split(",")[-1])          # 2020 ms: the ticks' span
    Path(str(p) + ".tag").write_bytes(tag_bytes(ticks=(60, end // 2, end + 60)))   # 60 ms lead
    ticks = np.array([int(r.split(",")[-1]) for r in rows[2:-1]])
    a = read_drive_imu(p, time_offset=0.0, tag_start="first-bytes")
    np.testing.assert_allclose(a.time, TAG_SEC + TAG_FRAC + 0.060 + (ticks - TICK0) / 1000.0, rtol=0, atol=1e-6)
    b = read_drive_imu(p, time_offset=0.0)
    np.testing.assert_allclose(b.time, TAG_SEC + TAG_FRAC + (ticks - TICK0) / 2020 * 2.080, rtol=0, atol=1e-6)
    with pytest.raises(ArgumentError, match="first-bytes"):
        read_drive_imu(p, tag_start="lead")


def test_drive_imu_scales_g_and_deg(tmp_path):
    # One sample per axis so that a swapped or unscaled column shows.
    rows = drive_rows()
    rows = [",".join(["0.1", "-0.2", "-1.0", "4.0", "-5.0", "6.0", r.split(",")[-1]]) for r in rows]
    imu = read_drive_imu(write_drive(tmp_path / "imu.csv", rows))
    np.testing.assert_allclose(imu.dvel / imu.dt[:, None], np.tile([0.1, -0.2, -1.0], (N - 1, 1)) * G0,
                               rtol=1e-12)
    np.testing.assert_allclose(imu.dtheta / imu.dt[:, None], np.tile([4.0, -5.0, 6.0], (N - 1, 1)) * DEG,
                               rtol=1e-12)


# --- RTKLIB .pos ---------------------------------------------------------------------
def test_pos_brief_example_line(tmp_path):
    # The demo5 line of the real recording, verbatim.
    p = write_lines(tmp_path / "a.pos", [
        "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
        "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)      ve(m/s)      vu(m/s)      sdvn     sdve"
        "     sdvu    sdvne    sdveu    sdvun",
        "2025/07/08 19:34:18.499 40.0966268 -105.1474483 1601.4740000 1 21 0.0099 0.0099 0.0100 0.0 0.0 0.0"
        " 0.0 0.0 0.0100 -0.0020 0.0090 0.0587 0.0587 0.0587 0.0 0.0 0.0"])
    s = read_pos(p)
    # 2025-07-08 is a Tuesday of GPS week 2374: tow = 2 days + 19:34:18.499.
    assert s.time[0] == pytest.approx(GPS_EPOCH_UNIX + 2374 * 604800 + 2 * 86400 + 70458.499, abs=1e-6)
    assert s.time[0] == pytest.approx(1752003258.499, abs=1e-6)
    np.testing.assert_allclose(s.lla[0], [40.0966268 * DEG, -105.1474483 * DEG, 1601.474], rtol=1e-15)
    assert s.quality[0] == 1 and s.n_sat[0] == 21
    np.testing.assert_allclose(s.sd_ned[0], [0.0099, 0.0099, 0.0100])
    np.testing.assert_allclose(s.vel_ned[0], [0.0100, -0.0020, -0.0090])  # vu = +0.009 -> vd = -0.009
    np.testing.assert_allclose(s.sd_vel[0], [0.0587] * 3)


@pytest.mark.parametrize("fmt", ["calendar", "week"])
def test_pos_round_trip_both_time_formats(tmp_path, fmt):
    p = write_lines(tmp_path / "a.pos", pos_lines(fmt))
    s = read_pos(p)
    # 1.75e9 s in float64: 2.4e-7 s ulp.
    np.testing.assert_allclose(s.time, GNSS_T, rtol=0, atol=1e-6)
    np.testing.assert_allclose(s.time, 1752003258.499 + 0.25 * np.arange(5), rtol=0, atol=1e-6)
    np.testing.assert_allclose(s.lla[:, :2], GNSS_LLA_DEG[:, :2] * DEG, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.lla[:, 2], GNSS_LLA_DEG[:, 2], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(s.quality, GNSS_Q)
    np.testing.assert_array_equal(s.n_sat, GNSS_NS)
    np.testing.assert_allclose(s.sd_ned, GNSS_SD, atol=1e-12)
    np.testing.assert_allclose(s.vel_ned, GNSS_VNEU * [1, 1, -1], atol=1e-12)  # up -> down
    np.testing.assert_allclose(s.sd_vel, GNSS_SDV, atol=1e-12)
    assert s.source == str(p)


def test_pos_calendar_and_week_give_the_same_times(tmp_path):
    a = read_pos(write_lines(tmp_path / "a.pos", pos_lines("calendar")))
    b = read_pos(write_lines(tmp_path / "b.pos", pos_lines("week")))
    np.testing.assert_allclose(a.time, b.time, rtol=0, atol=1e-6)
    # A week boundary: Saturday 23:59:59.750 then Sunday 00:00:00.000 of week 2375.
    t_ms = (GPS_EPOCH_UNIX + 2375 * 604800) * 1000 + 250 * (np.arange(5) - 1)
    c = read_pos(write_lines(tmp_path / "c.pos", pos_lines("calendar", t_ms=t_ms)))
    d = read_pos(write_lines(tmp_path / "d.pos", pos_lines("week", t_ms=t_ms)))
    np.testing.assert_allclose(c.time, t_ms / 1000, atol=1e-6)
    np.testing.assert_allclose(d.time, t_ms / 1000, atol=1e-6)


def test_pos_without_velocity(tmp_path):
    s = read_pos(write_lines(tmp_path / "a.pos", pos_lines(vel=False)))
    assert s.vel_ned is None and s.sd_vel is None
    np.testing.assert_allclose(s.sd_ned, GNSS_SD)
    fx = s.fixes()
    assert fx.vel_n is None and fx.vel_sigma is None
    assert s.reference().v_n is None


def test_pos_ecef_closed_form_points(tmp_path):
    # (a + h, 0, 0) is lat 0, lon 0, height h; (0, a, 0) is lat 0, lon 90 deg.
    head = POS_PREAMBLE + [POS_COLS_ECEF]
    rows = [f"2374 243258.{k}00 {x:.4f} {y:.4f} {z:.4f} 1 20 0.01 0.01 0.01 0 0 0 0 0"
            for k, (x, y, z) in enumerate([(A_WGS84 + 100.0, 0, 0), (0, A_WGS84, 0)])]
    s = read_pos(write_lines(tmp_path / "e.pos", head + rows))
    np.testing.assert_allclose(s.lla, [[0, 0, 100.0], [0, math.pi / 2, 0.0]], atol=1e-9)


def test_pos_ecef_round_trip(tmp_path):
    s = read_pos(write_lines(tmp_path / "e.pos", pos_lines("week", ecef=True)))
    # x, y, z written to 0.1 mm: 1e-4 m / 6.4e6 m = 2e-11 rad.
    np.testing.assert_allclose(s.lla[:, :2], GNSS_LLA_DEG[:, :2] * DEG, rtol=0, atol=1e-10)
    np.testing.assert_allclose(s.lla[:, 2], GNSS_LLA_DEG[:, 2], rtol=0, atol=2e-4)
    assert s.vel_ned is None
    np.testing.assert_allclose(s.time, GNSS_T, atol=1e-6)


def test_pos_ecef_sigmas_are_rotated_to_ned(tmp_path):
    # Diagonal ECEF covariance sdx = sdy = 1 cm, sdz = 1 m at 40 N, 105 W. Rotated to NED the
    # north sigma is about cos(40 deg) * 1 m = 0.77 m; the reader reports sdx = 0.01 m.
    lat, lon = 40.0 * DEG, -105.0 * DEG
    xyz = lla_to_ecef([lat, lon, 1600.0])
    p = write_lines(tmp_path / "e.pos", POS_PREAMBLE + [POS_COLS_ECEF, (
        f"2374 243258.499 {xyz[0]:.4f} {xyz[1]:.4f} {xyz[2]:.4f} 1 20 0.0100 0.0100 1.0000 0 0 0 0 0")])
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    c_ne = np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])
    sd = np.sqrt(np.diag(c_ne @ np.diag([0.01, 0.01, 1.0]) ** 2 @ c_ne.T))
    np.testing.assert_allclose(read_pos(p).sd_ned[0], sd, rtol=1e-3)


def test_pos_quality_selection(tmp_path):
    s = read_pos(write_lines(tmp_path / "a.pos", pos_lines()))
    fixed = GNSS_Q == 1
    np.testing.assert_array_equal(s.select([1]), fixed)
    fx = s.fixes(qualities=[1])
    np.testing.assert_allclose(fx.time, GNSS_T[fixed], atol=1e-6)
    np.testing.assert_allclose(fx.lla[:, 0], GNSS_LLA_DEG[fixed, 0] * DEG, atol=1e-15)
    np.testing.assert_allclose(fx.pos_sigma, GNSS_SD[fixed])
    np.testing.assert_allclose(fx.vel_n, GNSS_VNEU[fixed] * [1, 1, -1])
    np.testing.assert_allclose(fx.vel_sigma, GNSS_SDV[fixed])
    assert len(s.fixes()) == 5                       # default: fix, float and single
    assert len(s.fixes(qualities=[2, 5])) == 2
    ref = s.reference(qualities=[1])
    np.testing.assert_allclose(ref.time, GNSS_T[fixed], atol=1e-6)
    np.testing.assert_allclose(ref.v_n, GNSS_VNEU[fixed] * [1, 1, -1])
    assert ref.q_nb is None
    assert len(s.reference()) == 3                   # default reference: fixed only


def test_pos_min_sigma_floors_position_sigma(tmp_path):
    s = read_pos(write_lines(tmp_path / "a.pos", pos_lines()))
    fx = s.fixes(min_sigma=0.03)
    np.testing.assert_allclose(fx.pos_sigma, np.maximum(GNSS_SD, 0.03))
    assert fx.pos_sigma.min() == 0.03 and fx.pos_sigma.max() == pytest.approx(0.05)  # 5 * 0.0100


@pytest.mark.parametrize("call", ["fixes", "reference"])
def test_pos_no_epoch_of_the_quality(tmp_path, call):
    p = write_lines(tmp_path / "a.pos", pos_lines())
    with pytest.raises(DataError) as ei:
        getattr(read_pos(p), call)(qualities=[4])
    assert_data_error(ei, p, None, r"no epoch with quality in \[4\]")


# --- KF-GINS ------------------------------------------------------------------------
def test_kfgins_imu_round_trip(tmp_path):
    imu = read_kfgins_imu(write_lines(tmp_path / "imu.txt", kfgins_imu_lines()))
    assert_motion(imu, SOW0)   # the decoy increments of line 1 are not in the sums


def _kfgins_gnss_lines(vel):
    rows = []
    for k in range(5):
        r = [SOW0 + 0.25 * k, *GNSS_LLA_DEG[k], *GNSS_SD[k]]
        if vel:
            r += [*(GNSS_VNEU[k] * [1, 1, -1]), *GNSS_SDV[k]]
        rows.append(" ".join(f"{v:.10g}" for v in r))
    return rows


@pytest.mark.parametrize("vel", [False, True])
def test_kfgins_gnss_round_trip(tmp_path, vel):
    fx = read_kfgins_gnss(write_lines(tmp_path / "gnss.txt", _kfgins_gnss_lines(vel)))
    np.testing.assert_allclose(fx.time, SOW0 + 0.25 * np.arange(5), atol=1e-9)
    np.testing.assert_allclose(fx.lla[:, :2], GNSS_LLA_DEG[:, :2] * DEG, atol=1e-15)
    np.testing.assert_allclose(fx.lla[:, 2], GNSS_LLA_DEG[:, 2], atol=1e-9)
    np.testing.assert_allclose(fx.pos_sigma, GNSS_SD)
    if vel:
        np.testing.assert_allclose(fx.vel_n, GNSS_VNEU * [1, 1, -1])  # KF-GINS already writes down
        np.testing.assert_allclose(fx.vel_sigma, GNSS_SDV)
    else:
        assert fx.vel_n is None


def test_kfgins_gnss_mixed_widths_and_bad_sigma(tmp_path):
    lines = _kfgins_gnss_lines(True)
    lines[2] = _kfgins_gnss_lines(False)[2]
    p = write_lines(tmp_path / "g.txt", lines)
    with pytest.raises(DataError) as ei:
        read_kfgins_gnss(p)
    assert_data_error(ei, p, 3, r"column count changes from 13 to 7")
    lines = _kfgins_gnss_lines(False)
    toks = lines[3].split()
    toks[5] = "0"      # sd_e = 0
    lines[3] = " ".join(toks)
    p = write_lines(tmp_path / "h.txt", lines)
    with pytest.raises(DataError) as ei:
        read_kfgins_gnss(p)
    assert_data_error(ei, p, 4, r"standard deviations must be positive")


def test_kfgins_nav_euler_to_quaternion(tmp_path):
    rpy_deg = np.array([[0.0, 0.0, 90.0], [10.0, -5.0, 200.0], [-30.0, 60.0, -45.0]])
    rows = [f"2374 {SOW0 + k} 40.1 -105.2 1601.5 1.0 -2.0 0.5 {r:.6f} {p:.6f} {y:.6f}"
            for k, (r, p, y) in enumerate(rpy_deg)]
    tr = read_kfgins_nav(write_lines(tmp_path / "ref.nav", rows))
    np.testing.assert_allclose(tr.time, SOW0 + np.arange(3))
    np.testing.assert_allclose(tr.lla[0], [40.1 * DEG, -105.2 * DEG, 1601.5])
    np.testing.assert_allclose(tr.v_n, np.tile([1.0, -2.0, 0.5], (3, 1)))
    np.testing.assert_allclose(tr.q_nb, euler_to_quat(rpy_deg * DEG), atol=1e-15)
    # Closed form: a yaw of 90 deg alone is a quarter turn about down.
    np.testing.assert_allclose(tr.q_nb[0], [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-15)
    # Back to Euler angles (yaw 200 deg wraps to -160 deg).
    np.testing.assert_allclose(tr.rpy / DEG, [[0, 0, 90], [10, -5, -160], [-30, 60, -45]], atol=1e-9)


# --- generic CSV ------------------------------------------------------------------------
@pytest.mark.parametrize("header", [
    IMU_RATE_HEAD,
    "time[s],wx[rad/s],wy[rad/s],wz[rad/s],fx[g],fy[g],fz[g]",
    "fz[g], time[ms], wz[rad/s], fx[m/s^2], wy[deg/s], fy[g], wx[deg/s]",  # any order, mixed units
])
def test_generic_imu_rates_round_trip(tmp_path, header):
    imu = read_imu_csv(write_lines(tmp_path / "imu.csv", generic_imu_rate_lines(header)))
    assert_motion(imu, SOW0, atol_t=1e-9)


@pytest.mark.parametrize("header", [
    "time[s],dthx[rad],dthy[rad],dthz[rad],dvx[m/s],dvy[m/s],dvz[m/s]",
    "dvz[km/h],dthy[deg],time[s],dvx[m/s],dthz[deg],dvy[m/s],dthx[rad]",
])
def test_generic_imu_increments_round_trip(tmp_path, header):
    imu = read_imu_csv(write_lines(tmp_path / "imu.csv", generic_imu_inc_lines(header)))
    assert_motion(imu, SOW0, atol_t=1e-9)


def _generic_gnss_lines(header):
    names = [c.strip() for c in header.split(",")]
    vned = GNSS_VNEU * [1, 1, -1]
    cols = {"time[s]": SOW0 + 0.25 * np.arange(5), "lat[deg]": GNSS_LLA_DEG[:, 0],
            "lon[deg]": GNSS_LLA_DEG[:, 1], "lat[rad]": GNSS_LLA_DEG[:, 0] * DEG,
            "height[m]": GNSS_LLA_DEG[:, 2], "height[km]": GNSS_LLA_DEG[:, 2] / 1e3}
    for i, ax in enumerate("ned"):
        cols[f"sd_{ax}[m]"], cols[f"sd_{ax}[cm]"] = GNSS_SD[:, i], GNSS_SD[:, i] * 100
        cols[f"v{ax}[m/s]"], cols[f"v{ax}[km/h]"] = vned[:, i], vned[:, i] * 3.6
        cols[f"sd_v{ax}[m/s]"] = GNSS_SDV[:, i]
    return [header] + [",".join(repr(float(cols[c][k])) for c in names) for k in range(5)]


@pytest.mark.parametrize("header, vel", [
    ("time[s],lat[deg],lon[deg],height[m],sd_n[m],sd_e[m],sd_d[m]", False),
    ("time[s],lat[deg],lon[deg],height[m],sd_n[m],sd_e[m],sd_d[m],vn[m/s],ve[m/s],vd[m/s],"
     "sd_vn[m/s],sd_ve[m/s],sd_vd[m/s]", True),
    ("sd_vd[m/s],vd[km/h],lon[deg],sd_n[cm],height[km],time[s],sd_e[m],ve[km/h],lat[rad],vn[m/s],"
     "sd_d[m],sd_ve[m/s],sd_vn[m/s]", True),
])
def test_generic_gnss_round_trip(tmp_path, header, vel):
    fx = read_gnss_csv(write_lines(tmp_path / "gnss.csv", _generic_gnss_lines(header)))
    np.testing.assert_allclose(fx.time, SOW0 + 0.25 * np.arange(5), atol=1e-9)
    np.testing.assert_allclose(fx.lla[:, :2], GNSS_LLA_DEG[:, :2] * DEG, atol=1e-15)
    np.testing.assert_allclose(fx.lla[:, 2], GNSS_LLA_DEG[:, 2], atol=1e-9)
    np.testing.assert_allclose(fx.pos_sigma, GNSS_SD, rtol=1e-12)
    if vel:
        np.testing.assert_allclose(fx.vel_n, GNSS_VNEU * [1, 1, -1], rtol=1e-12)
        np.testing.assert_allclose(fx.vel_sigma, GNSS_SDV)
    else:
        assert fx.vel_n is None and fx.vel_sigma is None


def test_generic_reference_round_trip(tmp_path):
    rpy_deg = np.array([[0.0, 0.0, 90.0], [10.0, -5.0, 170.0], [-30.0, 60.0, -45.0]])
    rows = ["yaw[deg],time[s],lat[deg],lon[deg],height[m],vn[m/s],ve[m/s],vd[m/s],roll[deg],pitch[rad]"]
    rows += [f"{y},{SOW0 + k},40.1,-105.2,1601.5,1.0,-2.0,0.5,{r},{float(p * DEG)!r}"
             for k, (r, p, y) in enumerate(rpy_deg)]
    tr = read_reference_csv(write_lines(tmp_path / "ref.csv", rows))
    np.testing.assert_allclose(tr.time, SOW0 + np.arange(3))
    np.testing.assert_allclose(tr.lla[2], [40.1 * DEG, -105.2 * DEG, 1601.5])
    np.testing.assert_allclose(tr.v_n, np.tile([1.0, -2.0, 0.5], (3, 1)))
    np.testing.assert_allclose(tr.q_nb, euler_to_quat(rpy_deg * DEG), atol=1e-15)
    np.testing.assert_allclose(tr.q_nb[0], [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-15)
    pos_only = read_reference_csv(write_lines(tmp_path / "p.csv", ["time[s],lat[deg],lon[deg],height[m]",
                                                                   "1,40,-105,1600", "2,40.1,-105,1601"]))
    assert pos_only.v_n is None and pos_only.q_nb is None
    np.testing.assert_allclose(pos_only.lla[1], [40.1 * DEG, -105 * DEG, 1601])


# --- PSINS ----------------------------------------------------------------------------------
def test_psins_round_trip(tmp_path):
    imu, h = read_psins_imu(write_lines(tmp_path / "a.imu", psins_lines()))
    assert len(imu) == N - 1
    # The first sample ends at t0 + dt.
    np.testing.assert_allclose(imu.time, 100.0 + 0.01 * np.arange(1, N), atol=1e-9)
    np.testing.assert_allclose(imu.dt, 0.01, rtol=1e-12)
    # Sensor (right, forward, up) -> body (forward, right, down): x_b = y_s, y_b = x_s, z_b = -z_s.
    np.testing.assert_allclose(imu.dtheta[0], np.array([200, 100, -3600]) * 0.1 * ARCSEC, rtol=1e-12)
    np.testing.assert_allclose(imu.dvel[0], [0, 0, -80 * 125e-6 * 9.7936], rtol=1e-12)
    # 10 deg/s about sensor up = -10 deg/s about body down, for 2 s.
    assert imu.dtheta[:, 2].sum() == pytest.approx(-RATE_Z * DEG * DUR, rel=1e-12)
    # Header in mixnav conventions: roll, pitch, NED yaw; velocity N, E, D.
    np.testing.assert_allclose(h.rpy, np.array([2.0, 1.0, 90.6]) * DEG, rtol=1e-12)
    np.testing.assert_allclose(h.v_n, [0.2, 0.1, -0.3])
    np.testing.assert_allclose(h.lla, [34.246 * DEG, 108.91 * DEG, 380.0])
    assert (h.t0, h.dt, h.g) == (100.0, 0.01, 9.7936)
    np.testing.assert_allclose(h.gyro_scale, 0.1 * ARCSEC)
    np.testing.assert_allclose(h.accel_scale, 125e-6 * 9.7936)


# ===========================================================================
# 2. Bad input
# ===========================================================================
# Row corruptions shared by the three 7-column text formats. BAD_LINE is
# the 1-based file line that is damaged; the one before it is intact.
BAD_LINE = 6
ROW_CASES = {
    "missing column": r"expected 7 columns, found 6",
    "extra column": r"expected 7 columns, found 8",
    "text in a number": r"not a number: 'abc'",
    "NaN": r"non-finite value",
    "time backwards": r"time goes backwards",
    "time repeats": r"time repeats",
}


def corrupt(toks, prev, case, tcol):
    toks = list(toks)
    if case == "missing column":
        return toks[:-1]
    if case == "extra column":
        return toks + ["0.5"]
    if case == "text in a number":
        toks[2] = "abc"
    elif case == "NaN":
        toks[2] = "nan"
    elif case == "time backwards":
        toks[tcol] = repr(float(prev[tcol]) - 0.5 * (float(toks[tcol]) - float(prev[tcol])))
    elif case == "time repeats":
        toks[tcol] = prev[tcol]
    return toks


# name: (lines, separator, time column, write(path, lines), read(path, **kw))
def _kfgins_lines():
    lines = kfgins_imu_lines()
    lines.insert(2, "")    # a blank line at line 3 must still be counted
    return lines


ROW_FORMATS = {
    "kfgins": (_kfgins_lines, None, 0, write_lines, read_kfgins_imu),
    "generic": (generic_imu_rate_lines, ",", 0, write_lines, read_imu_csv),
    "drive": (drive_rows, ",", 6, write_drive, read_drive_imu),
}


def _split(line, sep):
    return line.split(sep) if sep else line.split()


@pytest.mark.parametrize("case", list(ROW_CASES))
@pytest.mark.parametrize("fmt", list(ROW_FORMATS))
def test_bad_row(tmp_path, fmt, case):
    make, sep, tcol, write, read = ROW_FORMATS[fmt]
    lines = make()
    bad = corrupt(_split(lines[BAD_LINE - 1], sep), _split(lines[BAD_LINE - 2], sep), case, tcol)
    lines[BAD_LINE - 1] = (sep or " ").join(bad)
    p = write(tmp_path / "imu.txt", lines)
    with pytest.raises(DataError) as ei:
        read(p)
    assert_data_error(ei, p, BAD_LINE, ROW_CASES[case])


@pytest.mark.parametrize("action", ["fail", "warn"])
@pytest.mark.parametrize("fmt", list(ROW_FORMATS))
def test_gap_longer_than_max_gap(tmp_path, fmt, action):
    # From line 51 on every time is 0.1 s later: one 0.11 s step, above max_gap = 0.05 s.
    make, sep, tcol, write, read = ROW_FORMATS[fmt]
    lines, gap_line = make(), 51
    shift = 100 if fmt == "drive" else 0.1   # drive ticks are in ms
    for i in range(gap_line - 1, len(lines)):
        if lines[i]:
            toks = _split(lines[i], sep)
            toks[tcol] = repr(float(toks[tcol]) + shift) if fmt != "drive" else str(int(toks[tcol]) + shift)
            lines[i] = (sep or " ").join(toks)
    p = write(tmp_path / "imu.txt", lines)
    if action == "fail":
        with pytest.raises(DataError) as ei:
            read(p, max_gap=0.05, gap_action="fail")
        assert_data_error(ei, p, gap_line, r"1 gap\(s\) longer than 0.05 s.*0\.110 s")
    else:
        with pytest.warns(UserWarning, match=rf"{re.escape(str(p))}, line {gap_line}: 1 gap"):
            imu = read(p, max_gap=0.05, gap_action="warn")
        assert len(imu) == N - 1                       # data still returned, gap included
        assert imu.dt.max() == pytest.approx(0.11, abs=1e-6)
        assert np.sum(imu.dt > 0.05) == 1


RATE_HEAD_RAD = "time[s],wx[rad/s],wy[rad/s],wz[rad/s],fx[m/s^2],fy[m/s^2],fz[m/s^2]"
RATE_HEAD_G = "time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[g],fy[g],fz[g]"


@pytest.mark.parametrize("written, gyro_scale, declared, words", [
    # A turn at 30 deg/s written in deg/s but declared rad/s: 30 "rad/s" is beyond any vehicle.
    (IMU_RATE_HEAD, 3.0, RATE_HEAD_RAD, r"declared in 'rad/s'.*unit is probably wrong"),
    # Accelerometer written in g but declared m/s^2: |f| is 1 "m/s^2".
    (RATE_HEAD_G, 1.0, IMU_RATE_HEAD, r"median specific force is 1 m/s\^2 .*declared in 'm/s\^2'"),
    # Accelerometer written in m/s^2 but declared g: |f| is 9.8 "g" = 96 m/s^2.
    (IMU_RATE_HEAD, 1.0, RATE_HEAD_G, r"median specific force is 96.17 .*declared in 'g'"),
])
def test_generic_imu_implausible_for_declared_units(tmp_path, written, gyro_scale, declared, words):
    lines = generic_imu_rate_lines(written, gyro_scale=gyro_scale)
    lines[0] = declared
    p = write_lines(tmp_path / "imu.csv", lines)
    with pytest.raises(DataError) as ei:
        read_imu_csv(p)
    assert_data_error(ei, p, None, words)


def test_generic_imu_10_deg_s_declared_rad_s_is_refused(tmp_path):
    lines = generic_imu_rate_lines(IMU_RATE_HEAD)
    lines[0] = RATE_HEAD_RAD
    p = write_lines(tmp_path / "imu.csv", lines)
    with pytest.raises(DataError, match="rad/s"):
        read_imu_csv(p)


@pytest.mark.parametrize("header, words", [
    ("time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],speed[m/s]", r"unknown column 'speed'"),
    ("time[s],wx[deg/s],wy[deg/s],wz,fx[m/s^2],fy[m/s^2],fz[m/s^2]", r"header column 'wz' is not 'name\[unit\]'"),
    ("time[s],wx[m/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],fz[m/s^2]", r"column 'wx'.*angular rate"),
    ("time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],fz[furlong]", r"column 'fz'.*furlong"),
    ("time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],fy[m/s^2]", r"appears twice"),
    ("time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],dvz[m/s]", r"not a known layout"),
])
def test_generic_bad_header(tmp_path, header, words):
    lines = generic_imu_rate_lines()
    lines[0] = header
    p = write_lines(tmp_path / "imu.csv", lines)
    with pytest.raises(DataError) as ei:
        read_imu_csv(p)
    assert_data_error(ei, p, 1, words)


def test_generic_gnss_zero_sigma(tmp_path):
    lines = _generic_gnss_lines("time[s],lat[deg],lon[deg],height[m],sd_n[m],sd_e[m],sd_d[m]")
    toks = lines[3].split(",")
    toks[6] = "0.0"
    lines[3] = ",".join(toks)
    p = write_lines(tmp_path / "g.csv", lines)
    with pytest.raises(DataError) as ei:
        read_gnss_csv(p)
    assert_data_error(ei, p, 4, r"standard deviations must be positive")


# --- empty inputs -------------------------------------------------------------------------------
def _write_drive_text(path, lines):
    return write_drive(path, lines, tag_end_ms=1000)


EMPTY_CASES = {
    # id: (lines, writer, reader, expected line, message)
    "kfgins empty": ([], write_lines, read_kfgins_imu, None, r"KF-GINS IMU file is empty"),
    "kfgins blank lines only": (["", "  "], write_lines, read_kfgins_gnss, None, r"file is empty"),
    "kfgins one line": (kfgins_imu_lines()[:1], write_lines, read_kfgins_imu, None, r"at least two"),
    "generic empty": ([], write_lines, read_imu_csv, 1, r"IMU file is empty \(no header line\)"),
    "generic header only": ([IMU_RATE_HEAD], write_lines, read_imu_csv, 1,
                            r"IMU file is empty: no data line after the header"),
    "generic header then blank lines": ([IMU_RATE_HEAD, "", " "], write_lines, read_imu_csv, 1,
                                        r"no data line after the header"),
    "generic gnss header only": (["time[s],lat[deg],lon[deg],height[m],sd_n[m],sd_e[m],sd_d[m]"],
                                 write_lines, read_gnss_csv, 1, r"GNSS file is empty: no data line after"),
    "generic reference empty": ([], write_lines, read_reference_csv, 1, r"reference file is empty"),
    "drive empty": ([], _write_drive_text, read_drive_imu, None, r"IMU file is empty"),
    "drive only the two edge lines": (drive_rows()[:2], _write_drive_text, read_drive_imu, None,
                                      r"IMU file is empty"),
    "drive one kept line": (drive_rows()[:3], _write_drive_text, read_drive_imu, None, r"at least two"),
    "pos header only": (POS_PREAMBLE + [POS_COLS], write_lines, read_pos, None, r"empty \(no data lines\)"),
    "psins comments only": (PSINS_COMMENTS, write_lines, lambda p: read_psins_imu(p), 4,
                            r"ends before the three header lines"),
    "psins header without data": (PSINS_COMMENTS + [PSINS_H1, PSINS_H2, PSINS_H3], write_lines,
                                  read_psins_imu, 4, r"ends before"),
}


@pytest.mark.parametrize("case", list(EMPTY_CASES))
def test_empty_inputs(tmp_path, case):
    lines, write, read, line, words = EMPTY_CASES[case]
    p = write(tmp_path / "f.txt", lines)
    with pytest.raises(DataError) as ei:
        read(p)
    assert_data_error(ei, p, line, words)


# --- missing files --------------------------------------------------------------------------------
MISSING = {
    "read_numeric": lambda p: read_numeric(p, 3),
    "read_time_tag": read_time_tag,
    "read_drive_imu": read_drive_imu,
    "read_pos": read_pos,
    "read_kfgins_imu": read_kfgins_imu,
    "read_kfgins_gnss": read_kfgins_gnss,
    "read_kfgins_nav": read_kfgins_nav,
    "read_imu_csv": read_imu_csv,
    "read_gnss_csv": read_gnss_csv,
    "read_reference_csv": read_reference_csv,
    "read_psins_imu": read_psins_imu,
}


@pytest.mark.parametrize("read", list(MISSING.values()), ids=list(MISSING))
def test_missing_file(tmp_path, read):
    p = tmp_path / "no_such_file.txt"
    with pytest.raises(DataError) as ei:
        read(p)
    # read_drive_imu looks for the tag first: either name is right as long as it is the missing one.
    assert ei.value.file in (str(p), str(p) + ".tag")
    assert_data_error(ei, ei.value.file, None, r"does not exist")


def test_drive_missing_csv_with_tag_present(tmp_path):
    p = tmp_path / "imu.csv"
    Path(str(p) + ".tag").write_bytes(tag_bytes())
    with pytest.raises(DataError) as ei:
        read_drive_imu(p)
    assert_data_error(ei, p, None, r"IMU file does not exist")


# --- drive-0708: bad time-tag files -----------------------------------------------------------------
GOOD_TAG = tag_bytes()
TAG_CASES = {
    # A pair is 8 bytes: 3 bytes off the end leave 5 stray bytes.
    "cut inside a pair": (GOOD_TAG[:-3], r"truncated: 5 stray bytes.*byte 92"),
    "cut inside the fixed part": (GOOD_TAG[:70], r"truncated: 70 bytes.*need 84"),
    "header and fixed part, no pair": (GOOD_TAG[:76], r"truncated: 76 bytes"),
    "no TIMETAG header": (tag_bytes(header=b"RTKLIB demo5 TIMETAG"), r"does not start with 'TIMETAG'"),
    "ticks decreasing": (tag_bytes(ticks=(0, 1000, 900)), r"corrupt.*ticks decreasing"),
    "fraction of a second >= 1": (tag_bytes(frac=1.5), r"corrupt.*fraction"),
    "empty file": (b"", r"truncated: 0 bytes"),
}


@pytest.mark.parametrize("case", list(TAG_CASES))
def test_bad_time_tag(tmp_path, case):
    data, words = TAG_CASES[case]
    p = tmp_path / "imu.csv.tag"
    p.write_bytes(data)
    with pytest.raises(DataError) as ei:
        read_time_tag(p)
    assert_data_error(ei, p, None, words)   # a binary file has no lines
    # read_drive_imu passes the same error on.
    write_lines(tmp_path / "imu.csv", drive_rows())
    with pytest.raises(DataError) as ei:
        read_drive_imu(tmp_path / "imu.csv")
    assert_data_error(ei, p, None, words)


@pytest.mark.parametrize("edit", ["last line cut mid-record", "first line cut inside the tick",
                                  "trailing blank line"])
def test_drive_partial_edge_lines_are_ignored(tmp_path, edit):
    rows = drive_rows()
    ref = read_drive_imu(write_drive(tmp_path / "ref.csv", rows))
    if edit == "last line cut mid-record":
        rows[-1] = rows[-1][:15]            # "0.000000000,0.0": the logger stopped mid-line
    elif edit == "first line cut inside the tick":
        rows[0] = rows[0][-2:]              # "00" : the tail of a line whose tick was 5000
    else:
        rows.append("")
    p = write_drive(tmp_path / "imu.csv", rows, tag_end_ms=(N + 1) * 10)
    imu = read_drive_imu(p)
    assert len(imu) == len(ref)
    # A blank line is no data: nothing may change (1e-6 s: float rounding near 1.75e9 s). When an
    # edge line is cut its tick is lost, so the span is known to one sample (10 ms) only.
    tol = 1e-6 if edit == "trailing blank line" else 0.011
    np.testing.assert_allclose(imu.time, ref.time, rtol=0, atol=tol)


# --- RTKLIB .pos: bad files ----------------------------------------------------------------------------
def _pos_edit(line_no, fn):
    def make():
        lines = pos_lines()
        lines[line_no - 1] = fn(lines[line_no - 1], lines[line_no - 2])
        return lines
    return make


def _tok(i, value):
    return lambda line, prev: " ".join(line.split()[:i] + [value] + line.split()[i + 1:])


L2 = POS_FIRST_LINE + 2   # 1-based file line of the second epoch
POS_CASES = {
    "no header": (lambda: pos_lines()[POS_FIRST_LINE:], None, 1, r"no RTKLIB column header"),
    "comments but no column header": (lambda: POS_PREAMBLE + pos_lines()[POS_FIRST_LINE:], None, 2,
                                      r"no RTKLIB column header \('%  GPST"),
    "UTC time": (lambda: POS_PREAMBLE + [POS_COLS.replace("GPST", "UTC ") + POS_VEL] + pos_lines()[3:], None,
                 POS_FIRST_LINE, r"UTC time stamps are not supported"),
    "missing column": (_pos_edit(L2, lambda ln, p: ln.rsplit(" ", 1)[0]), None, L2, r"expected 24 fields, found 23"),
    "extra column": (_pos_edit(L2, lambda ln, p: ln + " 0.0"), None, L2, r"expected 24 fields, found 25"),
    "text in a number": (_pos_edit(L2, _tok(3, "abc")), None, L2, r"cannot read .*'abc'"),
    "bad date": (_pos_edit(L2, _tok(0, "2025/13/08")), None, L2, r"cannot read this RTKLIB solution line"),
    "NaN": (_pos_edit(L2, _tok(4, "nan")), None, L2, r"non-finite value"),
    "time backwards": (_pos_edit(L2, lambda ln, p: " ".join(p.split()[:2] + ln.split()[2:]).replace(
        ".499", ".399", 1)), None, L2, r"solution time goes backwards"),
    "time repeats": (_pos_edit(L2, lambda ln, p: " ".join(p.split()[:2] + ln.split()[2:])), None, L2,
                     r"solution time repeats"),
    "gap": (lambda: pos_lines(t_ms=GNSS_T0_MS + 250 * np.arange(5) + 1000 * (np.arange(5) > 0)),
            dict(max_gap=0.3, gap_action="fail"), L2,
            r"1 gap\(s\) longer than 0.3 s in the solution; the first, 1.250 s"),
    "latitude beyond 90": (_pos_edit(L2, _tok(2, "95.000000000")), None, L2, r"latitude outside"),
}


@pytest.mark.parametrize("case", list(POS_CASES))
def test_bad_pos(tmp_path, case):
    make, kw, line, words = POS_CASES[case]
    p = write_lines(tmp_path / "a.pos", make())
    with pytest.raises(DataError) as ei:
        read_pos(p, **(kw or {}))
    assert_data_error(ei, p, line, words)


def test_pos_gap_warns_and_returns_data(tmp_path):
    t_ms = GNSS_T0_MS + 250 * np.arange(5) + 1000 * (np.arange(5) > 0)
    p = write_lines(tmp_path / "a.pos", pos_lines(t_ms=t_ms))
    with pytest.warns(UserWarning, match=rf"line {L2}: 1 gap"):
        s = read_pos(p, max_gap=0.3)
    np.testing.assert_allclose(s.time, t_ms / 1000, rtol=0, atol=1e-6)   # all five epochs kept


# --- PSINS: bad files ---------------------------------------------------------------------------------
H2_LINE = len(PSINS_COMMENTS) + 2


def _psins_edit(line_no, new):
    def make():
        lines = psins_lines(20)
        lines[line_no - 1] = new
        return lines
    return make


PSINS_CASES = {
    "header with 5 numbers": (_psins_edit(H2_LINE, "34.246 108.91 380.0 100.0 10.0"), H2_LINE,
                              r"expected 6 numbers, got 5"),
    "text in header": (_psins_edit(H2_LINE + 1, "0.1 0.1 abc 125 125 125"), H2_LINE + 1,
                       r"expected 6 numbers, got '0.1 0.1 abc"),
    "NaN in header": (_psins_edit(H2_LINE - 1, "1 2 nan 0 0 0"), H2_LINE - 1, r"non-finite"),
    "zero sampling interval": (_psins_edit(H2_LINE, "34.246 108.91 380.0 100.0 0 9.7936"), H2_LINE,
                               r"sampling interval must be positive"),
    "data with 5 numbers": (_psins_edit(PSINS_DATA_LINE + 3, "1 2 3 4 5"), PSINS_DATA_LINE + 3,
                            r"expected 6 columns, found 5"),
    "text in data": (_psins_edit(PSINS_DATA_LINE + 3, "1 2 x 4 5 6"), PSINS_DATA_LINE + 3,
                     r"not a number: 'x'"),
    "NaN in data": (_psins_edit(PSINS_DATA_LINE + 3, "1 2 nan 4 5 6"), PSINS_DATA_LINE + 3,
                    r"non-finite value"),
}


@pytest.mark.parametrize("case", list(PSINS_CASES))
def test_bad_psins(tmp_path, case):
    make, line, words = PSINS_CASES[case]
    p = write_lines(tmp_path / "a.imu", make())
    with pytest.raises(DataError) as ei:
        read_psins_imu(p)
    assert_data_error(ei, p, line, words)


@pytest.mark.parametrize("bad", ["1 2 nan 4 5 6", "1 2 x 4 5 6"])
def test_psins_blank_line_before_a_bad_line(tmp_path, bad):
    lines = psins_lines(20)
    lines.insert(PSINS_DATA_LINE + 1, "")          # blank file line PSINS_DATA_LINE + 2
    bad_line = PSINS_DATA_LINE + 4
    lines[bad_line - 1] = bad
    p = write_lines(tmp_path / "a.imu", lines)
    with pytest.raises(DataError) as ei:
        read_psins_imu(p)
    assert ei.value.line == bad_line


# ===========================================================================
# 3. Real data (../shared/data/drive-0708), skipped when absent
# ===========================================================================
@pytest.fixture(scope="module")
def real_imu():
    return read_drive_imu(data_file("drive-0708", "imu_1934.csv"))


@pytest.fixture(scope="module")
def real_pos():
    return read_pos(data_file("drive-0708", "gnss_1934_sf.pos"))


def test_real_drive_imu(real_imu):
    # 54860 lines, the two edge lines dropped: 54858 samples, 54857 increments.
    assert len(real_imu) == 54857
    # 100 Hz from a millisecond tick counter: 10 +- 1 ms, jitter up to ~2 ms.
    assert 0.007 <= real_imu.dt.min() and real_imu.dt.max() <= 0.012
    assert np.median(real_imu.dt) == pytest.approx(0.01, abs=2e-4)
    # A car spends most of the time near 1 g of specific force.
    f = np.linalg.norm(real_imu.dvel / real_imu.dt[:, None], axis=1)
    assert np.median(f) / G0 == pytest.approx(1.02, abs=0.02)
    tag = read_time_tag(data_file("drive-0708", "imu_1934.csv.tag"))
    # Times lie within the tag's span, moved by the -0.125 s latency.
    assert tag.start - 0.125 <= real_imu.start_time and real_imu.time[-1] <= tag.end - 0.125 + 1e-6


def test_real_pos(real_pos):
    assert len(real_pos.time) == 2197
    assert int(np.sum(real_pos.quality == 1)) == 2189
    assert real_pos.vel_ned is not None and real_pos.sd_vel is not None
    assert len(real_pos.fixes(qualities=[1])) == 2189
    # 4 Hz, first epoch 2025/07/08 19:34:18.499 GPST.
    assert real_pos.time[0] == pytest.approx(1752003258.499, abs=1e-6)
    assert np.median(np.diff(real_pos.time)) == pytest.approx(0.25, abs=1e-6)
    # Boulder, Colorado.
    assert np.degrees(real_pos.lla[0, :2]) == pytest.approx([40.0966268, -105.1474483], abs=1e-7)


def test_real_imu_and_gnss_spans_overlap(real_imu, real_pos):
    lo = max(real_imu.start_time, real_pos.time[0])
    hi = min(real_imu.time[-1], real_pos.time[-1])
    # Both record the same ~549 s drive: they should share most of it.
    assert hi - lo > 500.0


def test_rtklib_velocity_delay_moves_velocity_to_epoch_times():
    """A velocity valid 0.125 s before each 4 Hz epoch is interpolated to the epoch."""
    import numpy as np
    from mixnav.io.rtklib import PosSolution
    t = 1000.0 + 0.25 * np.arange(8)
    true_v = lambda tt: np.column_stack([2.0 * (tt - 1000.0), -tt + 1000.0, 0.0 * tt])  # noqa: E731
    sol = PosSolution(time=t, lla=np.zeros((8, 3)), quality=np.ones(8, int), n_sat=np.full(8, 9),
                      sd_ned=np.full((8, 3), 0.01), vel_ned=true_v(t - 0.125), sd_vel=np.full((8, 3), 0.05),
                      source="x")
    v = sol.velocity_at_epochs(0.125)
    np.testing.assert_allclose(v[:-1], true_v(t)[:-1], atol=1e-12)
    np.testing.assert_array_equal(v[-1], sol.vel_ned[-1])  # no later velocity: kept as reported
    f = sol.fixes(qualities=(1,), velocity_delay=0.125)
    np.testing.assert_allclose(f.vel_n[:-1], true_v(t)[:-1], atol=1e-12)
    np.testing.assert_array_equal(sol.fixes(qualities=(1,)).vel_n, sol.vel_ned)


def test_rtklib_velocity_delay_interpolates_only_between_the_given_epochs():
    """Oracle: epochs 1.0-1.75 s and 32-33 s (a 30 s hole, as a withheld window leaves):
    the last epoch before the hole has no later velocity within 1.5 intervals, so it keeps
    its reported value instead of taking half of a velocity from inside the hole."""
    from mixnav.io.rtklib import velocity_at_epochs
    t = np.concatenate([1.0 + 0.25 * np.arange(4), 32.0 + 0.25 * np.arange(5)])
    v = np.column_stack([t, -t, 0 * t])
    out = velocity_at_epochs(t, v, 0.125)
    np.testing.assert_array_equal(out[3], v[3])
    np.testing.assert_allclose(out[:3, 0], t[:3] + 0.125)   # v(t) = t reported at t - 0.125 -> t + 0.125
    assert velocity_at_epochs(t, None, 0.125) is None


def test_drive0708_withheld_velocities_do_not_leak_into_the_kept_fixes():
    """issue 34: the velocity-delay interpolation ran over every fix before the windows
    were withheld, so the last fix before a window carried half of the first withheld
    velocity. Now the last kept fix before each window keeps its reported velocity (its
    next kept neighbour is 30 s away), a kept fix away from the windows is interpolated
    as before, and the velocity the filter gets is the same whatever lies in the window."""
    from dataclasses import replace
    from mixnav.config import load_dataset
    from mixnav.experiment.pipelines import ins_fixes
    from mixnav.io.rtklib import read_pos
    folder = data_file("drive-0708")
    ds, src, _ = load_dataset("drive-0708-aided")
    inputs = ins_fixes.load(ds, src, folder)
    po = ins_fixes.run(ds, src, folder, inputs)
    pos = read_pos(folder / ds.gnss.file)
    t0 = inputs.imu.start_time
    sel = pos.select(ds.gnss.qualities)
    reported = dict(zip(np.round(pos.time[sel] - t0, 3), pos.vel_ned[sel]))
    for a, b in ds.gnss.withhold:
        k = np.flatnonzero(po.fixes.time < a)[-1]
        np.testing.assert_array_equal(po.fixes.vel_n[k], reported[round(po.fixes.time[k], 3)])
    # away from the windows: the same interpolation as over the whole file
    i = np.flatnonzero((po.all_fixes.time > 300.0) & (po.all_fixes.time < 301.0))
    j = np.flatnonzero((po.fixes.time > 300.0) & (po.fixes.time < 301.0))
    np.testing.assert_allclose(po.fixes.vel_n[j], po.all_fixes.vel_n[i], atol=1e-12)
    # what lies inside a window does not reach the filter's fixes
    changed = replace(inputs.fixes, vel_n=np.where(
        np.isin(np.round(inputs.fixes.time - t0, 3), np.round(po.all_fixes.time[
            (po.all_fixes.time >= 133.0) & (po.all_fixes.time <= 163.0)], 3))[:, None], 99.0, inputs.fixes.vel_n))
    po2 = ins_fixes.run(ds, src, folder, replace(inputs, fixes=changed))
    np.testing.assert_array_equal(po2.fixes.vel_n, po.fixes.vel_n)
