"""comma2k19 example segment: clocks, time lags and the odometer against GNSS and comma's pose.

    PYTHONPATH=src python benchmarks/comma2k19_odometer.py [SEGMENT_DIR]

Prints the numbers recorded in benchmarks/results/comma2k19_odometer.md (and
writes them as JSON next to it). Everything on boot time, through the
readers in mixnav.io.comma2k19.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

from mixnav.io import comma2k19 as cm

ROOT = Path(__file__).resolve().parents[1]
SEG = Path(sys.argv[1]) if len(sys.argv) > 1 else \
    Path(os.environ.get("MIXNAV_DATA", ROOT.parent / "shared" / "data")) / "comma2k19-example1"


def robust(d):
    """Median, median |d| and 1.4826 MAD (a robust sigma) of differences."""
    d = np.asarray(d)
    med = float(np.median(d))
    return {"median": med, "median_abs": float(np.median(np.abs(d))),
            "robust_sigma": float(1.4826 * np.median(np.abs(d - med))), "n": int(d.size)}


def smooth(y, n):
    return np.convolve(y, np.ones(n) / n, mode="same")


def lag_against_imu(t_imu, a_fwd, t, speed, lags):
    """Shift [s] to add to the series' stamps that best matches its speed derivative to the IMU.

    Both signals are put on a 100 Hz grid, differentiated (the speed) and
    smoothed over 0.5 s; the lag maximises their correlation.
    """
    grid = np.arange(max(t_imu[0], t[0]) + 1.0, min(t_imu[-1], t[-1]) - 1.0, 0.01)
    a = smooth(np.interp(grid, t_imu, a_fwd), 51)[60:-60]
    best = (0.0, -2.0)
    for lag in lags:
        s = np.interp(grid, t + lag, speed)
        ds = smooth(np.gradient(s, grid), 51)[60:-60]
        c = float(np.corrcoef(a, ds)[0, 1])
        if c > best[1]:
            best = (float(lag), c)
    return best


def scale_fit(odo, ref):
    """ref ~ k * odo: least squares through the origin, median of ratios, and with an intercept."""
    k_ls = float(np.sum(odo * ref) / np.sum(odo * odo))
    k_med = float(np.median(ref / odo))
    A = np.column_stack([odo, np.ones_like(odo)])
    (k1, b1), *_ = np.linalg.lstsq(A, ref, rcond=None)
    return {"k_ls": k_ls, "k_median_ratio": k_med, "k_with_intercept": float(k1), "intercept": float(b1)}


def main():
    clock = cm.read_comma_clock(SEG)
    imu = cm.read_comma_imu(SEG)
    gnss = cm.read_comma_gnss(SEG)
    pose = cm.read_comma_pose(SEG)
    tlog = np.load(SEG / "processed_log/GNSS/live_gnss_ublox/t")
    raw_t = np.load(SEG / "processed_log/GNSS/raw_gnss_ublox/t")
    raw_v = np.load(SEG / "processed_log/GNSS/raw_gnss_ublox/value")
    gval = np.load(SEG / "processed_log/GNSS/live_gnss_ublox/value")
    gspeed = gval[:, 2]
    out = {"segment": str(SEG.name)}

    # --- clocks -----------------------------------------------------------------------------
    out["clock"] = {
        "gps_week": clock.week, "gps_minus_boot_s": clock.offset,
        "pose_offset_spread_s": float(np.ptp(pose.extra["gps_tow"] - pose.time)),
        "gnss_log_latency_s": {k: float(v) for k, v in zip(("min", "p5", "median", "p95", "max"),
                                                           np.percentile(tlog - gnss.time, [0, 5, 50, 95, 100]))},
        "raw_gnss_log_latency_s": float(np.median(raw_t - clock.gps_to_boot(raw_v[:, 1], raw_v[:, 2]))),
        "leap_seconds": clock.leap_seconds,
    }

    # --- IMU --------------------------------------------------------------------------------
    f = imu.dvel / imu.dt[:, None]
    w = imu.dtheta / imu.dt[:, None]
    out["imu"] = {"n": len(imu), "rate_hz": float(1 / np.median(imu.dt)), "dt_max_s": float(imu.dt.max()),
                  "mean_specific_force": f.mean(0).tolist(), "gravity_norm_of_mean": float(np.linalg.norm(f.mean(0))),
                  "span_s": [float(imu.start_time), float(imu.time[-1])]}
    # gyro z against the pose's yaw rate (sign and scale check of the axes)
    yaw = np.unwrap(pose.rpy[:, 2])
    yaw_rate = np.gradient(yaw, pose.time)
    wz = np.interp(pose.time, imu.time - imu.dt / 2, smooth(w[:, 2], 5))
    sel = slice(5, -5)
    out["imu"]["gyro_z_vs_pose_yaw_rate"] = {"corr": float(np.corrcoef(wz[sel], yaw_rate[sel])[0, 1]),
                                             "slope": float(np.polyfit(yaw_rate[sel], wz[sel], 1)[0])}

    # --- lags against the IMU ---------------------------------------------------------------
    lags = np.arange(-0.30, 0.301, 0.002)
    t_imu, a_fwd = imu.time - imu.dt / 2, f[:, 0]
    series = {"gnss_speed_utc_time": (gnss.time, gspeed), "gnss_speed_log_time": (tlog, gspeed),
              "pose_speed": (pose.time, np.linalg.norm(pose.v_n, axis=1))}
    odo = {s: cm.read_comma_odometer(SEG, source=s) for s in cm.ODOMETER_SOURCES}
    for s, o in odo.items():
        series[f"can_{s}"] = (o.time, o.speed)
    out["lag_to_add_s"] = {}
    mid = 0.5 * (t_imu[0] + t_imu[-1])
    for name, (t, y) in series.items():
        lag, c = lag_against_imu(t_imu, a_fwd, t, y, lags)
        halves = []
        for lo, hi in ((t_imu[0], mid), (mid, t_imu[-1])):
            mi, ms = (t_imu > lo - 1) & (t_imu < hi + 1), (t > lo) & (t < hi)
            halves.append(lag_against_imu(t_imu[mi], a_fwd[mi], t[ms], y[ms], lags)[0])
        c_edges = [lag_against_imu(t_imu, a_fwd, t, y, [lag + e])[1] for e in (-0.1, 0.1)]
        out["lag_to_add_s"][name] = {"lag": lag, "corr": c, "lag_first_half": halves[0],
                                     "lag_second_half": halves[1], "corr_at_lag_pm_0.1s": c_edges}

    # --- speeds ----------------------------------------------------------------------------
    # GNSS ground speed at its fix (UTC) time against the odometer interpolated there.
    inside = (gnss.time > odo["speed"].time[0]) & (gnss.time < odo["speed"].time[-1])
    tg, vg = gnss.time[inside], gspeed[inside]
    pose_sp = np.linalg.norm(pose.v_n, axis=1)
    pose_h = np.linalg.norm(pose.v_n[:, :2], axis=1)
    out["speed"] = {}
    for s, o in odo.items():
        for shift in (0.0, out["lag_to_add_s"][f"can_{s}"]["lag"]):
            vo = np.interp(tg, o.time + shift, o.speed)
            key = f"{s}@{shift:+.3f}s"
            k = scale_fit(vo, vg)
            out["speed"][key] = {
                "gnss_minus_odo": robust(vg - vo),
                "gnss_minus_scaled_odo": robust(vg - k["k_ls"] * vo),
                "scale_vs_gnss": k,
                "pose3d_minus_odo": robust(pose_sp - np.interp(pose.time, o.time + shift, o.speed)),
                "scale_vs_pose3d": scale_fit(np.interp(pose.time, o.time + shift, o.speed), pose_sp),
            }
    out["speed"]["pose_horizontal_minus_gnss"] = robust(np.interp(tg, pose.time, pose_h) - vg)
    out["speed"]["pose_3d_over_horizontal"] = float(np.median(pose_sp / pose_h))

    # --- GNSS positions against comma's pose --------------------------------------------------
    from mixnav.geodesy.frames import lla_to_ned
    ref = np.column_stack([np.interp(tg, pose.time, pose.lla[:, i]) for i in range(3)])
    d = np.array([lla_to_ned(gnss.lla[inside][k], ref[k]) for k in range(len(tg))])
    out["gnss_minus_pose_m"] = {"north": robust(d[:, 0]), "east": robust(d[:, 1]), "down": robust(d[:, 2])}
    # along track: a lever arm is constant, a time offset grows with speed
    vp = np.column_stack([np.interp(tg, pose.time, pose.v_n[:, i]) for i in range(2)])
    sp = np.linalg.norm(vp, axis=1)
    along = np.sum(d[:, :2] * vp / sp[:, None], axis=1)
    cross = (-d[:, 0] * vp[:, 1] + d[:, 1] * vp[:, 0]) / sp
    (a, b), *_ = np.linalg.lstsq(np.column_stack([sp, np.ones_like(sp)]), along, rcond=None)
    out["gnss_minus_pose_m"]["along_track_fit"] = {"seconds_times_speed": float(a), "constant_m": float(b),
                                                   "cross_track_median_m": float(np.median(cross))}

    print(json.dumps(out, indent=1))
    (ROOT / "benchmarks" / "results" / "comma2k19_odometer.json").write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
