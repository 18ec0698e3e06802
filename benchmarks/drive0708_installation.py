"""drive-0708: why the recorder's noise densities give NIS/dof >> 1 (analysis helpers).

    python benchmarks/drive0708_installation.py baseline
    python benchmarks/drive0708_installation.py offset      # IMU time-offset scan
    ...

Findings are written by hand into benchmarks/results/drive0708_installation.md;
this file holds the harness that produced the numbers: a run of the shipped
config with overrides (IMU densities, time offset, windows, states, GNSS
sigma floors) that records every update's innovation ``z`` and its predicted
covariance ``S = H P H^T + R`` so NIS can be split by kind (position /
velocity rows) and over time.
"""

from __future__ import annotations

import copy
import os
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np

from mixnav.config import load_dataset
from mixnav.experiment.process import process
from mixnav.experiment.run import solution_table
from mixnav.filters import ekf as _ekf

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MIXNAV_DATA", ROOT.parent / "shared" / "data")) / "drive-0708"
CONFIG = ROOT / "src" / "mixnav" / "config" / "datasets" / "drive-0708-plain.toml"

RECORDER = {"arw": "0.0038 deg/s/sqrt(Hz)", "vrw": "70 ug/sqrt(Hz)"}
WINDOWS_EXTRA = [(100.0, 130.0), (250.0, 280.0), (400.0, 430.0)]


class RecordingEstimator(_ekf.KalmanEstimator):
    """The EKF's estimator, also keeping each epoch's ``(t, z, S, kinds)`` before the update."""

    log: list = []

    def update(self, epoch):
        rows = epoch.rows()
        if rows is not None:
            H = rows.H
            S = H @ self.P @ H.T + np.diag(rows.R)
            RecordingEstimator.log.append((epoch.time, rows.z.copy(), S, np.asarray(rows.kinds).copy(),
                                           epoch.w_b.copy(), epoch.nav.copy()))
        return super().update(epoch)


def config_dict() -> dict:
    return tomllib.loads(CONFIG.read_text())


def _dump(d: dict) -> str:
    """A minimal TOML writer for the dataset config (strings, numbers, bools, lists, tables)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    out = []

    def table(prefix, t):
        scalars = {k: v for k, v in t.items() if not isinstance(v, dict)
                   and not (isinstance(v, list) and v and isinstance(v[0], dict))}
        subs = {k: v for k, v in t.items() if isinstance(v, dict)}
        arrays = {k: v for k, v in t.items() if isinstance(v, list) and v and isinstance(v[0], dict)}
        if prefix:
            out.append(f"[{prefix}]")
        out.extend(f"{k} = {val(v)}" for k, v in scalars.items())
        for k, v in subs.items():
            table(f"{prefix}.{k}" if prefix else k, v)
        for k, v in arrays.items():
            for item in v:
                out.append(f"[[{k}]]")
                out.extend(f"{kk} = {val(vv)}" for kk, vv in item.items())

    table("", d)
    return "\n".join(out) + "\n"


def run(cfg: dict | None = None, record: bool = True):
    """Process drive-0708 with the config dict ``cfg``; returns (po, table, log)."""
    cfg = cfg or config_dict()
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as fh:
        fh.write(_dump(cfg))
        path = fh.name
    try:
        ds, src, _ = load_dataset(path)
    finally:
        os.unlink(path)
    RecordingEstimator.log = []
    old = _ekf.ErrorStateEkf.make_estimator
    if record:
        _ekf.ErrorStateEkf.make_estimator = lambda self: RecordingEstimator(self.absurd_sigma)
    try:
        po = process(ds, src, str(DATA))
    finally:
        _ekf.ErrorStateEkf.make_estimator = old
    name = ds.methods[0].name
    res = po.results[name]
    table = solution_table(res, po.reference, ds.gnss.withhold, lever=po.lever)
    return po, table, list(RecordingEstimator.log)


def with_(cfg=None, **kw) -> dict:
    """A copy of the config with overrides: ``arw``, ``vrw``, ``offset`` (s), ``withhold``
    (list of (a, b) s), ``states``, ``min_sigma`` (m), ``errors`` (dict)."""
    c = copy.deepcopy(cfg or config_dict())
    if "arw" in kw:
        c["imu"]["errors"]["arw"] = kw.pop("arw")
    if "vrw" in kw:
        c["imu"]["errors"]["vrw"] = kw.pop("vrw")
    if "errors" in kw:
        c["imu"]["errors"].update(kw.pop("errors"))
    if "offset" in kw:
        c["installation"]["imu_time_offset"] = f"{kw.pop('offset')} s"
    if "withhold" in kw:
        c["gnss"]["withhold"] = [[f"{a} s", f"{b} s"] for a, b in kw.pop("withhold")]
    if "states" in kw:
        c["methods"][0]["states"] = kw.pop("states")
    if "min_sigma" in kw:
        c["gnss"]["min_sigma"] = f"{kw.pop('min_sigma')} m"
    for k, v in kw.items():  # dotted keys: "gnss.use_velocity"
        sect, key = k.split("__")
        c[sect][key] = v
    return c


def nis_split(log, t_from=-np.inf, t_to=np.inf, mask_fn=None):
    """NIS/dof per kind (position rows, velocity rows, all), using the marginal S of each block."""
    from mixnav.measurements.kinds import POSITION, VELOCITY
    acc = {"pos": [], "vel": [], "all": []}
    for (t, z, S, kinds, w, nav) in log:
        if not (t_from <= t < t_to):
            continue
        if mask_fn is not None and not mask_fn(t, z, S, kinds, w, nav):
            continue
        acc["all"].append(z @ np.linalg.solve(S, z) / len(z))
        for name, code in (("pos", POSITION), ("vel", VELOCITY)):
            k = kinds == code
            if k.any():
                zz, SS = z[k], S[np.ix_(k, k)]
                acc[name].append(zz @ np.linalg.solve(SS, zz) / k.sum())
    return {k: (float(np.mean(v)) if v else float("nan"), float(np.median(v)) if v else float("nan"), len(v))
            for k, v in acc.items()}


def window_errors(table, windows):
    """Max horizontal error [m] of the solution in each window (withheld or not)."""
    out = []
    h = np.hypot(table["err_n_m"], table["err_e_m"])
    for a, b in windows:
        m = (table["time_s"] >= a) & (table["time_s"] < b)
        out.append(float(h[m].max()) if m.any() else float("nan"))
    return out


def innovations(log):
    """Arrays of (t, z (K,6), sigma_S (K,6), w_b (K,3), nav (K,10)) of epochs with 6 rows."""
    rows = [r for r in log if len(r[1]) == 6]
    t = np.array([r[0] for r in rows])
    z = np.array([r[1] for r in rows])
    s = np.array([np.sqrt(np.diag(r[2])) for r in rows])
    w = np.array([r[4] for r in rows])
    nav = np.array([r[5] for r in rows])
    return t, z, s, w, nav


def summary(cfg, windows=None, label=""):
    """One line: NIS/dof per kind and max horizontal errors in the withheld windows."""
    windows = windows or [tuple(float(x.split()[0]) for x in w) for w in cfg["gnss"]["withhold"]]
    po, table, log = run(cfg)
    ns = nis_split(log)
    errs = window_errors(table, windows)
    nees = table.loc[table["in_outage"], ["nees_pos", "nees_vel"]].mean()
    print(f"{label:40s} NIS/dof all {ns['all'][0]:6.2f} (med {ns['all'][1]:5.2f})  pos {ns['pos'][0]:6.2f}  "
          f"vel {ns['vel'][0]:6.2f}  | max horiz err " + " ".join(f"{e:6.2f}" for e in errs)
          + f" | NEES pos {nees['nees_pos']:.1f} vel {nees['nees_vel']:.1f}", flush=True)
    return po, table, log, ns, errs


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "baseline"
    if what == "baseline":
        shipped = config_dict()
        summary(shipped, label="shipped (10x densities)")
        summary(with_(shipped, **RECORDER), label="recorder densities")
        summary(with_(shipped, withhold=WINDOWS_EXTRA), label="shipped, extra windows")
        summary(with_(shipped, withhold=WINDOWS_EXTRA, **RECORDER), label="recorder, extra windows")
    if what == "offset":
        base = with_(config_dict(), **RECORDER)
        for off in np.arange(-0.40, 0.1001, 0.025):
            summary(with_(base, offset=round(float(off), 3)), label=f"recorder, offset {off:+.3f}")
    if what == "offset-extra":
        base = with_(config_dict(), withhold=WINDOWS_EXTRA, **RECORDER)
        for off in np.arange(-0.40, 0.1001, 0.025):
            summary(with_(base, offset=round(float(off), 3)), label=f"recorder extra, offset {off:+.3f}")
    if what == "vdelay":
        base = with_(config_dict(), **RECORDER)
        for d in (0.0, 0.1, 0.125, 0.15):
            summary(with_(base, gnss__velocity_delay=f"{d} s"), label=f"recorder, vel delay {d}")
        summary(with_(base, gnss__use_velocity=False), label="recorder, no GNSS velocity")
    if what == "offset-vd":
        base = with_(config_dict(), gnss__velocity_delay="0.125 s", **RECORDER)
        for off in np.arange(-0.30, 0.1001, 0.025):
            summary(with_(base, offset=round(float(off), 3)), label=f"recorder+vd, offset {off:+.3f}")
    if what == "which":
        base = with_(config_dict(), **RECORDER)
        summary(with_(base, states=21), label="recorder, 21 states")
        summary(with_(base, arw="0.038 deg/s/sqrt(Hz)"), label="recorder, arw x10 only")
        summary(with_(base, vrw="700 ug/sqrt(Hz)"), label="recorder, vrw x10 only")
        summary(with_(base, vrw="1000 ug/sqrt(Hz)"), label="recorder, vrw 1000 (rest adev)")
        summary(with_(base, errors={"accel_bias_walk": "70 ug/s/sqrt(Hz)"}), label="recorder, ba walk x10")
        summary(with_(base, errors={"gyro_bias_walk": "3.8e-4 deg/s^2/sqrt(Hz)"}), label="recorder, bg walk x10")
        summary(with_(base, gnss__use_velocity=False, vrw="700 ug/sqrt(Hz)"), label="vrw x10, no GNSS vel")
    if what == "scale":
        base = with_(config_dict(), states=21, errors={"gyro_scale": "1 %", "accel_scale": "1 %"}, **RECORDER)
        po, table, log, ns, errs = summary(base, label="recorder, 21 states, scale 1 %")
        res = po.results["ekf"]
        for tq in (100, 200, 300, 400, 500):
            k = int(np.searchsorted(res.time, tq))
            print(f"t {tq}: gyro scale [ppm] {np.round(res.estimates['gyro_scale'][k] * 1e6)}  "
                  f"accel scale [ppm] {np.round(res.estimates['accel_scale'][k] * 1e6)}")
    if what == "uniform":
        # the IMU ticks jitter 0-2 ms about an exact 10 ms grid: time the samples on the grid
        from mixnav.io import drive0708 as _d
        from mixnav.experiment import process as _p
        orig = _d.read_drive_imu

        def uniform(*a, **k):
            imu = orig(*a, **k)
            n = len(imu.time) + 1
            k_ = np.arange(n)
            t_all = np.concatenate([[imu.time[0] - imu.dt[0]], imu.time])
            c = np.polyfit(k_, t_all, 1)
            tu = np.polyval(c, k_)
            # the trapezoid of the same samples on the uniform grid: increments scaled by dt_u / dt
            from dataclasses import replace as _r
            dtu = np.diff(tu)
            return _r(imu, time=tu[1:], dt=dtu, dtheta=imu.dtheta * (dtu / imu.dt)[:, None],
                      dvel=imu.dvel * (dtu / imu.dt)[:, None])
        _p.drive0708.read_drive_imu = uniform
        base = with_(config_dict(), **RECORDER)
        summary(base, label="recorder, uniform 10 ms grid")
        summary(with_(base, gnss__velocity_delay="0.125 s"), label="recorder, uniform grid + vel delay")
    if what == "shipped-vd":
        for wins, tag in ((None, "shipped windows"), (WINDOWS_EXTRA, "extra windows")):
            base = config_dict() if wins is None else with_(config_dict(), withhold=wins)
            summary(base, label=f"shipped, {tag}")
            for off in (-0.25, -0.2, -0.15, -0.125, -0.1, -0.05, 0.0):
                summary(with_(base, gnss__velocity_delay="0.125 s", offset=off),
                        label=f"shipped+vd, off {off:+.3f}, {tag[:5]}")
    if what == "tune":
        for wins in (None, WINDOWS_EXTRA):
            base = with_(config_dict(), gnss__velocity_delay="0.125 s", offset=-0.2)
            if wins:
                base = with_(base, withhold=wins)
            for arw, vrw in (("0.038", "350"), ("0.025", "700"), ("0.038", "1000")):
                summary(with_(base, arw=f"{arw} deg/s/sqrt(Hz)", vrw=f"{vrw} ug/sqrt(Hz)"),
                        label=f"vd, -0.2, arw {arw} vrw {vrw} {'extra' if wins else ''}")
    if what == "tagfix":
        # needs the reader change tried in section 6 (spread from TimeTag.first), which was not
        # kept: on the shipped reader this is the offset scan of "shipped-vd" again
        for wins in (None, WINDOWS_EXTRA):
            base = with_(config_dict(), gnss__velocity_delay="0.125 s")
            if wins:
                base = with_(base, withhold=wins)
            for off in (-0.2, -0.15, -0.125, -0.1, -0.075):
                summary(with_(base, offset=off), label=f"tagfix+vd, off {off:+.3f} {'extra' if wins else ''}")
            summary(with_(base, offset=-0.125, **RECORDER), label=f"tagfix+vd recorder -0.125 {'extra' if wins else ''}")
