"""The RTS smoother: forward pass (filter with history) against backward pass, in one run.

    python benchmarks/bench_smoother.py      # writes benchmarks/results/smoother.{md,json}

Cases: loose-demo (simulated, 15 and 21 states, 1 Hz fixes, one 60 s outage) and, when
``../shared/data/drive-0708`` exists (or ``$MIXNAV_DATA``), drive-0708 (real, 15
states, 4 Hz RTK fixes, three withheld 30 s windows). For each, best of
``REPEATS`` in the same process, kernels compiled first:

- forward without history, and with it (the price of keeping the history);
- backward: ``rts_smooth`` (mapping the output epochs, the compiled recursion,
  the injection at the output epochs; ``timing["smoother_time_s"]``);
- the history's memory per event (bytes of its arrays over the events);
- the largest horizontal error in each outage window, filter and smoother.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from _timing import best_of
from mixnav.config import load_dataset, load_scenario
from mixnav.engine.smoother import rts_smooth
from mixnav.experiment.run import solution_table
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.ins.error_model import get_layout
from mixnav.measurements.loose import LooseGnss
from mixnav.sim.scenario import simulate

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MIXNAV_DATA", ROOT.parent / "shared" / "data"))
RESULTS = ROOT / "benchmarks" / "results"
REPEATS = 7


def _outage_max(table, windows):
    h = np.hypot(table["err_n_m"], table["err_e_m"]).to_numpy()
    t = table["time_s"].to_numpy()
    return [float(h[(t > a) & (t <= b)].max()) for a, b in windows]


def _case(name, run, truth, windows, lever=None):
    run(False)  # compile / warm the caches
    rts_smooth(run(True))
    fwd_plain, _ = best_of(lambda: run(False), REPEATS)
    fwd_hist, res = best_of(lambda: run(True), REPEATS)
    bwd, sm = best_of(lambda: rts_smooth(res), REPEATS)
    h = res.history
    E, n = len(h.time), res.layout.n
    nbytes = sum(a.nbytes for a in (h.time, h.Phi, h.P_pred, h.P_filt, h.dx, h.nav, h.updated))
    tf = solution_table(res, truth, windows, lever=lever)
    ts = solution_table(sm, truth, windows, lever=lever)
    return {"case": name, "states": n, "events": E, "output_epochs": len(res.time),
            "forward_s": fwd_plain, "forward_history_s": fwd_hist, "backward_s": bwd,
            "backward_kernel_s": sm.timing["smoother_time_s"],
            "backward_over_forward": bwd / fwd_hist, "backward_us_per_event": bwd / E * 1e6,
            "forward_us_per_event": fwd_hist / E * 1e6,
            "history_bytes_per_event": nbytes / E, "history_formula_bytes": 8 * (3 * n * n + n + 11) + 1,
            "smoother_not_pd": sm.recoveries["smoother_not_pd"],
            "outages": [{"window_s": [float(a), float(b)], "filter_max_m": f, "smoother_max_m": s}
                        for (a, b), f, s in zip(windows, _outage_max(tf, windows), _outage_max(ts, windows))],
            "nees_pos_filter_mean": float(tf["nees_pos"].mean()), "nees_pos_smoother_mean": float(ts["nees_pos"].mean())}


def loose_demo(n_states=15):
    sc, src, _ = load_scenario("loose-demo")
    sim = simulate(sc, sc.scenario.seed, src)
    lay = get_layout(n_states)
    meas = [LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm, float), lay)]
    f = ErrorStateEkf(lay, sim.imu_model)
    return _case("loose-demo" if n_states == 15 else f"loose-demo, {n_states} states", lambda hist: f.run(sim.imu, sim.init, meas, history=hist), sim.truth,
                 [tuple(o) for o in sc.gnss.outages])


def drive_0708():
    from mixnav.config.loader import imu_model
    from mixnav.experiment import methods
    from mixnav.experiment.process import process
    ds, src, _ = load_dataset("drive-0708-plain")
    po = process(ds, src, str(DATA / "drive-0708"))  # read, withhold, align: as `mixnav process`
    m = ds.methods[0]
    filt, meas = methods.build(m, imu_model(ds.imu.grade, ds.imu.errors, src, "imu.errors", "imu.grade"),
                               po.fixes, po.lever, src, 0)
    ref = po.reference
    out_t = ref.time[(ref.time > po.init.time) & (ref.time <= po.imu.time[-1])]
    return _case("drive-0708", lambda hist: filt.run(po.imu, po.init, meas, output_times=out_t, history=hist),
                 ref, [tuple(w) for w in ds.gnss.withhold], lever=po.lever)


def main():
    cases = [loose_demo(15), loose_demo(21)]
    if (DATA / "drive-0708").exists():
        cases.append(drive_0708())
    out = {"date": time.strftime("%Y-%m-%d %H:%M"), "repeats": REPEATS, "cases": cases}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "smoother.json").write_text(json.dumps(out, indent=2) + "\n")
    md = ["# RTS smoother: forward vs backward pass (benchmarks/bench_smoother.py)", "",
          f"Recorded {out['date']}, best of {REPEATS} in one process, kernels compiled first. "
          "Forward = `ErrorStateEkf.run` (mechanization, covariance, updates, recording); backward = "
          "`rts_smooth` on its result (output-epoch mapping, compiled recursion over every event, "
          "injection at the output epochs).", "",
          "| case | n | events | forward [s] | forward + history [s] | backward [s] | backward / forward "
          "| forward [us/event] | backward [us/event] | history [B/event] |",
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for c in cases:
        md.append(f"| {c['case']} | {c['states']} | {c['events']} | {c['forward_s']:.4f} | "
                  f"{c['forward_history_s']:.4f} | {c['backward_s']:.4f} | {c['backward_over_forward']:.2f} | "
                  f"{c['forward_us_per_event']:.1f} | {c['backward_us_per_event']:.1f} | "
                  f"{c['history_bytes_per_event']:.0f} (formula {c['history_formula_bytes']}) |")
    md += ["", "| case | outage window [s] | filter max horizontal error [m] | smoother [m] |",
           "| --- | --- | --- | --- |"]
    for c in cases:
        md += [f"| {c['case']} | {o['window_s'][0]:g}-{o['window_s'][1]:g} | {o['filter_max_m']:.2f} | "
               f"{o['smoother_max_m']:.2f} |" for o in c["outages"]]
    md += ["", "| case | mean position NEES, filter | smoother | smoother_not_pd |", "| --- | --- | --- | --- |"]
    md += [f"| {c['case']} | {c['nees_pos_filter_mean']:.2f} | {c['nees_pos_smoother_mean']:.2f} | "
           f"{c['smoother_not_pd']} |" for c in cases]
    md += ["", "Notes:", "",
           "- The backward pass is a fraction of the forward one: per event it is one n x n Cholesky, "
           "Phi P_filt (Phi sparse), two triangular solves and G (P_s - P_pred) G^T, about 4 n^3 "
           "multiply-adds in one compiled call over all events; the forward event also mechanizes 25 "
           "(drive-0708, 4 Hz) to 100 (loose-demo, 1 Hz) IMU increments and updates.",
           "- Keeping the history costs the forward pass the difference of its two columns (writing "
           "three n x n matrices per event into preallocated arrays).",
           "- History memory per event is measured from the arrays' bytes: exactly 3 n^2 + n + 11 "
           "doubles + 1 byte (docs/smoother.md has the table for an hour at 4 events/s).",
           "- drive-0708's position NEES is scored against the withheld RTK fixes (antenna point); the "
           "filter's own is far above 3 already (the roof-mount vibration and time-tag jitter "
           "noted in its dataset file), and a smoother of a mis-modelled filter inherits it."]
    (RESULTS / "smoother.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
