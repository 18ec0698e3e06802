"""SPP speed on urbannav-tst-static beside RTKLIB's rnx2rtkp (issue 36, "Speed").

Run::

    PYTHONPATH=src python benchmarks/bench_spp_speed.py [--repeat 7]

(the rnx2rtkp binaries as for benchmarks/rtklib_urbannav.py: ``RNX2RTKP_EX``,
``RNX2RTKP_B34`` or the defaults under /tmp below; a missing one is reported, not timed.)

Workload: the shipped dataset ``urbannav-tst-static`` (986 epochs at 1 Hz, u-blox F9P,
the eight HKSC navigation files), plain SPP with the dataset file's settings (15 deg mask,
Klobuchar scaled per frequency, Saastamoinen), for GPS, GPS+BeiDou and all four systems.
Timed, in one run, side by side:

- rnx2rtkp (demo5 EX 2.5.1 and 2.4.3 b34, no RAIM; option files of rtklib_urbannav.py):
  the whole run (process start, read, solve, write), wall and the child's CPU time, best
  of ``--repeat``;
- mixnav in this process (imports done): the read (RINEX observations + navigation, the
  pipeline's ``read_raw``), the compiled SPP (``solve_epochs``, numba compiled beforehand)
  and the numpy SPP (``engine = "numpy"``, the reference; once), wall and CPU
  (``time.process_time``), best of ``--repeat``; SPP per epoch = SPP / 986;
- the compiled SPP's first call in a fresh interpreter: with an empty numba cache (the
  compilation) and again with that cache on disk (what every later run pays), and the whole
  fresh process (interpreter start, imports, read, SPP), the like of rnx2rtkp's whole run.

The machine's 2 cores are shared with other jobs: wall times are disturbed, CPU times less
so; both are reported. Writes benchmarks/results/spp_speed.md and .json.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _timing import best_wall_cpu  # noqa: E402
from rtklib_urbannav import NAV, OBS, VERSIONS, option_text, timed  # noqa: E402

from mixnav import __version__  # noqa: E402
from mixnav.config.loader import load_dataset  # noqa: E402
from mixnav.experiment.data_folder import find_data_dir  # noqa: E402
from mixnav.experiment.spp_process import _systems_of, options, read_raw  # noqa: E402
from mixnav.gnss.spp import solve_epochs  # noqa: E402

OUT = ROOT / "benchmarks" / "results"
SETS = {"GPS": "G", "GPS+BeiDou": "GC", "GPS+GLONASS+Galileo+BeiDou": "GREC"}
DEFAULT_BINARIES = {"ex": "/tmp/rtklib-ex251/app/consapp/rnx2rtkp/gcc/rnx2rtkp",
                    "b34": "/tmp/rtklib-243b34/app/consapp/rnx2rtkp/gcc/rnx2rtkp"}

#: a fresh interpreter: imports, read, the first SPP call (compiles or loads the numba
#: cache), a second call; prints the times as JSON
FRESH = """
import json, sys, time
t0 = time.perf_counter()
sys.path.insert(0, {src!r})
from mixnav.config.loader import load_dataset
from mixnav.experiment.data_folder import find_data_dir
from mixnav.experiment.spp_process import _systems_of, options, read_raw
from mixnav.gnss.spp import solve_epochs
t1 = time.perf_counter()
ds0, source, _ = load_dataset("urbannav-tst-static")
ds = ds0.model_copy(update={{"raw_gnss": ds0.raw_gnss.model_copy(update={{"systems": {systems!r}}})}})
obs, eph, _ = read_raw(ds, source, find_data_dir(ds, None, source))
system, chan = _systems_of(obs, eph)
t2 = time.perf_counter()
run = lambda: solve_epochs(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange, options(ds), system=system,
                           glonass_channel=chan)
run()
t3 = time.perf_counter()
run()
t4 = time.perf_counter()
print(json.dumps({{"imports_s": t1 - t0, "read_s": t2 - t1, "first_spp_s": t3 - t2, "second_spp_s": t4 - t3,
                  "in_process_total_s": t4 - t0}}))
"""


def dataset(letters: str):
    ds0, source, _ = load_dataset("urbannav-tst-static")
    ds = ds0.model_copy(update={"raw_gnss": ds0.raw_gnss.model_copy(update={"systems": list(letters)})})
    return ds, source, find_data_dir(ds, None, source)


def rtklib(letters: str, repeat: int, work: Path, folder: Path) -> dict:
    out = {}
    for key, default in DEFAULT_BINARIES.items():
        exe = Path(os.environ.get(VERSIONS[key]["env"], default))
        if not exe.is_file():
            out[key] = {"missing": str(exe)}
            continue
        conf = work / f"{key}_{letters}.conf"
        conf.write_text(option_text(letters, False))
        cmd = [str(exe), "-k", str(conf), "-o", str(work / f"{key}_{letters}.pos"), str(folder / OBS),
               *[str(folder / n) for n in NAV]]
        wall, _, cpu = timed(cmd, repeat)
        out[key] = {"label": VERSIONS[key]["label"], "binary": str(exe), "wall_s": wall, "cpu_s": cpu}
    return out


def fresh(letters: str, cache_dir: str) -> dict:
    code = FRESH.format(src=str(ROOT / "src"), systems=list(letters))
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    out = json.loads(r.stdout.strip().splitlines()[-1])
    out["process_wall_s"] = time.perf_counter() - t
    return out


def mixnav(letters: str, repeat: int) -> dict:
    ds, source, folder = dataset(letters)
    read_wall, read_cpu, (obs, eph, _) = best_wall_cpu(lambda: read_raw(ds, source, folder), repeat)
    system, chan = _systems_of(obs, eph)
    opts = options(ds)

    def spp(engine):
        return solve_epochs(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange,
                            dataclasses.replace(opts, engine=engine), system=system, glonass_channel=chan)

    spp("compiled")                                            # compiled (or loaded) before timing
    wall, cpu, track = best_wall_cpu(lambda: spp("compiled"), repeat)
    np_wall, np_cpu, ref = best_wall_cpu(lambda: spp("numpy"), 1)
    ok = track.ok
    k = len(obs.tow)
    return {"epochs": k, "observations": len(obs.pseudorange), "epochs_solved": int(ok.sum()),
            "read_wall_s": read_wall, "read_cpu_s": read_cpu, "spp_wall_s": wall, "spp_cpu_s": cpu,
            "spp_per_epoch_wall_us": 1e6 * wall / k, "spp_per_epoch_cpu_us": 1e6 * cpu / k,
            "numpy_spp_wall_s": np_wall, "numpy_spp_cpu_s": np_cpu,
            "read_plus_spp_wall_s": read_wall + wall, "read_plus_spp_cpu_s": read_cpu + cpu,
            "max_position_difference_to_numpy_m": float(np.abs(track.pos_ecef[ok] - ref.pos_ecef[ok]).max())}


def report(data: dict) -> str:
    lines = ["# SPP speed on urbannav-tst-static beside RTKLIB rnx2rtkp (issue 36)", "",
             f"Made by `benchmarks/bench_spp_speed.py` ({data['date']}, mixnav {data['mixnav_version']}, Python "
             f"{data['python']}, {data['machine']}, 2 cores shared with other jobs: wall times disturbed, CPU times "
             f"less so). Best of {data['repeat']}. 986 epochs at 1 Hz; plain SPP with the dataset file's settings "
             "(15 deg mask, Klobuchar scaled per frequency, Saastamoinen); rnx2rtkp with rtklib_urbannav.py's "
             "option files (single, no RAIM).", "",
             "## Whole runs and parts [s]", "",
             "| systems | rnx2rtkp demo5 EX 2.5.1 wall (CPU) | rnx2rtkp 2.4.3 b34 wall (CPU) | mixnav read wall (CPU) | "
             "mixnav SPP wall (CPU) | read + SPP wall (CPU) | / 2x demo5 wall | numpy SPP wall (CPU) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in data["results"].items():
        m, rt = r["mixnav"], r["rtklib"]

        def rk(key):
            q = rt.get(key, {})
            return "missing" if "wall_s" not in q else f"{q['wall_s']:.3f} ({q['cpu_s']:.3f})"
        ratio = (m["read_plus_spp_wall_s"] / (2 * rt["ex"]["wall_s"])) if "wall_s" in rt.get("ex", {}) else float("nan")
        lines.append(f"| {name} | {rk('ex')} | {rk('b34')} | {m['read_wall_s']:.3f} ({m['read_cpu_s']:.3f}) | "
                     f"{m['spp_wall_s']:.4f} ({m['spp_cpu_s']:.4f}) | {m['read_plus_spp_wall_s']:.3f} "
                     f"({m['read_plus_spp_cpu_s']:.3f}) | {ratio:.2f} | {m['numpy_spp_wall_s']:.2f} "
                     f"({m['numpy_spp_cpu_s']:.2f}) |")
    lines += ["", "## SPP per epoch [us] (target <= 100)", "",
              "| systems | observations | compiled wall | compiled CPU | numpy wall | speed-up (CPU) | "
              "max |position - numpy's| [m] |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in data["results"].items():
        m = r["mixnav"]
        lines.append(f"| {name} | {m['observations']} | {m['spp_per_epoch_wall_us']:.0f} | "
                     f"{m['spp_per_epoch_cpu_us']:.0f} | {1e6 * m['numpy_spp_wall_s'] / m['epochs']:.0f} | "
                     f"{m['numpy_spp_cpu_s'] / m['spp_cpu_s']:.0f}x | {m['max_position_difference_to_numpy_m']:.1e} |")
    lines += ["", "## Compilation and fresh processes [s] (all four systems)", "",
              "A fresh interpreter: imports, read, the first SPP call, a second call. `cold`: an empty numba "
              "cache (the kernels compile); `warm`: the same cache on disk (they load).", "",
              "| cache | imports | read | first SPP call | second SPP call | whole process wall |",
              "|---|---:|---:|---:|---:|---:|"]
    for label, f in data["fresh"].items():
        lines.append(f"| {label} | {f['imports_s']:.2f} | {f['read_s']:.3f} | {f['first_spp_s']:.3f} | "
                     f"{f['second_spp_s']:.3f} | {f['process_wall_s']:.2f} |")
    lines += ["", "The compiled SPP equals the numpy one (the reference, `SppOptions(engine=\"numpy\")`) to the "
              "difference shown (tests/test_spp_kernel.py holds it to 1e-6 m, statuses and counts equal). "
              "rnx2rtkp's whole run includes its process start and writing the .pos file; mixnav's in-process "
              "read + SPP does not include the interpreter start and imports (the fresh-process rows do).", ""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    started = dt.datetime.now(dt.timezone.utc)
    results = {}
    with tempfile.TemporaryDirectory() as work:
        for name, letters in SETS.items():
            _, _, folder = dataset(letters)
            results[name] = {"systems": letters, "rtklib": rtklib(letters, args.repeat, Path(work), folder),
                             "mixnav": mixnav(letters, args.repeat)}
            m = results[name]["mixnav"]
            print(f"{name}: read {m['read_wall_s']:.3f} s, SPP {m['spp_wall_s']:.4f} s wall "
                  f"{m['spp_cpu_s']:.4f} s CPU, rtklib {results[name]['rtklib']}", flush=True)
        cache = str(Path(work) / "numba_cache")
        fr = {"cold": fresh("GREC", cache), "warm": fresh("GREC", cache)}
    data = {"date": started.isoformat(timespec="seconds"), "mixnav_version": __version__,
            "python": platform.python_version(), "machine": platform.machine(), "repeat": args.repeat,
            "results": results, "fresh": fr}
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "spp_speed.json").write_text(json.dumps(data, indent=1) + "\n")
    (OUT / "spp_speed.md").write_text(report(data))
    print((OUT / "spp_speed.md").read_text())


if __name__ == "__main__":
    main()
