"""Cost of a tight-EKF GNSS epoch with several satellite systems.

    python benchmarks/bench_tight_multi.py   # writes benchmarks/results/tight_multi_bench.{json,md}

One epoch of the simulator's four-system constellation (GPS 30 + Galileo, BeiDou MEO,
GLONASS 24 each; tight-demo's start, 10 deg mask) through what the engine runs at a GNSS
epoch: the compiled measurement model (:meth:`TightGnss.rows`: antenna, lines of sight,
z, H, R) plus the compiled gate + Joseph update + feedback (``ekf_correct``), best of 7
repeats of 2000 calls, wall and CPU time. Cases:

- ``gps``: the GPS satellites alone (17 states, no offset: the single-system path);
- ``gps_as_4``: the same satellites, relabelled as four systems (20 states, three offsets):
  the price of the offset states and columns at an equal number of rows;
- ``all``: every visible satellite of the four systems (20 states).

Also the engine's mean update and epoch time (``FilterResult.timing``) of the whole
600 s tight-demo with GPS alone and with the four systems (tests/test_tight_multi.py's
scenario), after a first run that compiles.
"""

from __future__ import annotations

import json
import platform
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from _timing import best_time
from mixnav import __version__
from mixnav.config import load_scenario
from mixnav.config.loader import resolve
from mixnav.experiment.run import run_scenario
from mixnav.filters._ekf_kernels import ekf_correct
from mixnav.filters.ekf import _warm_up
from mixnav.gnss.constellation import MultiConstellation
from mixnav.gnss.observables import simulate_observables
from mixnav.ins.error_model import get_layout
from mixnav.measurements.tight import TightGnss, observation_systems, tight_layout
from mixnav.sim.scenario import truth_and_ideal_imu

RESULTS = Path(__file__).resolve().parent / "results"
LEVER = np.array([0.5, 0.2, -1.0])
OFFSETS = {8: 12.0, 32: -20.0, 4: 35.0}


def _epoch_cost(obs, lay, nav, k) -> tuple[float, float, int]:
    """Best wall and CPU time [us] of one epoch's rows + correction, and the rows."""
    _warm_up(lay)
    meas = TightGnss(obs, LEVER, lay)
    la = lay.as_array()
    w_b = np.array([0.01, -0.02, 0.15])
    clock = obs.clock[k]
    aux = {"system_offset": np.zeros(lay.block("system_offset").size)} if lay.has("system_offset") else None
    sig = np.r_[np.full(3, 1e-2), np.full(3, 0.1), np.full(3, 2.0), np.full(3, 1e-4), np.full(3, 1e-2), 10.0, 1.0,
                np.full(lay.n - 17, 10.0)]
    P0 = np.diag(sig ** 2)

    def one():
        rows = meas.rows(k, nav, w_b, clock, aux=aux)
        return ekf_correct(P0, rows.z, rows.H, rows.R, 1e4, nav.copy(), np.zeros(12), np.zeros(2), la)

    wall = best_time(one, 7, number=2000, warmup=True)
    cpu = best_time(one, 7, number=2000, clock=time.process_time)
    return wall * 1e6, cpu * 1e6, len(meas.rows(k, nav, w_b, clock, aux=aux).z)


def bench_epochs() -> dict:
    sc, _, _ = load_scenario("tight-demo")
    truth = truth_and_ideal_imu(sc)[0]
    sats = MultiConstellation.of(("G", "E", "C", "R"))
    obs = simulate_observables(truth, sats, 1.0, LEVER, np.radians(10), 3.0, 0.1, 0.003, (0.1, 0.01), (7.0, 0.5),
                               np.random.default_rng(0), system_offsets=OFFSETS)
    k = 100
    kt = int(np.searchsorted(truth.time, obs.time[k] - 1e-9))
    nav = np.concatenate([truth.q_nb[kt], truth.v_n[kt], truth.lla[kt]])
    gps_slots = obs.valid & (obs.system == 1)
    gps = replace(obs, valid=gps_slots, system=None)
    # the GPS satellites relabelled round-robin as four systems: equal rows, 3 offsets
    relabel = obs.system.copy()
    idx = np.nonzero(gps_slots[k])[0]
    relabel[k, idx] = np.array([1, 4, 8, 32])[np.arange(len(idx)) % 4]
    as4 = replace(obs, valid=gps_slots, system=relabel)
    lay17, lay20 = get_layout(17), tight_layout(get_layout(17), observation_systems(obs))
    out = {}
    for name, o, lay in (("gps", gps, lay17), ("gps_as_4", as4, lay20), ("all", obs, lay20)):
        wall, cpu, m = _epoch_cost(o, lay, nav, k)
        out[name] = {"satellites": int(o.valid[k].sum()), "rows": m, "states": lay.n,
                     "wall_us_per_epoch": wall, "cpu_us_per_epoch": cpu}
    return out


def bench_engine() -> dict:
    text, _ = resolve("tight-demo")
    multi = text.replace('constellation = "gps30"\n', 'constellation = "gps30"\nsystems = ["G", "E", "C", "R"]\n'
                         'system_offsets = ["12 m", "-20 m", "35 m"]\n')
    out = {}
    with tempfile.TemporaryDirectory() as d:
        for name, t in (("gps", text), ("four systems", multi)):
            p = Path(d) / f"{name.replace(' ', '_')}.toml"
            p.write_text(t)
            sc, src, _ = load_scenario(str(p))
            run_scenario(sc, src, seed=1)           # compiles (or loads) the kernels
            best = {}
            for _ in range(3):
                res = run_scenario(sc, src, seed=1).results["tight"]
                for key in ("update_time_mean_us", "epoch_time_mean_us"):
                    best[key] = min(best.get(key, np.inf), res.timing[key])
            best["satellites_mean"] = float(run_scenario(sc, src, seed=1).sim.observations.n_visible.mean())
            out[name] = best
    return out


def main():
    res = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                       "mixnav": __version__, "date": time.strftime("%Y-%m-%d %H:%M")},
           "epoch": bench_epochs(), "engine": bench_engine()}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "tight_multi_bench.json").write_text(json.dumps(res, indent=2) + "\n")
    lines = ["# Tight EKF epoch cost with several systems (benchmarks/bench_tight_multi.py)", "",
             f"Recorded {res['machine']['date']}, Python {res['machine']['python']}, mixnav "
             f"{res['machine']['mixnav']}; one process, best of 7 repeats of 2000 calls (a shared 2-core "
             "machine: CPU time beside wall time).", "",
             "One epoch, rows + correction + feedback:", "",
             "| case | satellites | rows | states | wall [us] | CPU [us] |", "| --- | --- | --- | --- | --- | --- |"]
    for k, v in res["epoch"].items():
        lines.append(f"| {k} | {v['satellites']} | {v['rows']} | {v['states']} | {v['wall_us_per_epoch']:.1f} | "
                     f"{v['cpu_us_per_epoch']:.1f} |")
    lines += ["", "Engine, tight-demo (600 s, seed 1), best of 3 runs, mean per GNSS epoch:", "",
              "| constellation | satellites (mean) | update [us] | whole epoch incl. INS [us] |",
              "| --- | --- | --- | --- |"]
    for k, v in res["engine"].items():
        lines.append(f"| {k} | {v['satellites_mean']:.1f} | {v['update_time_mean_us']:.1f} | "
                     f"{v['epoch_time_mean_us']:.1f} |")
    (RESULTS / "tight_multi_bench.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
