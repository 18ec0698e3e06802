"""drive-0708: what bounds the aided causal filter's error in a 30 s outage (issue 34).

    python benchmarks/drive0708_outage_limit.py [--data DIR] [--workers 2] [--out benchmarks/results]
                                                [--no-variants]

Issue 34 asks the shipped aided configuration for a sweep (30 s windows every 10 s) median
<= 3 m, p90 <= 8 m and worst <= 15 m. This benchmark asks why it is not there, in two parts:

1. **The filter's own uncertainty, per window.** Each window of the sweep is withheld alone
   (as ``mixnav process --outage-sweep`` does) and the causal ``aided`` filter's horizontal
   error inside the window is set beside its own 1-sigma (``sqrt(sig_n^2 + sig_e^2)``) at the
   epoch of the largest error, the error's along-track share (along the filter's own
   velocity) and the window's course change. A consistent filter's errors follow its sigma:
   a worst window of <= 15 m needs the sigma there to be several times smaller, i.e. a
   forward specific force known better at the outage start (pitch, forward accelerometer
   bias), which the recording's IMU does not give (part 2) and no odometer measures.
2. **Settings tried against the reference (exploration, not a choice).** The whole sweep of
   the shipped file with one group of values changed at a time (NHC sigmas, the IMU noise
   and bias walks, extra states). These runs look at the reference in the scored windows:
   they are a sensitivity study, and none of them is shipped. A setting that moves one worst
   window moves another (the table's per-variant worst window).

Writes ``drive0708_outage_limit.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "src" / "mixnav" / "config" / "datasets" / "drive-0708-aided.toml"
WINDOW, STEP, FIRST, LAST = 30.0, 10.0, 60.0, 500.0

_ARW = 'arw = ["0.15 deg/s/sqrt(Hz)", "0.15 deg/s/sqrt(Hz)", "0.038 deg/s/sqrt(Hz)"]'
_GBW = 'gyro_bias_walk = ["2e-3 deg/s^2/sqrt(Hz)", "7e-3 deg/s^2/sqrt(Hz)", "1.2e-3 deg/s^2/sqrt(Hz)"]'
_ABW = 'accel_bias_walk = ["290 ug/s/sqrt(Hz)", "260 ug/s/sqrt(Hz)", "160 ug/s/sqrt(Hz)"]'
_NHC = 'sigma = ["0.1 m/s", "0.25 m/s"]'
_METHOD = 'states = 15\ncovariance_interval = "0.25 s"\naiding'
_MOUNT = '[aiding]\nvehicle_mounting = ["0 deg", "0 deg", "0 deg"]'

#: (label, [(text in the shipped file, its replacement), ...])
VARIANTS = [
    ("shipped", []),
    ("NHC vertical sigma 0.1 m/s", [(_NHC, 'sigma = ["0.1 m/s", "0.1 m/s"]')]),
    ("NHC vertical sigma 0.5 m/s", [(_NHC, 'sigma = ["0.1 m/s", "0.5 m/s"]')]),
    ("NHC vertical sigma 5 m/s (lateral only)", [(_NHC, 'sigma = ["0.1 m/s", "5 m/s"]')]),
    ("NHC lateral sigma 0.3 m/s", [(_NHC, 'sigma = ["0.3 m/s", "0.25 m/s"]')]),
    ("ARW x/y at z's 0.038 deg/s/sqrt(Hz)",
     [(_ARW, 'arw = ["0.038 deg/s/sqrt(Hz)", "0.038 deg/s/sqrt(Hz)", "0.038 deg/s/sqrt(Hz)"]')]),
    ("pitch gyro bias walk 2e-3 (as roll)",
     [(_GBW, 'gyro_bias_walk = ["2e-3 deg/s^2/sqrt(Hz)", "2e-3 deg/s^2/sqrt(Hz)", "1.2e-3 deg/s^2/sqrt(Hz)"]')]),
    ("roll/pitch gyro bias walks 0.7e-3",
     [(_GBW, 'gyro_bias_walk = ["0.7e-3 deg/s^2/sqrt(Hz)", "0.7e-3 deg/s^2/sqrt(Hz)", "1.2e-3 deg/s^2/sqrt(Hz)"]')]),
    ("gyro walks 0.7e-3 + accel walks / 3",
     [(_GBW, 'gyro_bias_walk = ["0.7e-3 deg/s^2/sqrt(Hz)", "0.7e-3 deg/s^2/sqrt(Hz)", "1.2e-3 deg/s^2/sqrt(Hz)"]'),
      (_ABW, 'accel_bias_walk = ["100 ug/s/sqrt(Hz)", "100 ug/s/sqrt(Hz)", "60 ug/s/sqrt(Hz)"]')]),
    ("gyro walks 0.7e-3 + accel walks / 10",
     [(_GBW, 'gyro_bias_walk = ["0.7e-3 deg/s^2/sqrt(Hz)", "0.7e-3 deg/s^2/sqrt(Hz)", "1.2e-3 deg/s^2/sqrt(Hz)"]'),
      (_ABW, 'accel_bias_walk = ["30 ug/s/sqrt(Hz)", "30 ug/s/sqrt(Hz)", "20 ug/s/sqrt(Hz)"]')]),
    ("21 states: scale factors 3000 ppm", [(_METHOD, _METHOD.replace("15", "21")),
                                            ('accel_bias = "10 mg"',
                                             'accel_bias = "10 mg"\ngyro_scale = "3000 ppm"\naccel_scale = "3000 ppm"')]),
    ("mounting pitch/yaw as states (0.3 deg)", [(_METHOD, _METHOD.replace("aiding", 'estimate = ["mounting"]\naiding')),
                                                 (_MOUNT, _MOUNT + '\nmounting_sigma = "0.3 deg"')]),
]


def _window_detail(args) -> dict:
    """One window withheld: the aided filter's error and own sigma inside it."""
    dataset, data, w0 = args
    warnings.simplefilter("ignore")
    from mixnav.experiment.ins_common import with_withheld
    from mixnav.experiment.sweep import _load, _run_quietly
    ds, source, p, folder, inputs = _load(dataset, data)
    t = p.tables(_run_quietly(p, with_withheld(ds, [(w0, w0 + WINDOW)]), source, folder, inputs))["aided"]
    t = t[(t.time_s >= w0) & (t.time_s <= w0 + WINDOW)]
    e = np.hypot(t.err_n_m, t.err_e_m).to_numpy()
    s = np.hypot(t.sig_n_m, t.sig_e_m).to_numpy()
    k = int(np.argmax(e))
    psi = np.arctan2(t.ve_mps.to_numpy()[k], t.vn_mps.to_numpy()[k])      # the filter's own course
    along = t.err_n_m.to_numpy()[k] * np.cos(psi) + t.err_e_m.to_numpy()[k] * np.sin(psi)
    yaw = np.unwrap(np.radians(t.yaw_deg.to_numpy()))
    return {"start_s": w0, "max_m": float(e[k]), "sigma_at_max_m": float(s[k]), "ratio": float(e[k] / s[k]),
            "along_share": float(abs(along) / max(e[k], 1e-9)), "sigma_end_m": float(s[-1]),
            "pitch_sigma_start_deg": float(t.sig_pitch_deg.to_numpy()[0]),
            "course_change_deg": float(np.degrees(np.abs(np.diff(yaw)).sum()))}


def _variant_file(base: str, subs, folder: Path, data_dir: str, i: int) -> Path:
    text = base.replace('data_dir = "../shared/data/drive-0708"', f'data_dir = "{data_dir}"')
    for old, new in subs:
        if old not in text:
            raise SystemExit(f"variant {i}: {old!r} is not in {SHIPPED.name} any more: update VARIANTS")
        text = text.replace(old, new)
    f = folder / f"variant_{i}.toml"
    f.write_text(text)
    return f


def _summary(rows) -> dict:
    from mixnav.experiment.sweep import NEES_POS_99
    g = rows[rows.method == "aided"].sort_values("start_s")
    h = g.horizontal_max_m.to_numpy(float)
    return {"median_m": float(np.median(h)), "p90_m": float(np.percentile(h, 90)), "worst_m": float(h.max()),
            "worst_start_s": float(g.start_s.to_numpy()[h.argmax()]),
            "nees_out_share": float(np.mean(g.nees_pos_mean.to_numpy(float) > NEES_POS_99)),
            "per_window": {f"{a:g}": float(x) for a, x in zip(g.start_s, h)}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    ap.add_argument("--no-variants", action="store_true")
    a = ap.parse_args(argv)
    from mixnav.config import load_dataset
    from mixnav.experiment.data_folder import find_data_dir
    from mixnav.experiment.sweep import run_outage_sweep
    t_wall = time.perf_counter()
    ds, source, _ = load_dataset("drive-0708-aided")
    data_dir = str(find_data_dir(ds, a.data, source))
    starts = list(np.arange(FIRST, LAST + 1e-9, STEP))
    with ProcessPoolExecutor(a.workers) as pool:
        detail = list(pool.map(_window_detail, [("drive-0708-aided", a.data, float(w)) for w in starts]))
    variants = []
    if not a.no_variants:
        base = SHIPPED.read_text()
        with tempfile.TemporaryDirectory() as tmp:
            for i, (label, subs) in enumerate(VARIANTS):
                f = _variant_file(base, subs, Path(tmp), data_dir, i)
                res = run_outage_sweep(str(f), f"{WINDOW:g} s", f"{STEP:g} s", workers=a.workers)
                variants.append({"label": label, "changes": [new for _, new in subs], **_summary(res.rows)})
                print(label, {k: v for k, v in variants[-1].items() if k not in ("per_window", "changes")})
    elapsed = time.perf_counter() - t_wall
    d = {k: np.array([r[k] for r in detail]) for k in detail[0]}
    straight = d["course_change_deg"] < 60
    doc = {"recorded": time.strftime("%Y-%m-%dT%H:%M"), "machine": platform.machine(), "cores": os.cpu_count(),
           "python": sys.version.split()[0], "wall_time_s": elapsed, "windows": detail, "variants": variants}
    out = Path(a.out)
    (out / "drive0708_outage_limit.json").write_text(json.dumps(doc, indent=1) + "\n")

    worst = sorted(detail, key=lambda r: -r["max_m"])[:6]
    L = ["# drive-0708: what bounds the aided filter in a 30 s outage (benchmarks/drive0708_outage_limit.py)", "",
         f"Recorded {doc['recorded']} on {doc['machine']} ({doc['cores']} cores), {elapsed:.0f} s. The shipped "
         f"`drive-0708-aided`, causal `aided` method; {len(detail)} windows of {WINDOW:g} s every {STEP:g} s from "
         f"{FIRST:g} s, each withheld alone; error = the antenna's horizontal error against the withheld RTK fixes "
         "inside the window (the sweep's rows also count the unaided stretch after it).", "",
         "## 1. The errors follow the filter's own sigma", "",
         f"Error / own 1-sigma at the epoch of the largest error: median {np.median(d['ratio']):.2f}, p90 "
         f"{np.percentile(d['ratio'], 90):.2f}, largest {d['ratio'].max():.2f}. Own 1-sigma at that epoch: median "
         f"{np.median(d['sigma_at_max_m']):.1f} m, p90 {np.percentile(d['sigma_at_max_m'], 90):.1f} m, largest "
         f"{d['sigma_at_max_m'].max():.1f} m. Pitch 1-sigma at the outage start: median "
         f"{np.median(d['pitch_sigma_start_deg']):.2f} deg (g x 0.2 deg = 0.034 m/s^2 of forward specific force: "
         "15 m in 30 s).", "",
         f"Windows with less than 60 deg of course change ({int(straight.sum())}): median error "
         f"{np.median(d['max_m'][straight]):.1f} m, own sigma {np.median(d['sigma_at_max_m'][straight]):.1f} m; "
         f"the others ({int((~straight).sum())}): {np.median(d['max_m'][~straight]):.1f} m, sigma "
         f"{np.median(d['sigma_at_max_m'][~straight]):.1f} m. A turn makes the forward velocity error lateral, "
         "where NHC sees it; on a straight road nothing observes it.", "",
         "| window start [s] | max error [m] | own sigma there [m] | error / sigma | along-track share | course "
         "change [deg] |", "|---|---|---|---|---|---|"]
    for r in worst:
        L.append(f"| {r['start_s']:g} | {r['max_m']:.1f} | {r['sigma_at_max_m']:.1f} | {r['ratio']:.2f} | "
                 f"{r['along_share']:.2f} | {r['course_change_deg']:.0f} |")
    L += ["", "The largest errors are along the track: the forward velocity drifts (the filter's speed falls "
          "behind on the descents after a crest) at the rate of a pitch error of a few tenths of a degree or a "
          "forward accelerometer bias of a few mg, which the recording's GNSS fixes the filter to no better than "
          "its sigma says before the outage begins.", ""]
    if variants:
        L += ["## 2. Settings tried against the reference (a sensitivity study, none shipped)", "",
              "The whole sweep (the rows `mixnav process --outage-sweep` writes, the unaided stretch after a window "
              "included) with one group of values of the shipped file changed. **These look at the reference in "
              "the scored windows**: they show how far settings move the distribution, and choose nothing.", "",
              "| variant | median [m] | p90 [m] | worst [m] (window) | NEES out of band |", "|---|---|---|---|---|"]
        for v in variants:
            L.append(f"| {v['label']} | {v['median_m']:.2f} | {v['p90_m']:.2f} | {v['worst_m']:.2f} "
                     f"({v['worst_start_s']:g} s) | {100 * v['nees_out_share']:.0f} % |")
        best_p90 = min(variants, key=lambda v: v["p90_m"])
        best_worst = min(variants, key=lambda v: v["worst_m"])
        L += ["", f"Lowest p90: {best_p90['label']} ({best_p90['p90_m']:.2f} m); lowest worst: "
              f"{best_worst['label']} ({best_worst['worst_m']:.2f} m). Issue 34's bar is p90 <= 8 m and worst "
              "<= 15 m with NEES out of band in at most 5 % of the windows.", ""]
    (out / "drive0708_outage_limit.md").write_text("\n".join(L) + "\n")
    print("\n".join(L))
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main())
