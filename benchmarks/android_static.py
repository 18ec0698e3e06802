"""The shipped phone log, `mixnav process android-static-filters`: every method against the
surveyed point (the numbers docs/data_formats.md and docs/features.md quote).

Run:  PYTHONPATH=src python benchmarks/android_static.py [--data ../shared/data] [--out benchmarks/results]

The epoch-by-epoch SPP (`spp`, and `robust-spp`) and the GNSS-only constant-velocity filters
of the shipped config on the same 223 epochs, through the public API
(:func:`mixnav.process_dataset`). Errors: estimate minus the surveyed point, in NED there.
Beside the accuracy, what a static receiver's filter should show: the EKF's horizontal speed
after its first 30 s (RMS, and the median of its own 1-sigma per axis); and from the log itself,
the hardware-clock segments (``HardwareClockDiscontinuityCount`` changes between epochs). Writes
``android_static.json`` and ``android_static.md`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import mixnav

DATASET = "android-static-filters"
#: the filters run causally on the SPP's corrected pseudoranges (the SPP rows and the smoother apart)
CAUSAL_FILTERS = ("ekf", "robust", "mixture", "epoch-mixture", "vb-akf")
SETTLED_AFTER_S = 30.0
LOG = "pseudoranges_log_2016_06_30_21_26_07.txt"


def clock_segments(log: Path) -> dict:
    """Epochs (distinct ``TimeNanos`` of the ``Raw`` rows) and hardware-clock segments of a
    GnssLogger file (a segment ends where ``HardwareClockDiscontinuityCount`` changes)."""
    columns, epochs = None, []
    for line in log.read_text().splitlines():
        if line.startswith("# Raw,"):
            columns = line[2:].split(",")
        elif line.startswith("Raw,") and columns:
            row = dict(zip(columns, line.split(",")))
            if not epochs or epochs[-1][0] != row["TimeNanos"]:
                epochs.append((row["TimeNanos"], row["HardwareClockDiscontinuityCount"]))
    changes = sum(a[1] != b[1] for a, b in zip(epochs, epochs[1:]))
    return {"epochs": len(epochs), "segments": changes + 1 if epochs else 0}


def measure(data: Path) -> dict:
    t0 = time.perf_counter()
    run = mixnav.process_dataset(DATASET, str(data / "android-static"))
    wall = time.perf_counter() - t0
    keys = ("horizontal_rmse_m", "horizontal_p95_m", "horizontal_max_m", "vertical_rmse_m", "n_epochs")
    methods = {name: {k: (int(row[k]) if k == "n_epochs" else float(row[k])) for k in keys}
               for name, row in run.metrics.iterrows()}
    filtered = [methods[n]["horizontal_rmse_m"] for n in CAUSAL_FILTERS]
    ekf = run.solutions["ekf"]
    late = ekf[(ekf["time_s"] > SETTLED_AFTER_S) & (ekf["status"] == "ok")]
    return {
        "dataset": DATASET,
        "recorded": time.strftime("%Y-%m-%dT%H:%M", time.gmtime()),
        "machine": platform.machine(), "python": platform.python_version(),
        "mixnav_version": mixnav.__version__,
        "wall_time_s": wall,
        "log_clock": clock_segments(data / "android-static" / LOG),
        "methods": methods,
        "filters": {"names": list(CAUSAL_FILTERS),
                    "min_horizontal_rmse_m": min(filtered), "max_horizontal_rmse_m": max(filtered)},
        "ekf_after_30s": {
            "epochs": int(len(late)),
            "horizontal_speed_rms_mps": float(np.sqrt(np.mean(late["vn_mps"] ** 2 + late["ve_mps"] ** 2))),
            "median_sigma_vn_mps": float(late["sig_vn_mps"].median()),
            "median_sigma_ve_mps": float(late["sig_ve_mps"].median()),
        },
    }


def markdown(r: dict) -> str:
    lines = ["# android-static: the phone's SPP and its filters against the surveyed point "
             "(benchmarks/android_static.py)", "",
             f"Recorded {r['recorded']} on {r['machine']}, Python {r['python']}, mixnav {r['mixnav_version']}; "
             f"`mixnav.process_dataset(\"{r['dataset']}\")` took {r['wall_time_s']:.1f} s (numba caches as found). "
             "Errors: estimate minus the surveyed point, NED there. Numbers: `android_static.json`.", "",
             "| method | epochs | h RMSE [m] | h p95 [m] | h max [m] | v RMSE [m] |",
             "|---|---:|---:|---:|---:|---:|"]
    for name, m in r["methods"].items():
        lines.append(f"| {name} | {m['n_epochs']} | {m['horizontal_rmse_m']:.2f} | {m['horizontal_p95_m']:.2f} | "
                     f"{m['horizontal_max_m']:.2f} | {m['vertical_rmse_m']:.2f} |")
    f, e = r["filters"], r["ekf_after_30s"]
    c = r["log_clock"]
    lines += ["", f"The log: {c['epochs']} epochs in {c['segments']} hardware-clock segments "
              "(`HardwareClockDiscontinuityCount` changes between epochs: a duty-cycled chip)."]
    lines += ["", f"Causal filters ({', '.join(f['names'])}): horizontal RMSE {f['min_horizontal_rmse_m']:.2f}"
              f"-{f['max_horizontal_rmse_m']:.2f} m.", "",
              f"The EKF after {SETTLED_AFTER_S:g} s ({e['epochs']} epochs): horizontal speed RMS "
              f"{e['horizontal_speed_rms_mps']:.3f} m/s, median 1-sigma {e['median_sigma_vn_mps']:.3f} (north) / "
              f"{e['median_sigma_ve_mps']:.3f} (east) m/s: a static receiver.", ""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    here = Path(__file__).resolve().parent
    ap.add_argument("--data", type=Path, default=here.parent.parent / "shared" / "data")
    ap.add_argument("--out", type=Path, default=here / "results")
    a = ap.parse_args()
    r = measure(a.data)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "android_static.json").write_text(json.dumps(r, indent=1) + "\n")
    (a.out / "android_static.md").write_text(markdown(r))
    print(markdown(r))


if __name__ == "__main__":
    main()
