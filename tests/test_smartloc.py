"""smartLoc reader and pseudorange residuals against ground truth (mixnav.io.smartloc).

1. Synthetic: satellites and a moving receiver chosen here, pseudoranges
   built independently of the code (satellite placed in the reception-time
   frame, then turned back by OMEGA_E tau into the transmit-time frame the
   data set uses), written in the smartLoc format, read back: residuals are
   zero to 1e-6 m and the clock comes back; NLOS outliers do not move the
   median clock.
2. Malformed files raise DataError naming the file and the line.
3. The real Berlin Potsdamer Platz files (skipped without ../shared/data).
"""

import numpy as np
import pytest

from mixnav.errors import DataError
from mixnav.geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from mixnav.gnss.geometry import C_LIGHT, earth_rotation_correction
from mixnav.io.smartloc import (SmartlocTruth, clock_per_epoch, geometric_range, pseudorange_residuals,
                                read_ground_truth, read_pseudoranges, read_smartloc)

from .conftest import data_file

LAT, LON, H = np.deg2rad(52.5096), np.deg2rad(13.3760), 40.0   # Potsdamer Platz


def _sat_positions(rx, az_el_range):
    """Satellites in the *reception-time* frame at given azimuth, elevation [deg] and range [m]."""
    C_ne = dcm_ecef_to_ned(LAT, LON)
    out = []
    for az, el, rho in az_el_range:
        a, e = np.deg2rad(az), np.deg2rad(el)
        u_n = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), -np.sin(e)])
        out.append(rx + rho * (C_ne.T @ u_n))
    return np.array(out)


# (system, id, azimuth, elevation, range)
SATS = [(1, 2, 30, 60, 20.4e6), (1, 5, 120, 35, 21.9e6), (1, 12, 200, 80, 20.2e6), (1, 17, 290, 15, 24.1e6),
        (1, 25, 330, 45, 21.0e6), (4, 301, 60, 25, 21.5e6), (4, 310, 170, 70, 19.4e6),
        (4, 319, 250, 40, 20.3e6)]


def make_synthetic(n_epochs=12, nlos=None, dt=0.2):
    """Rows (time, pseudorange, variance, sat xyz, id, sys, el, cn0), GT rows, true ranges and clocks."""
    rx0 = lla_to_ecef(np.array([LAT, LON, H]))
    v = np.array([8.0, -3.0, 2.0])                   # [m/s] straight line: interpolation is exact
    times = np.arange(n_epochs) * dt
    rows, truth_range, clocks = [], [], {}
    for k, t in enumerate(times):
        rx = rx0 + v * t
        clk = {1: -1.4e5 - 50.0 * t, 4: -1.4e5 - 50.0 * t + 7.5}       # receiver clock + ISB [m]
        clocks[k] = clk
        sats = _sat_positions(rx, [(az + 0.5 * k, el, rho + 700.0 * k) for _, _, az, el, rho in SATS])
        for (sys_, sid, az, el, _), p in zip(SATS, sats):
            rho = float(np.linalg.norm(p - rx))        # geometric range in the reception-time frame
            tau = rho / C_LIGHT
            p_tx = earth_rotation_correction(p, -tau)  # the same point in the transmit-time frame
            extra = nlos(k, sid) if nlos else 0.0
            rows.append((t, rho + clk[sys_] + extra, 25.0, *p_tx, sid, sys_, el, 45.0))
            truth_range.append(rho)
    # ground truth every second epoch, plus the last one
    gt_t = np.r_[times[::2], times[-1]] if (n_epochs - 1) % 2 else times[::2]
    gt = [(t, *(rx0 + v * t)) for t in gt_t]
    return rows, gt, np.array(truth_range), clocks


def write_files(tmp_path, rows, gt, extra_input_lines=(), extra_gt_lines=()):
    inp = tmp_path / "X_Input.txt"
    out = []
    for i, r in enumerate(rows):
        if i % 8 == 0:
            out.append(f"odom3 {float(r[0])!r} 5.0 0 0 0 0 0.01 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06   ")
        t, p, var, x, y, z, sid, sys_, el, cn0 = (float(v) for v in r)
        sid, sys_ = int(sid), int(sys_)
        out.append(f"pseudorange3 {t!r} {p!r} {var!r} {x!r} {y!r} {z!r} {sid} {sys_} {el!r} {cn0!r}       ")
    inp.write_text("\n".join(list(out) + list(extra_input_lines)) + "\n")
    gtf = tmp_path / "X_GT.txt"
    gtf.write_text("\n".join([f"point3 {float(t)!r} {float(x)!r} {float(y)!r} {float(z)!r} 0 0 0 0 0 0 0 0 0"
                              for t, x, y, z in gt]
                             + list(extra_gt_lines)) + "\n")
    return inp, gtf


# ---------------------------------------------------------------------------
# 1. synthetic
# ---------------------------------------------------------------------------
def test_synthetic_round_trip_residuals_are_zero(tmp_path):
    rows, gt, rho, clocks = make_synthetic()
    inp, gtf = write_files(tmp_path, rows, gt)
    pr, truth = read_smartloc(tmp_path, "X")
    assert len(pr) == len(rows) and len(truth) == len(gt)
    np.testing.assert_array_equal(pr.pseudorange, [r[1] for r in rows])
    np.testing.assert_array_equal(pr.sat_ecef, np.array([r[3:6] for r in rows]))
    np.testing.assert_allclose(np.rad2deg(pr.elevation), [r[8] for r in rows])
    assert pr.line[0] == 2 and truth.line[0] == 1      # line 1 of the input is an odom3 row
    assert pr.labels[:3] == ["G02", "G05", "G12"] and pr.labels[5] == "R301"

    res = pseudorange_residuals(pr, truth)
    np.testing.assert_allclose(res.range, rho, rtol=0, atol=1e-6)
    assert np.all(res.valid)
    assert np.max(np.abs(res.residual)) < 1e-6
    for k, clk in clocks.items():
        np.testing.assert_allclose(res.clock_bias[k], [clk[1], clk[4]], rtol=0, atol=1e-6)
    assert res.channel_names == ["G02", "G05", "G12", "G17", "G25", "R301", "R310", "R319"]
    ch = res.channels()
    assert ch.shape == (12, 8) and np.all(np.isfinite(ch))
    # Huber clock on noise-free data is exact too
    assert np.max(np.abs(pseudorange_residuals(pr, truth, clock="huber").residual)) < 1e-6


def test_without_earth_rotation_residuals_are_metres():
    rows, gt, _, _ = make_synthetic(4)
    pr = _as_pr(rows)
    truth = SmartlocTruth(np.array([g[0] for g in gt]), np.array([g[1:] for g in gt]), np.arange(len(gt)))
    res = pseudorange_residuals(pr, truth, earth_rotation=False)
    # Sagnac: OMEGA_E / c (x_s y_r - y_s x_r), up to ~30 m; not removed by a common clock
    assert 1.0 < np.max(np.abs(res.residual)) < 40.0


def _as_pr(rows):
    from mixnav.io.smartloc import SmartlocPseudoranges
    a = np.array(rows, dtype=float)
    return SmartlocPseudoranges(a[:, 0], a[:, 1], a[:, 2], a[:, 3:6], a[:, 6].astype(int), a[:, 7].astype(int),
                                np.deg2rad(a[:, 8]), a[:, 9], np.arange(len(a)) + 1)


def test_nlos_outliers_do_not_move_the_median_clock():
    # one GPS satellite per epoch 60..150 m long (NLOS), rotating through the satellites
    bad = {1: 2, 2: 5, 3: 12, 4: 17, 5: 25}
    rows, gt, _, clocks = make_synthetic(10, nlos=lambda k, sid: 60.0 + 10 * k if bad.get(1 + k % 5) == sid
                                         else 0.0)
    pr = _as_pr(rows)
    truth = SmartlocTruth(np.array([g[0] for g in gt]), np.array([g[1:] for g in gt]), np.arange(len(gt)))
    res = pseudorange_residuals(pr, truth)
    is_bad = np.array([bad.get(1 + int(round(r[0] / 0.2)) % 5) == r[6] for r in rows])
    assert is_bad.sum() == 10
    np.testing.assert_allclose(res.residual[~is_bad], 0.0, atol=1e-6)
    np.testing.assert_allclose(res.residual[is_bad], 60.0 + 10 * np.arange(10), atol=1e-6)
    # a mean clock would have moved by outlier / 5 and biased every other residual
    mean_clk = np.array([np.mean(res.raw[(res.epoch == k) & (pr.system == 1)]) for k in range(10)])
    assert np.all(mean_clk - np.array([clocks[k][1] for k in range(10)]) > 10.0)


def test_small_groups_are_left_out_and_counted():
    rows, gt, _, _ = make_synthetic(3)
    rows = [r for r in rows if not (r[7] == 4 and r[6] == 319)]        # 2 GLONASS left per epoch
    pr = _as_pr(rows)
    truth = SmartlocTruth(np.array([g[0] for g in gt]), np.array([g[1:] for g in gt]), np.arange(len(gt)))
    res = pseudorange_residuals(pr, truth)
    assert res.counts["small_group"] == 6 and res.counts["valid"] == 15
    assert np.all(np.isnan(res.residual[pr.system == 4])) and np.all(np.isnan(res.clock_bias[:, 1]))
    assert np.all(np.isnan(res.channels()[:, 5:]))
    res2 = pseudorange_residuals(pr, truth, min_satellites=2)
    assert res2.counts["small_group"] == 0
    # two satellites: +-half their difference, a symmetric pair
    g = res2.channels()[:, 5:]
    np.testing.assert_allclose(g[:, 0], -g[:, 1], atol=1e-9)


def test_rows_outside_truth_are_excluded_and_counted():
    rows, gt, _, _ = make_synthetic(6)
    pr = _as_pr(rows)
    truth = SmartlocTruth(np.array([g[0] for g in gt[:-1]]), np.array([g[1:] for g in gt[:-1]]),
                          np.arange(len(gt) - 1))
    res = pseudorange_residuals(pr, truth)
    assert res.counts["outside_truth"] == 8            # the last epoch (t = 1.0 s > 0.8 s)
    assert res.n_epochs == 5 and np.all(res.epoch[-8:] == -1)
    with pytest.raises(ValueError, match="outside the ground truth"):
        truth.position_at([1.0])
    far = SmartlocTruth(truth.time + 100.0, truth.pos_ecef, truth.line)
    with pytest.raises(ValueError, match="no pseudorange time"):
        pseudorange_residuals(pr, far)


def test_geometric_range_fixed_point_and_clock_arguments():
    rx = lla_to_ecef(np.array([LAT, LON, H]))[None]
    p = _sat_positions(rx[0], [(45, 30, 2.2e7)])
    rho = np.linalg.norm(p - rx, axis=1)
    p_tx = earth_rotation_correction(p, -rho / C_LIGHT)
    np.testing.assert_allclose(geometric_range(rx, p_tx), rho, rtol=0, atol=1e-7)
    assert abs(geometric_range(rx, p_tx, iterations=0) - rho)[0] > 1.0
    with pytest.raises(ValueError, match="median"):
        clock_per_epoch(np.zeros(3), np.zeros(3, int), np.ones(3, int), method="mean")
    with pytest.raises(ValueError, match="min_satellites"):
        clock_per_epoch(np.zeros(3), np.zeros(3, int), np.ones(3, int), min_satellites=0)


def test_huber_clock_is_a_robust_mean():
    rng = np.random.default_rng(4)
    raw = np.r_[rng.normal(0.0, 3.0, 9), 150.0]
    b_med, _, _, per_row = clock_per_epoch(raw, np.zeros(10, int), np.ones(10, int))
    b_hub, _, _, _ = clock_per_epoch(raw, np.zeros(10, int), np.ones(10, int), method="huber")
    assert np.all(per_row == b_med[0, 0])
    # leave one out: each row gets the median of the others of its group
    raw4 = np.array([0.0, 1.0, 2.0, 10.0, 5.0, 7.0, 6.0])
    ep4, sy4 = np.array([0, 0, 0, 0, 1, 1, 1]), np.array([1, 1, 1, 1, 4, 4, 4])
    b4, systems, count, loo = clock_per_epoch(raw4, ep4, sy4, leave_one_out=True)
    np.testing.assert_array_equal(loo, [2.0, 2.0, 1.0, 1.0, 6.5, 5.5, 6.0])
    np.testing.assert_array_equal(b4, [[1.5, np.nan], [np.nan, 6.0]])
    assert systems.tolist() == [1, 4] and count.tolist() == [[4, 0], [0, 3]]
    assert b_med[0, 0] == pytest.approx(np.median(raw))
    assert abs(b_hub[0, 0] - np.mean(raw[:9])) < 2.0 < abs(np.mean(raw) - np.mean(raw[:9]))


# ---------------------------------------------------------------------------
# 2. malformed files
# ---------------------------------------------------------------------------
GOOD = ("pseudorange3 0 19949087.65 25 14567933.9 2809850.9 21875628.0 12 1 85.1 49\n"
        "pseudorange3 0 19713469.01 64 18145814.9 11532054.1 13684003.6 320 4 58.1 40\n"
        "pseudorange3 0.2 19949088.65 25 14567933.9 2809850.9 21875628.0 12 1 85.1 49\n")


@pytest.mark.parametrize("bad, match", [
    ("pseudorange3 0.4 1.9e7 25 1.4e7 2.8e6 2.1e7 12 1 85.1\n", "11 fields, found 10"),
    ("pseudorange3 0.4 1.9e7 25 1.4e7 2.8e6 2.1e7 12 1 85.1 abc\n", "column 11: 'abc' is not a number"),
    ("pseudorange3 0.4 1.9e7 nan 1.4e7 2.8e6 2.1e7 12 1 85.1 40\n", "column 4: 'nan' is not finite"),
    ("pseudorange3 0.1 1.9e7 25 1.4e7 2.8e6 2.1e7 12 1 85.1 40\n", "time goes backwards"),
    ("pseudorange3 0.2 1.9e7 25 1.4e7 2.8e6 2.1e7 12 1 85.1 40\n", "G12 appears twice at time 0.2"),
    ("pseudorange3 0.4 1.9e7 25 1.4e7 2.8e6 2.1e7 12 3 85.1 40\n", "unknown satellite system code"),
    ("pseudorange3 0.4 1.9e7 25 1.4e7 2.8e6 2.1e7 12.5 1 85.1 40\n", "satellite id"),
    ("pseudorange3 0.4 1.9e7 0 1.4e7 2.8e6 2.1e7 12 1 85.1 40\n", "variance"),
    ("pseudorange3 0.4 1.9e7 25 1.4e3 2.8e3 2.1e3 12 1 85.1 40\n", "satellite position"),
    ("pseudorange3 0.4 1.9e7 25 1.4e7 2.8e6 2.1e7 12 1 95 40\n", "elevation"),
    ("pseudorange4 0.4 1.9e7 25 1.4e7 2.8e6 2.1e7 12 1 85 40\n", "unknown row type 'pseudorange4'"),
])
def test_malformed_input_rows_name_file_and_line(tmp_path, bad, match):
    p = tmp_path / "in.txt"
    p.write_text(GOOD + "odom3 0 5.85 0 0 0 0 -0.006 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06\n" + bad)
    with pytest.raises(DataError, match=match) as ei:
        read_pseudoranges(p)
    assert ei.value.line == 5 and ei.value.file == str(p)


def test_input_without_rows_or_file(tmp_path):
    p = tmp_path / "in.txt"
    p.write_text("odom3 0 5.85 0 0 0 0 -0.006 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06\n\n")
    with pytest.raises(DataError, match="no 'pseudorange3' rows"):
        read_pseudoranges(p)
    with pytest.raises(DataError, match="not found"):
        read_pseudoranges(tmp_path / "nope.txt")


@pytest.mark.parametrize("bad, match", [
    ("point3 0.2 3785105.7 899901.8 5037236.1 0 0 0 0 0 0 0 0 0\n", "time repeats"),
    ("point3 0.1 3785105.7 899901.8 5037236.1 0 0 0 0 0 0 0 0 0\n", "time goes backwards"),
    ("point3 0.4 3785105.7 899901.8 0 0 0 0 0 0 0 0 0 0\n", "ground-truth position"),
    ("point3 0.4 3785105.7 899901.8 5037236.1 0 0 0\n", "14 fields, found 8"),
])
def test_malformed_truth_rows(tmp_path, bad, match):
    p = tmp_path / "gt.txt"
    p.write_text("point3 0 3785108.1 899901.4 5037234.4 0 0 0 0 0 0 0 0 0\n"
                 "point3 0.2 3785106.6 899901.7 5037235.4 0 0 0 0 0 0 0 0 0\n" + bad)
    with pytest.raises(DataError, match=match) as ei:
        read_ground_truth(p)
    assert ei.value.line == 3


# ---------------------------------------------------------------------------
# 3. real data: Berlin Potsdamer Platz
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def berlin():
    folder = data_file("smartloc-berlin", "Berlin_Potsdamer_Platz_Input.txt").parent
    data_file("smartloc-berlin", "Berlin_Potsdamer_Platz_GT.txt")
    return read_smartloc(folder)


def test_real_reader_shapes_and_epochs(berlin):
    pr, gt = berlin
    assert len(pr) == 20038 and len(gt) == 1372
    assert set(np.unique(pr.system)) == {1, 4}
    ep = pr.epoch_times
    assert ep.size == 1372 and np.all(np.diff(ep) > 0)
    assert np.all(np.diff(pr.time) >= 0)
    # 5 Hz with some 0.3 s steps, 283 s; ~14.6 satellites per epoch
    assert 0.19 < np.min(np.diff(ep)) and np.max(np.diff(ep)) < 0.31
    assert 282 < ep[-1] - ep[0] < 284
    assert 14.0 < len(pr) / ep.size < 15.0
    assert np.all((pr.elevation > 0) & (pr.elevation < np.pi / 2))
    # the pseudorange times are truth times (interpolation exact there)
    assert np.all(np.isin(ep, gt.time))


def test_real_truth_is_a_continuous_car_track(berlin):
    _, gt = berlin
    dt = np.diff(gt.time)
    assert np.all(dt > 0) and dt.max() < 0.5
    v = np.linalg.norm(np.diff(gt.pos_ecef, axis=0), axis=1) / dt
    assert v.max() < 15.0                    # a car in town: < 54 km/h (measured max 9.9 m/s)
    assert np.median(v) > 2.0                # and it drives (median 5.8 m/s)
    tm = 0.5 * (gt.time[1:] + gt.time[:-1])
    a = np.linalg.norm(np.diff(np.diff(gt.pos_ecef, axis=0) / dt[:, None], axis=0), axis=1) / np.diff(tm)
    assert np.median(a) < 2.0                # no jumps: typical acceleration of a car (measured 0.6 m/s^2)
    # near Potsdamer Platz, on the ground
    r = np.linalg.norm(gt.pos_ecef, axis=1)
    assert np.all(np.abs(r - 6.365e6) < 2e4)


def test_real_residuals_after_clock_removal(berlin):
    pr, gt = berlin
    res = pseudorange_residuals(pr, gt)
    assert res.counts == {"rows": 20038, "outside_truth": 0, "small_group": 0, "valid": 20038}
    ch = res.channels()
    assert ch.shape == (1372, 19)
    assert np.sum(np.isfinite(ch)) == 20038
    # per epoch and system the median residual is zero for the group's own median clock ...
    own = pseudorange_residuals(pr, gt, leave_one_out=False)
    for sys_ in (1, 4):
        m = pr.system == sys_
        med = np.array([np.median(own.residual[m & (own.epoch == k)]) for k in range(own.n_epochs)])
        assert np.max(np.abs(med)) < 1e-6
    # ... and near zero for the leave-one-out median (default) and the Huber clock (a robust mean)
    hub = pseudorange_residuals(pr, gt, clock="huber", leave_one_out=False)
    for r, tol in ((res, 2.0), (hub, 5.0)):
        med = np.array([np.median(r.residual[r.epoch == k]) for k in range(r.n_epochs)])
        assert np.median(np.abs(med)) < tol
    # the own-median clock makes the median satellite of each odd group exactly zero; leave-one-out does not
    assert np.mean(own.residual == 0.0) > 0.05
    assert np.mean(np.abs(res.residual) < 1e-6) < 1e-3
    # the receiver clock drifts smoothly (~ -50 m/s); GLONASS-GPS offset is a few metres on median
    clk = res.clock_bias[:, 0]
    rate = np.polyfit(res.epoch_times, clk, 1)[0]
    assert -60.0 < rate < -40.0
    assert abs(np.median(res.clock_bias[:, 1] - res.clock_bias[:, 0])) < 5.0


def test_real_residuals_need_the_earth_rotation(berlin):
    pr, gt = berlin
    spread = {}
    for er in (True, False):
        v = pseudorange_residuals(pr, gt, earth_rotation=er).residual
        spread[er] = 1.4826 * np.median(np.abs(v - np.median(v)))
    # measured 23.5 m with the rotation, 30.8 m without
    assert spread[True] < 26.0 < 28.0 < spread[False]
    # the high line-of-sight satellite G12 (85 deg) is much tighter than the pool (measured 9.2 m)
    res = pseudorange_residuals(pr, gt)
    g12 = res.channels()[:, res.channel_names.index("G12")]
    assert 1.4826 * np.nanmedian(np.abs(g12 - np.nanmedian(g12))) < 0.5 * spread[True]


# ---------------------------------------------------------------------------
# one raw-GNSS type: the registered reader gives corrected RawPseudoranges
# ---------------------------------------------------------------------------
def _reader_output(tmp_path, rows=None):
    from mixnav.io.readers import ReadOptions, get_reader
    rows = make_synthetic()[0] if rows is None else rows
    inp, _ = write_files(tmp_path, rows, make_synthetic()[1])
    return read_pseudoranges(inp), get_reader("raw-gnss", "smartloc")(inp, ReadOptions())


def test_the_registered_reader_gives_corrected_raw_pseudoranges(tmp_path):
    """The raw-GNSS reader of format ``smartloc`` returns the one raw type with the file's rows
    (corrected, satellites and variances given, week 0, the log's seconds), and its epochs
    are, byte for byte, those the file's rows grouped directly give (what the reader of the
    old ``corrected-pseudoranges`` kind returned)."""
    from mixnav.data import RawPseudoranges
    from mixnav.gnss.pseudoranges import PseudorangeEpochs
    pr, raw = _reader_output(tmp_path)
    assert isinstance(raw, RawPseudoranges) and raw.corrected
    assert (raw.week == 0).all() and np.array_equal(raw.tow, np.unique(pr.time))
    assert np.array_equal(raw.tow[raw.epoch], pr.time) and np.array_equal(raw.line, pr.line)
    assert raw.satellite_ids()[:2].tolist() == ["G02", "G05"] and set(raw.system.tolist()) == {"G", "R"}
    direct = PseudorangeEpochs.from_rows(pr.time, pr.pseudorange, pr.variance, pr.sat_ecef, pr.sat_id, pr.system,
                                         pr.elevation, pr.cn0, source=pr.path)
    derived = PseudorangeEpochs.from_raw(raw)
    for name in ("time", "start", "pseudorange", "variance", "sat_ecef", "sat_id", "system", "elevation", "cn0"):
        a, b = getattr(direct, name), getattr(derived, name)
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name
    assert derived.source == direct.source


def test_keeping_systems_counts_the_rows_and_the_emptied_epochs(tmp_path):
    """``keep_systems`` leaves out and counts the other systems' rows, drops an epoch left
    without any (counted in epochs_all_rejected) and renumbers the rest; its epochs equal the
    kept rows grouped directly."""
    from mixnav.gnss.pseudoranges import PseudorangeEpochs
    rows = make_synthetic(n_epochs=3)[0]
    rows = [r for r in rows if not (r[0] == rows[0][0] and r[7] == 1)]   # epoch 0: GLONASS rows alone
    pr, raw = _reader_output(tmp_path, rows)
    gps = raw.keep_systems(["G"])
    n_glo = int((pr.system == 4).sum())
    assert gps.rejected == {"system not read: R": n_glo} and gps.epochs_all_rejected == 1
    assert len(gps.tow) == 2 and gps.epoch.tolist() == [0] * 5 + [1] * 5 and set(gps.system.tolist()) == {"G"}
    keep = pr.system == 1
    direct = PseudorangeEpochs.from_rows(pr.time[keep], pr.pseudorange[keep], pr.variance[keep], pr.sat_ecef[keep],
                                         pr.sat_id[keep], pr.system[keep], pr.elevation[keep], pr.cn0[keep])
    derived = PseudorangeEpochs.from_raw(gps)
    assert np.array_equal(direct.time, derived.time) and np.array_equal(direct.pseudorange, derived.pseudorange)
    assert np.array_equal(gps.line, pr.line[keep])
    assert raw.keep_systems(["G", "R"]) is raw


def test_corrected_and_broadcast_pseudoranges_are_told_apart():
    """A corrected log needs its satellites and variances; a broadcast one may not carry them;
    SBAS (``S``) is a corrected log's letter only; broadcast ranges cannot be grouped as
    corrected epochs (their satellite states come from a navigation file)."""
    from mixnav.data import RawPseudoranges
    from mixnav.errors import ArgumentError
    from mixnav.gnss.pseudoranges import PseudorangeEpochs
    base = dict(week=np.zeros(1, int), tow=np.zeros(1), epoch=np.zeros(2, int), prn=np.array([3, 120]),
                pseudorange=np.full(2, 2.1e7), source="x.txt", system=np.array(["G", "S"]))
    sat = dict(sat_ecef=np.full((2, 3), 1.5e7), variance=np.full(2, 25.0))
    ok = RawPseudoranges(**base, corrected=True, **sat)
    assert PseudorangeEpochs.from_raw(ok).system.tolist() == [1, 2]
    with pytest.raises(DataError, match="need each row's satellite position"):
        RawPseudoranges(**base, corrected=True)
    with pytest.raises(DataError, match="sat_ecef, variance given for broadcast"):
        RawPseudoranges(**base, **sat)
    with pytest.raises(DataError, match=r"\['S'\] are not among"):
        RawPseudoranges(**base)
    with pytest.raises(DataError, match="variances must be positive"):
        RawPseudoranges(**base, corrected=True, sat_ecef=sat["sat_ecef"], variance=np.array([25.0, 0.0]))
    broadcast = RawPseudoranges(**{**base, "system": np.array(["G", "G"])})
    with pytest.raises(ArgumentError, match="broadcast pseudoranges have no satellite positions"):
        PseudorangeEpochs.from_raw(broadcast)


def test_the_old_corrected_pseudoranges_kind_is_deprecated(tmp_path):
    """``corrected-pseudoranges`` still names the smartLoc reader (now ``raw-gnss``) with a
    DeprecationWarning, and a reader registered under it may still return PseudorangeEpochs:
    they come back as corrected RawPseudoranges that group into the same epochs."""
    from mixnav.data import RawPseudoranges
    from mixnav.gnss.pseudoranges import PseudorangeEpochs
    from mixnav.io import registry
    from mixnav.io.smartloc import to_pseudorange_epochs
    pr, raw = _reader_output(tmp_path)
    with pytest.warns(DeprecationWarning, match="'corrected-pseudoranges' is deprecated: use 'raw-gnss'"):
        assert registry.get_reader("corrected-pseudoranges", "smartloc") is registry.get_reader("raw-gnss", "smartloc")
    with pytest.warns(DeprecationWarning):
        assert "smartloc" in registry.formats("corrected-pseudoranges")
    epochs = to_pseudorange_epochs(pr)
    try:
        with pytest.warns(DeprecationWarning):
            plugin = registry.register_reader("corrected-pseudoranges", "old-plugin")(lambda path, options: epochs)
        out = registry.get_reader("raw-gnss", "old-plugin")(tmp_path / "any.txt")
        assert plugin(None, None) is epochs                      # the decorator gives the function back
        assert isinstance(out, RawPseudoranges) and out.corrected
        back = PseudorangeEpochs.from_raw(out)
        for name in ("time", "start", "pseudorange", "variance", "sat_ecef", "sat_id", "system", "elevation", "cn0"):
            assert np.array_equal(getattr(back, name), getattr(epochs, name), equal_nan=True), name
    finally:
        from mixnav import formats as known
        registry._READERS.pop(("raw-gnss", "old-plugin"), None)
        known._ADDED.pop(("raw-gnss", "old-plugin"), None)
