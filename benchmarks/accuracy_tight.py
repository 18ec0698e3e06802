"""Accuracy and consistency of the tight and TDCP EKFs over seeded runs.

    python benchmarks/accuracy_tight.py [--runs 20]   # writes benchmarks/results/tight.{md,json}

1. tight-demo, Gaussian noise, the filters' own models: run-averaged NEES of
   position and velocity and NIS per dof against their 95 % chi-square bands
   (the experiment runner's consistency table);
2. tight-demo's 60 s window with only the 3 highest satellites: maximum
   horizontal error in the window, tight EKF (still uses the 3 ranges and
   range rates) against the loose EKF (no fix at all);
3. tdcp-demo: pseudorange only vs pseudorange + TDCP with stochastic cloning vs
   the known-previous-position shortcut: velocity, attitude and position RMSE
   and NEES;
4. why cloning's NEES is below its dof: the same TDCP filter on carrier noise
   whose time differences are white (a random walk of the phase), where the
   filter's white-TDCP model is exact.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from mixnav.config import load_scenario
from mixnav.experiment.montecarlo import run_experiment, write_experiment_outputs
from mixnav.experiment.run import solution_table
from mixnav.experiment import methods as registry
from mixnav.ins.error_model import ClockModel
from mixnav.sim.scenario import simulate, truth_and_ideal_imu

RESULTS = Path(__file__).resolve().parent / "results"


def experiment(name: str, runs: int) -> tuple:
    out = Path(tempfile.mkdtemp(prefix=f"acc-{name}-"))
    df = run_experiment(name, runs, out, workers=2, progress=False)
    tables = write_experiment_outputs(name, df, out)
    return df, tables


def consistency_rows(tables, df) -> list[dict]:
    c = tables["consistency"]
    s = tables["series"]
    rows = []
    for _, r in c.iterrows():
        q = r["quantity"]
        lo_col, hi_col = ({"NEES pos": ("nees_pos_lo", "nees_pos_hi"), "NEES vel": ("nees_vel_lo", "nees_vel_hi"),
                           "NEES pv": ("nees_pv_lo", "nees_pv_hi"),
                           "NIS per dof": ("nis_lo", "nis_hi")}.get(q, (None, None)))
        g = s[s["method"] == r["method"]]
        band = (float(g[lo_col].median()), float(g[hi_col].median())) if lo_col in g else (np.nan, np.nan)
        rows.append({"method": r["method"], "quantity": q, "expected": r["expected"], "mean": r["mean"],
                     "in_band_fraction": r["in_band_fraction"], "band_lo": band[0], "band_hi": band[1],
                     "runs": int(r["runs"])})
    return rows


def white_tdcp_check(runs: int) -> dict:
    """TDCP filter (cloning) on carrier phases whose epoch differences are white.

    Carrier = range + receiver clock (a noise-free copy of the run: the same
    streams, observable sigmas 1e-12, so the same clock walk) + a random walk
    per satellite with steps of sqrt(2) * carrier_sigma: every TDCP then has
    independent noise of variance 2 sigma^2, exactly the filter's R. The
    ambiguity is left out (TDCP cancels it).
    """
    sc, src, _ = load_scenario("tdcp-demo")
    ideal = truth_and_ideal_imu(sc, src)
    s = sc.gnss.satellites
    quiet = s.model_copy(update={"carrier_sigma": 1e-12, "pseudorange_sigma": 1e-12,
                                 "range_rate_sigma": 1e-12})
    sc_quiet = sc.model_copy(update={"gnss": sc.gnss.model_copy(update={"satellites": quiet})})
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    m = next(mm for mm in sc.methods if mm.name == "tdcp")
    nees_p, nees_v, vel = [], [], []
    for seed in range(runs):
        sim = simulate(sc, seed, src, ideal=ideal)
        o = sim.observations
        range_clock = simulate(sc_quiet, seed, src, ideal=ideal).observations.pseudorange
        rng = np.random.default_rng(1000 + seed)
        walk = {}
        carrier = np.full_like(o.carrier, np.nan)
        for k in range(len(o.time)):
            for j in np.nonzero(o.valid[k])[0]:
                p = int(o.prn[k, j])
                walk[p] = walk.get(p, 0.0) + rng.standard_normal() * np.sqrt(2) * o.sigma_cp
                carrier[k, j] = range_clock[k, j] + walk[p]
        o2 = dataclasses.replace(o, carrier=carrier)
        filt, meas = registry.build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 1,
                                    observations=o2, clock=clock)
        res = filt.run(sim.imu, sim.init, meas)
        t = solution_table(res, sim.truth, sim.outages)
        nees_p.append(t["nees_pos"].mean())
        nees_v.append(t["nees_vel"].mean())
        vel.append(np.sqrt(np.mean(t["err_vn_mps"] ** 2 + t["err_ve_mps"] ** 2 + t["err_vd_mps"] ** 2)))
    return {"runs": runs, "nees_pos_per_dof": float(np.mean(nees_p) / 3),
            "nees_vel_per_dof": float(np.mean(nees_v) / 3), "velocity_rmse_mps": float(np.mean(vel))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--markdown-only", action="store_true",
                    help="rewrite tight.md from the recorded tight.json")
    args = ap.parse_args()
    if args.markdown_only:
        return write_md(json.loads((RESULTS / "tight.json").read_text()))
    t0 = time.perf_counter()
    res = {"date": time.strftime("%Y-%m-%d %H:%M"), "runs": args.runs}
    df, tables = experiment("tight-demo", args.runs)
    res["tight_consistency"] = consistency_rows(tables, df)
    w = df.pivot(index="seed", columns="method", values="outage0_horizontal_max_m")
    res["partial_outage"] = {
        "loose_median_m": float(w["loose"].median()), "tight_median_m": float(w["tight"].median()),
        "loose_max_m": float(w["loose"].max()), "tight_max_m": float(w["tight"].max()),
        "loose_mean_m": float(w["loose"].mean()), "tight_mean_m": float(w["tight"].mean()),
        "tight_better_fraction": float((w["tight"] < w["loose"]).mean())}
    df2, tables2 = experiment("tdcp-demo", args.runs)
    cols = ["velocity_rmse_mps", "roll_rmse_deg", "pitch_rmse_deg", "yaw_rmse_deg", "horizontal_rmse_m",
            "vertical_rmse_m"]
    res["tdcp"] = {m: {c: float(g[c].mean()) for c in cols} for m, g in df2.groupby("method")}
    # yaw is unobservable in the first 60 s at rest: its whole-run RMSE is mostly the
    # initial error; the RMS over runs and epochs after 150 s shows what TDCP changes
    s2 = tables2["series"]
    for m, g in s2[s2["time_s"] > 150].groupby("method"):
        res["tdcp"][m]["yaw_rmse_after_150s_deg"] = float(np.sqrt(np.mean(g["rms_err_yaw_deg"] ** 2)))
    res["tdcp_consistency"] = consistency_rows(tables2, df2)
    res["white_tdcp"] = white_tdcp_check(min(args.runs, 8))
    res["wall_s"] = time.perf_counter() - t0
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "tight.json").write_text(json.dumps(res, indent=2) + "\n")
    write_md(res)


def _f(x):
    return "n/a" if not np.isfinite(x) else f"{x:.3g}"


def write_md(res):
    L = ["# Tight coupling and TDCP: accuracy and consistency (benchmarks/accuracy_tight.py)", "",
         f"Recorded {res['date']}; {res['runs']} seeded runs per scenario (seeds 0..{res['runs'] - 1}); "
         f"Gaussian noise, each filter's own models; {res['wall_s']:.0f} s on 2 workers.", "",
         "## 1. tight-demo: consistency (run-averaged NEES / NIS, 95 % chi-square bands)", "",
         "`mean` is the time average of the run-averaged statistic, `in band` the share of epochs "
         "whose run average lies in its two-sided 95 % band (band shown at its median over epochs).", "",
         "| method | quantity | expected | mean | band | in band |", "| --- | --- | --- | --- | --- | --- |"]
    for r in res["tight_consistency"]:
        L.append(f"| {r['method']} | {r['quantity']} | {_f(r['expected'])} | {_f(r['mean'])} | "
                 + (f"[{_f(r['band_lo'])}, {_f(r['band_hi'])}]" if np.isfinite(r['band_lo']) else "-")
                 + f" | {r['in_band_fraction']:.2f} |")
    p = res["partial_outage"]
    L += ["", "## 2. tight-demo: 60 s with only the 3 highest satellites (300-360 s)", "",
          "Maximum horizontal error inside the window, per run; the loose EKF has no fix there.", "",
          "| method | median [m] | mean [m] | worst run [m] |", "| --- | --- | --- | --- |",
          f"| loose | {_f(p['loose_median_m'])} | {_f(p['loose_mean_m'])} | {_f(p['loose_max_m'])} |",
          f"| tight | {_f(p['tight_median_m'])} | {_f(p['tight_mean_m'])} | {_f(p['tight_max_m'])} |", "",
          f"Tight below loose in {100 * p['tight_better_fraction']:.0f} % of the runs.", "",
          "## 3. tdcp-demo: pseudorange only vs + TDCP (mean over runs of each run's RMSE)", "",
          "| method | velocity [m/s] | roll [deg] | pitch [deg] | yaw [deg] | yaw after 150 s [deg] | "
          "horizontal [m] | vertical [m] |",
          "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for m, v in res["tdcp"].items():
        L.append(f"| {m} | {_f(v['velocity_rmse_mps'])} | {_f(v['roll_rmse_deg'])} | {_f(v['pitch_rmse_deg'])} | "
                 f"{_f(v['yaw_rmse_deg'])} | {_f(v['yaw_rmse_after_150s_deg'])} | {_f(v['horizontal_rmse_m'])} | {_f(v['vertical_rmse_m'])} |")
    L += ["", "Yaw is unobservable during the first 60 s at rest, so its whole-run RMSE is "
          "mostly the initial 2 deg error, the same for all; after 150 s (the first acceleration "
          "and turn done) the TDCP velocity makes yaw observable far sooner.", "",
          "Consistency of the three:", "", "| method | quantity | expected | mean | band | in band |",
          "| --- | --- | --- | --- | --- | --- |"]
    for r in res["tdcp_consistency"]:
        L.append(f"| {r['method']} | {r['quantity']} | {_f(r['expected'])} | {_f(r['mean'])} | "
                 + (f"[{_f(r['band_lo'])}, {_f(r['band_hi'])}]" if np.isfinite(r['band_lo']) else "-")
                 + f" | {r['in_band_fraction']:.2f} |")
    wt = res["white_tdcp"]
    L += ["", "## 4. Why cloning's NEES is below its dof", "",
          "Successive TDCPs share a carrier epoch: with white carrier noise their errors are "
          "correlated (-1/2), so a sum of TDCPs (the displacement over many epochs) is far more "
          "accurate than the filter's white-TDCP model says, and the filter is conservative. "
          f"With a random-walk carrier noise whose differences are white ({wt['runs']} runs, same "
          "filter, same sigma of a TDCP) the model is exact:", "",
          f"- NEES position / dof: {_f(wt['nees_pos_per_dof'])}",
          f"- NEES velocity / dof: {_f(wt['nees_vel_per_dof'])}",
          f"- velocity RMSE: {_f(wt['velocity_rmse_mps'])} m/s", "",
          "Taking the previous position as known (`tdcp-known`) instead ignores that it is "
          "uncertain: the TDCP then pins the current position to millimetres and the position NEES "
          "grows by orders of magnitude (table above).", "",
          "Speed of a GNSS epoch (tight and TDCP, beside filterpy): tight_bench.md "
          "(benchmarks/bench_tight.py).", ""]
    (RESULTS / "tight.md").write_text("\n".join(L))
    print("\n".join(L))


if __name__ == "__main__":
    main()
