"""Monte Carlo reproduction of paper P5 (VB-AUKF) on the P5-aircraft scenario.

    python benchmarks/reproductions/make_p5.py [--runs 50] [--workers 2] [--out DIR] [--velocity-too]

Runs the shipped ``P5-aircraft`` scenario for seeds 1..runs (its five methods: EKF, UKF,
VB-AKF, Sage-Husa, VB-AUKF, on the same simulated data per seed) plus an *oracle*: the EKF
told the true noise sd at every epoch (the best any noise-adaptive filter can do on
this data, the bound the targets are measured against). Scores each run by segment
(clean 100-400 s, jump 400-600 s and its last 140 s "jump_settled", recovery 600-900 s,
drift 900-1300 s, end 1300-1400 s),
the tracked noise sigma of the VB filters against the true sd outside the transients
(more than 60 s after each step of the noise), and the Monte Carlo NEES per epoch with
its 95 % chi-square band. Writes ``p5_runs.csv`` into ``--out``, and ``P5_tables.md``
and ``P5.png`` beside this file (``P5_velocity_too_*`` with ``--velocity-too``: the
same flight with the velocity noise changing as the position noise does).
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import chi2
from scipy.stats import t as student

HERE = Path(__file__).parent
SEGMENTS = {"clean": (100.0, 400.0), "jump": (400.0, 600.0), "jump_settled": (460.0, 600.0),
            "recovery": (600.0, 900.0), "drift": (900.0, 1300.0), "end": (1300.0, 1400.0)}
STEADY = [(100.0, 400.0), (460.0, 600.0), (660.0, 1400.0)]   # > 60 s after each step of the noise
CHANNELS = [f"{k}_{a}" for k in ("position", "velocity") for a in "ned"]
METHODS = ["ekf", "ukf", "vb-akf", "sage-husa", "vb-aukf", "ekf-oracle"]
LABEL = {"ekf": "EKF", "ukf": "UKF", "vb-akf": "VB-AKF (VB on the EKF)", "sage-husa": "Sage-Husa EKF",
         "vb-aukf": "VB-AUKF (P5)", "ekf-oracle": "EKF told the true sd (oracle)"}


_VELOCITY_PROFILE = '''[gnss.velocity_noise]
type = "profile"
base = { type = "gaussian", sigma = ["0.1 m/s", "0.1 m/s", "0.2 m/s"] }
steps = [["400 s", 5], ["600 s", 1]]
drifts = [["900 s", "1300 s", 4]]

'''


def _variant_text(velocity_too: bool) -> str:
    from mixnav.config.loader import resolve
    text, _ = resolve("P5-aircraft", "scenarios", "scenario")
    if velocity_too:
        b = text.index("[init]")
        text = text[:b] + _VELOCITY_PROFILE + text[b:]
        text = text.replace('name = "P5-aircraft"', 'name = "P5-aircraft-velocity-too"')
    return text


def one_run(args) -> tuple[list[dict], dict]:
    seed, scenario = args
    from dataclasses import replace
    from mixnav.config.loader import load_scenario
    from mixnav.experiment.run import gnss_noise_sd, run_scenario, solution_table
    from mixnav.filters.ekf import ErrorStateEkf
    from mixnav.ins.error_model import get_layout
    from mixnav.measurements.loose import LooseGnss
    sc, src, _ = load_scenario(scenario)
    out = run_scenario(sc, src, seed=seed)
    sim = out.sim
    fx = sim.fixes
    sd = gnss_noise_sd(sc, src, fx.time)
    told_true = replace(fx, pos_sigma=np.c_[sd["position_n"], sd["position_e"], sd["position_d"]],
                        vel_sigma=np.c_[sd["velocity_n"], sd["velocity_e"], sd["velocity_d"]])
    oracle = ErrorStateEkf(get_layout(15), sim.imu_model)
    results = dict(out.results)
    results["ekf-oracle"] = oracle.run(sim.imu, sim.init,
                                       [LooseGnss(told_true, np.asarray(sc.gnss.lever_arm, float), oracle.layout)])
    rows, series = [], {}
    for name in METHODS:
        res = results[name]
        t = solution_table(res, sim.truth, ())
        ts = t.time_s.to_numpy()
        e3 = t.err_n_m ** 2 + t.err_e_m ** 2 + t.err_d_m ** 2
        eh = t.err_n_m ** 2 + t.err_e_m ** 2
        ev = t.err_vn_mps ** 2 + t.err_ve_mps ** 2 + t.err_vd_mps ** 2
        row = {"seed": seed, "method": name, "wall_time_s": res.timing["wall_time_s"],
               "epoch_time_mean_us": res.timing["epoch_time_mean_us"]}
        for seg, (a, b) in SEGMENTS.items():
            s = ((ts >= a) & (ts < b))
            row[f"{seg}_pos_rmse"] = float(np.sqrt(e3[s].mean()))
            row[f"{seg}_hor_rmse"] = float(np.sqrt(eh[s].mean()))
            row[f"{seg}_vel_rmse"] = float(np.sqrt(ev[s].mean()))
            row[f"{seg}_yaw_rmse"] = float(np.sqrt((t.err_yaw_deg[s] ** 2).mean()))
            row[f"{seg}_nees_pos"] = float(t.nees_pos[s].mean())
        cols = [f"vb_sigma_{c}" for c in CHANNELS]
        ser = {"time": ts, "nees_pos": t.nees_pos.to_numpy(), "e3": e3.to_numpy()}
        if all(c in t.columns for c in cols):
            truth = gnss_noise_sd(sc, src, ts)
            steady = np.zeros(len(ts), bool)
            for a, b in STEADY:
                steady |= (ts >= a) & (ts < b)
            for c in CHANNELS:
                ratio = t[f"vb_sigma_{c}"].to_numpy() / truth[c]
                ok = steady & np.isfinite(ratio)
                row[f"sigma_ratio_{c}"] = float(ratio[ok].mean())
                row[f"sigma_abs_err_{c}"] = float(np.abs(ratio[ok] - 1).mean())
                ser[f"sigma_{c}"] = t[f"vb_sigma_{c}"].to_numpy()
                ser[f"true_{c}"] = truth[c]
        rows.append(row)
        series[name] = ser
    return rows, series


def _ci(x):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    n = len(x)
    if n < 2:
        return float(x.mean()) if n else np.nan, np.nan
    return float(x.mean()), float(student.ppf(0.975, n - 1) * x.std(ddof=1) / np.sqrt(n))


def _fmt(m, h, d=2):
    return f"{m:.{d}f} ± {h:.{d}f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("p5_out"))
    ap.add_argument("--velocity-too", action="store_true")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    tag = "P5_velocity_too" if a.velocity_too else "P5"
    scen = a.out / f"{tag}.toml"
    scen.write_text(_variant_text(a.velocity_too))
    t0 = time.perf_counter()
    rows, acc = [], {}
    tasks = [(s, str(scen)) for s in range(1, a.runs + 1)]
    with ProcessPoolExecutor(a.workers) as pool:
        for k, (r, series) in enumerate(pool.map(one_run, tasks)):
            rows += r
            for name, ser in series.items():   # sums over runs, per epoch
                d = acc.setdefault(name, {"time": ser["time"], "n": 0})
                d["n"] += 1
                for key, v in ser.items():
                    if key == "time":
                        continue
                    d[key] = d.get(key, 0.0) + v
                    if key.startswith("sigma_"):
                        d.setdefault("all_" + key, []).append(v)
            print(f"run {k + 1}/{a.runs} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    df = pd.DataFrame(rows)
    df.to_csv(a.out / "p5_runs.csv", index=False)
    elapsed = time.perf_counter() - t0
    N = a.runs
    lo, hi = chi2.ppf(0.025, 3 * N) / N, chi2.ppf(0.975, 3 * N) / N
    lines = [f"# {tag} tables (generated by make_p5.py)", "",
             f"{N} runs, seeds 1-{N}; {elapsed:.0f} s wall with {a.workers} workers. Mean ± half width of the "
             "95 % confidence interval over runs (t distribution).", ""]
    # 1. RMSE by segment
    lines += ["## 3-D position RMSE by segment [m]", "",
              "| method | " + " | ".join(SEGMENTS) + " |", "|---|" + "---|" * len(SEGMENTS)]
    for m in METHODS:
        sub = df[df.method == m]
        lines.append(f"| {LABEL[m]} | " + " | ".join(_fmt(*_ci(sub[f"{s}_pos_rmse"])) for s in SEGMENTS) + " |")
    for q, unit, d in (("hor", "m", 2), ("vel", "m/s", 3), ("yaw", "deg", 3)):
        lines += ["", f"## {dict(hor='horizontal position', vel='3-D velocity', yaw='yaw')[q]} RMSE by "
                  f"segment [{unit}]", "", "| method | " + " | ".join(SEGMENTS) + " |", "|---|" + "---|" * len(SEGMENTS)]
        for m in METHODS:
            sub = df[df.method == m]
            lines.append(f"| {LABEL[m]} | " + " | ".join(_fmt(*_ci(sub[f"{s}_{q}_rmse"]), d) for s in SEGMENTS) + " |")
    # 2. paired comparisons
    lines += ["", "## Paired comparisons: relative difference of the 3-D position RMSE, (A - B) / B [%]", "",
              "Per run, then mean ± 95 % CI over runs; negative: A better.", "",
              "| A vs B | " + " | ".join(SEGMENTS) + " |", "|---|" + "---|" * len(SEGMENTS)]
    wide = {s: df.pivot(index="seed", columns="method", values=f"{s}_pos_rmse") for s in SEGMENTS}
    for A, B in (("vb-aukf", "ukf"), ("vb-akf", "ekf"), ("vb-aukf", "vb-akf"), ("vb-aukf", "sage-husa"),
                 ("ukf", "ekf"), ("ekf-oracle", "ukf"), ("vb-aukf", "ekf-oracle")):
        cells = [_fmt(*_ci(100 * (wide[s][A] - wide[s][B]) / wide[s][B]), 1) for s in SEGMENTS]
        lines.append(f"| {A} vs {B} | " + " | ".join(cells) + " |")
    # 3. NEES
    lines += ["", f"## Position NEES (3 dof): Monte Carlo mean per epoch, averaged over the segment; in brackets "
              f"the fraction of epochs whose {N}-run mean lies in the 95 % band [{lo:.2f}, {hi:.2f}]", "",
              "| method | " + " | ".join(SEGMENTS) + " |", "|---|" + "---|" * len(SEGMENTS)]
    for m in METHODS:
        d = acc[m]
        t = d["time"]
        nees = d["nees_pos"] / d["n"]
        cells = []
        for s, (a0, b0) in SEGMENTS.items():
            sel = (t >= a0) & (t < b0)
            cells.append(f"{nees[sel].mean():.2f} ({np.mean((nees[sel] >= lo) & (nees[sel] <= hi)):.0%})")
        lines.append(f"| {LABEL[m]} | " + " | ".join(cells) + " |")
    # 4. tracked sigma
    lines += ["", "## Tracked noise sigma / true sd outside the transients (> 60 s after each step)", "",
              "Per run the mean of tracked/true over the steady epochs, then mean ± CI over runs; in brackets "
              "the mean absolute relative error |tracked/true - 1|.", "",
              "| method | " + " | ".join(CHANNELS) + " |", "|---|" + "---|" * len(CHANNELS)]
    for m in ("vb-akf", "vb-aukf"):
        sub = df[df.method == m]
        cells = [f"{_fmt(*_ci(sub[f'sigma_ratio_{c}']))} ({sub[f'sigma_abs_err_{c}'].mean():.0%})"
                 for c in CHANNELS]
        lines.append(f"| {LABEL[m]} | " + " | ".join(cells) + " |")
    # the mean tracked sigma of all runs, by segment
    lines += ["", "## Mean over runs of the tracked sigma / true sd, by segment (transients included)", "",
              "| method, channel | " + " | ".join(SEGMENTS) + " |", "|---|" + "---|" * len(SEGMENTS)]
    for m in ("vb-akf", "vb-aukf"):
        d = acc[m]
        t = d["time"]
        for c in ("position_n", "position_d", "velocity_n"):
            r = (d[f"sigma_{c}"] / d["n"]) / (d[f"true_{c}"] / d["n"])
            cells = [f"{np.nanmean(r[(t >= a0) & (t < b0)]):.2f}" for a0, b0 in SEGMENTS.values()]
            lines.append(f"| {m}, {c} | " + " | ".join(cells) + " |")
    lines += ["", "## Time", "", "| method | wall time per run [s] | filter time per GNSS epoch [us] |", "|---|---|---|"]
    for m in METHODS:
        sub = df[df.method == m]
        lines.append(f"| {LABEL[m]} | {sub.wall_time_s.mean():.2f} | {sub.epoch_time_mean_us.mean():.0f} |")
    (HERE / f"{tag}_tables.md").write_text("\n".join(lines) + "\n")
    _figure(acc, N, lo, hi, HERE / f"{tag}.png", tag)
    print("\n".join(lines))


def _figure(acc, N, lo, hi, path, tag):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(4, 1, figsize=(9, 12), sharex=True, constrained_layout=True)
    for k, c in enumerate(("position_n", "velocity_n")):
        a = ax[k]
        for m, col in (("vb-aukf", "C0"), ("vb-akf", "C1")):
            d = acc[m]
            t = d["time"]
            allv = np.array(d["all_sigma_" + c])
            a.plot(t, np.nanmean(allv, axis=0), color=col, lw=1.2, label=f"{LABEL[m]}: mean over {N} runs")
            if m == "vb-aukf":
                a.fill_between(t, np.nanpercentile(allv, 5, axis=0), np.nanpercentile(allv, 95, axis=0),
                               color=col, alpha=0.2, lw=0, label="VB-AUKF: 5-95 % of runs")
        d = acc["vb-aukf"]
        a.plot(d["time"], d[f"true_{c}"] / d["n"], "k", lw=1.0, label="true sd")
        a.set_ylabel("m" if c.startswith("position") else "m/s")
        a.set_title(f"{tag}: tracked GNSS noise sigma, {c.replace('_', ' ')}")
        a.grid(alpha=0.3)
        a.legend(fontsize="small", loc="upper right")
    a = ax[2]
    for m, col in (("ukf", "C3"), ("vb-aukf", "C0"), ("ekf-oracle", "k")):
        d = acc[m]
        a.semilogy(d["time"], d["nees_pos"] / d["n"], color=col, lw=1.0, label=LABEL[m])
    a.axhspan(lo, hi, color="g", alpha=0.15, label=f"95 % band, {N} runs")
    a.set_ylabel("position NEES")
    a.set_title("Monte Carlo mean position NEES per epoch")
    a.grid(alpha=0.3)
    a.legend(fontsize="small", loc="upper right")
    a = ax[3]
    for m, col in (("ukf", "C3"), ("sage-husa", "C2"), ("vb-aukf", "C0"), ("ekf-oracle", "k")):
        d = acc[m]
        a.plot(d["time"], np.sqrt(d["e3"] / d["n"]), color=col, lw=1.0, label=LABEL[m])
    a.set_ylabel("m")
    a.set_xlabel("time [s]")
    a.set_title("3-D position RMS error over runs, per epoch")
    a.grid(alpha=0.3)
    a.legend(fontsize="small", loc="upper right")
    for a in ax:
        for s0, s1 in ((400, 600), (900, 1300)):
            a.axvspan(s0, s1, color="grey", alpha=0.08)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
