"""Tables and figures of the P1 epsilon sweeps (paper P1 fig. 4) from `mixnav experiment` folders.

    mixnav experiment P1-sweep      --runs 50 --out runs/p1-sweep      --workers 1
    mixnav experiment P1-sweep-sim2 --runs 50 --out runs/p1-sweep-sim2 --workers 1
    python benchmarks/reproductions/make_p1_sweep.py runs/p1-sweep runs/p1-sweep-sim2

writes, next to this file, ``P1_sweep_tables.md`` (one row per epsilon and
metric, one column per method: mean over runs ± half width of its 95 % t
confidence interval, from the experiment's ``summary.csv``) and the figures
``P1-sweep.png`` (fig. 4a: maximum roll, pitch, yaw error and maximum
horizontal error over the run) and ``P1-sweep-sim2.png`` (fig. 4b: maximum
horizontal and vertical error in each of the two 30 s outages), each point
the mean over runs with its 95 % CI as error bar.  A missing folder is skipped.

For P1-sweep it also recomputes the four maxima from the per-epoch series
(``runs/series_*``) over ``t > 30 s`` only (``P1-sweep-after-30s.png`` and a
table): the whole-run maxima of the learned filters are set in the first
epochs by the start-up problem P1.md describes (gross errors at epoch 0), and
the maxima without the start-up show how the noise models compare once the
state has converged.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy import stats  # noqa: E402

HERE = Path(__file__).parent
ORDER = ["ekf", "robust", "mcmc-1000", "mcmc-5000", "vb", "gm-true"]
STYLE = {"ekf": ("tab:blue", "o"), "robust": ("tab:purple", "s"), "mcmc-1000": ("tab:green", "v"),
         "mcmc-5000": ("tab:red", "^"), "vb": ("tab:brown", "D"), "gm-true": ("tab:gray", "x")}
SWEEPS = {
    "P1-sweep": ("P1 fig. 4(a): P1-sim1 over epsilon",
                 [("roll_max_deg", "max roll error [deg]"), ("pitch_max_deg", "max pitch error [deg]"),
                  ("yaw_max_deg", "max yaw error [deg]"), ("horizontal_max_m", "max horizontal error [m]")]),
    "P1-sweep-sim2": ("P1 fig. 4(b): P1-sim2 over epsilon, maxima in the outages",
                      [("outage0_horizontal_max_m", "outage 20-50 s: max horizontal [m]"),
                       ("outage1_horizontal_max_m", "outage 70-100 s: max horizontal [m]"),
                       ("outage0_vertical_max_m", "outage 20-50 s: max vertical [m]"),
                       ("outage1_vertical_max_m", "outage 70-100 s: max vertical [m]")]),
}


STARTUP_S = 30.0      # the start-up excluded from the series maxima [s]


def series_maxima(folder: Path, values: list[float], t0: float = STARTUP_S) -> pd.DataFrame:
    """Per run (seed, sweep_value, method): the four maxima over ``t > t0`` from the series files."""
    rows = []
    for f in sorted((folder / "runs").glob("series_*_v*.parquet")):
        seed, v = f.stem.removeprefix("series_").split("_v")
        s = pd.read_parquet(f)
        s = s[s["time_s"] > t0]
        for m, g in s.groupby("method"):
            rows.append({"seed": int(seed), "sweep_value": values[int(v)], "method": m,
                         "roll_max_deg": g["err_roll_deg"].abs().max(),
                         "pitch_max_deg": g["err_pitch_deg"].abs().max(), "yaw_max_deg": g["err_yaw_deg"].abs().max(),
                         "horizontal_max_m": np.hypot(g["err_n_m"], g["err_e_m"]).max()})
    return pd.DataFrame(rows)


def _ci(x: np.ndarray) -> tuple[float, float]:
    """Mean and half width of the 95 % t confidence interval of the mean."""
    x = x[np.isfinite(x)]
    half = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x)) if len(x) > 1 else np.nan
    return float(x.mean()), float(half)


def summarise(runs: pd.DataFrame, metrics: list[str]) -> pd.DataFrame:
    """summary.csv-like table (sweep_value, method, metric, n, mean, ci95_half) of per-run records."""
    out = []
    for (v, m), g in runs.groupby(["sweep_value", "method"]):
        for k in metrics:
            mean, half = _ci(g[k].to_numpy(dtype=float))
            out.append({"sweep_value": v, "method": m, "metric": k, "n": len(g), "mean": mean, "ci95_half": half})
    return pd.DataFrame(out)


def paired(runs: pd.DataFrame, metrics: list[tuple[str, str]], title: str, ref: str = "ekf",
           others: list[str] | None = None) -> list[str]:
    """Table of the paired differences (method - ``ref``) over the same seeds, mean ± 95 % CI.

    Every method of a run sees the same simulated data, so the run-to-run spread, which makes
    the per-method intervals overlap, cancels in the difference.  ``*``: the interval excludes 0.
    """
    others = others or [m for m in ORDER if m != ref]
    out = [f"### {title}", "", "| epsilon | metric | " + " | ".join(f"{m} - {ref}" for m in others) + " |",
           "|---|---|" + "---|" * len(others)]
    for v, g in runs.groupby("sweep_value"):
        w = {k: g.pivot_table(index="seed", columns="method", values=k) for k, _ in metrics}
        for k, _ in metrics:
            cells = []
            for m in others:
                if m not in w[k] or ref not in w[k]:
                    cells.append("")
                    continue
                mean, half = _ci((w[k][m] - w[k][ref]).to_numpy(dtype=float))
                cells.append(f"{mean:+.3g} ± {half:.2g}{' *' if abs(mean) > half else ''}")
            out.append(f"| {v:g} | {k} | " + " | ".join(cells) + " |")
    return out


def _cell(g: pd.DataFrame, method: str, metric: str) -> str:
    r = g[(g["method"] == method) & (g["metric"] == metric)]
    if r.empty:
        return ""
    return f"{float(r['mean'].iloc[0]):.4g} ± {float(r['ci95_half'].iloc[0]):.2g}"


def table(summary: pd.DataFrame, metrics: list[tuple[str, str]], title: str) -> list[str]:
    out = [f"### {title}", "", "| epsilon | metric | " + " | ".join(ORDER) + " |", "|---|---|" + "---|" * len(ORDER)]
    for v, g in summary.groupby("sweep_value"):
        for metric, _ in metrics:
            out.append(f"| {v:g} | {metric} | " + " | ".join(_cell(g, m, metric) for m in ORDER) + " |")
    return out


def figure(summary: pd.DataFrame, metrics: list[tuple[str, str]], title: str, runs: int, path: Path) -> None:
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics), 3.8))
    eps = sorted(summary["sweep_value"].unique())
    step = min(b - a for a, b in zip(eps, eps[1:])) if len(eps) > 1 else 1.0
    for ax, (metric, label) in zip(axes, metrics):
        for i, m in enumerate(ORDER):
            r = summary[(summary["method"] == m) & (summary["metric"] == metric)].sort_values("sweep_value")
            if r.empty:
                continue
            dx = (i - (len(ORDER) - 1) / 2) * 0.06 * step        # side by side, so the bars stay readable
            c, mk = STYLE[m]
            ax.errorbar(r["sweep_value"] + dx, r["mean"], yerr=r["ci95_half"], color=c, marker=mk, ms=4,
                        lw=1.2, capsize=2, label=m)
        ax.set_xlabel("contamination ratio epsilon")
        ax.set_title(label, fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{title} ({runs} runs per value; mean and 95 % CI)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(folders: list[Path]) -> None:
    lines = ["# P1 epsilon sweeps (fig. 4): the numbers", "",
             "Generated by `benchmarks/reproductions/make_p1_sweep.py` from the experiment folders; the "
             "discussion is in P1.md. Cells: mean over runs ± half width of the 95 % t confidence interval "
             "of the mean.", ""]
    for folder in folders:
        s = pd.read_csv(folder / "summary.csv")
        name = next(k for k in SWEEPS if k.lower() == folder.name.lower())
        title, metrics = SWEEPS[name]
        runs = int(s[s["metric"].isin([k for k, _ in metrics])]["n"].min())
        lines += table(s, metrics, f"{name}: {title}, {runs} runs per value") + [""]
        figure(s, metrics, f"{name}: {title}", runs, HERE / f"{name}.png")
        res = pd.read_parquet(folder / "results.parquet")
        lines += paired(res, metrics, f"{name}: paired differences to the EKF (same seeds), {runs} runs") + [""]
        lines += paired(res, metrics, f"{name}: MCMC against VB, paired, {runs} runs", "vb",
                        ["mcmc-1000", "mcmc-5000"]) + [""]
        if name == "P1-sweep":
            values = json.loads((folder / "manifest.json").read_text())["sweep"]["values"]
            r = series_maxima(folder, values)
            a = summarise(r, [k for k, _ in metrics])
            t = f"{name}: maxima over t > {STARTUP_S:g} s (start-up excluded)"
            n = int(a["n"].min())
            lines += table(a, metrics, f"{t}, {n} runs per value") + [""]
            lines += paired(r, metrics, f"{t}: paired differences to the EKF, {n} runs") + [""]
            figure(a, metrics, t, n, HERE / f"{name}-after-30s.png")
    (HERE / "P1_sweep_tables.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main([Path(a) for a in sys.argv[1:] if (Path(a) / "summary.csv").exists()])
