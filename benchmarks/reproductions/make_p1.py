"""Tables of the P1 reproduction from `mixnav experiment` folders.

    mixnav experiment P1-sim1 --runs 50 --out runs/P1-sim1
    mixnav experiment P1-sim2 --runs 50 --out runs/P1-sim2
    python -c "import sys; from pathlib import Path; sys.path.insert(0, 'benchmarks/reproductions'); \
        import make_p1; make_p1.late_gross_variant(Path('runs'))"
    mixnav experiment runs/P1-sim1-late-gross.toml --runs 50 --out runs/P1-sim1-late-gross
    (the same with urban_variant -> runs/P1-sim1-urban, random_gross_variant ->
    runs/P1-sim1-random-gross and consumer_variant -> runs/P1-sim1-consumer)
    python benchmarks/reproductions/make_p1.py runs      # -> benchmarks/reproductions/P1_tables.md

Each cell is the mean over runs with the half width of its 95 % confidence
interval; the paper's value (P1 tables 1 and 2, MATLAB on an i5-7200U) is
given beside it. The epsilon sweeps (P1 fig. 4) have their own script,
``make_p1_sweep.py`` (tables in P1_sweep_tables.md, figures P1-sweep*.png).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).parent
ORDER = ["ekf", "robust", "mcmc-1000", "mcmc-5000", "vb", "gm-true"]
PAPER_SCHEME = {"ekf": "1", "robust": "2", "mcmc-1000": "3", "mcmc-5000": "4", "vb": "5", "gm-true": "-"}
# P1 table 1: pitch, roll, yaw RMSE [deg], time per epoch [s]
PAPER_T1 = {"ekf": (0.5829, 0.6738, 0.8727, 0.084), "robust": (0.3145, 0.3784, 0.7347, 0.092),
            "mcmc-1000": (0.2276, 0.3399, 0.5831, 0.206), "mcmc-5000": (0.1648, 0.0998, 0.4727, 0.530),
            "vb": (0.1974, 0.1073, 0.4746, 0.108)}
# P1 table 2: outage 1 horizontal, vertical; outage 2 horizontal, vertical [m]; time per epoch [s]
PAPER_T2 = {"ekf": (60.49, 2.68, 60.78, 2.75, 0.098), "robust": (58.72, 2.01, 58.33, 2.03, 0.114),
            "mcmc-1000": (56.86, 1.81, 56.17, 1.72, 0.240), "mcmc-5000": (51.40, 1.43, 52.93, 1.47, 0.608),
            "vb": (51.41, 1.48, 52.83, 1.46, 0.124)}


def _cell(summary: pd.DataFrame, method: str, metric: str, scale: float = 1.0, fmt: str = ".4g") -> str:
    r = summary[(summary["method"] == method) & (summary["metric"] == metric)]
    if r.empty:
        return ""
    m, h = float(r["mean"].iloc[0]) * scale, float(r["ci95_half"].iloc[0]) * scale
    return f"{m:{fmt}} ± {h:.2g}"


def table1(summary: pd.DataFrame, runs: int) -> list[str]:
    out = [f"### P1-sim1 (table 1), {runs} runs", "",
           "| scheme | method | pitch RMSE [deg] (paper) | roll RMSE [deg] (paper) | yaw RMSE [deg] (paper) | "
           "time per epoch [ms] (paper) | learning [s] | total [s] |", "|---|---|---|---|---|---|---|---|"]
    for m in ORDER:
        p = PAPER_T1.get(m)
        ref = (lambda i: f" ({p[i]})" if p else "")
        out.append(f"| {PAPER_SCHEME[m]} | {m} | {_cell(summary, m, 'pitch_rmse_deg')}{ref(0)} | "
                   f"{_cell(summary, m, 'roll_rmse_deg')}{ref(1)} | {_cell(summary, m, 'yaw_rmse_deg')}{ref(2)} | "
                   f"{_cell(summary, m, 'epoch_time_mean_us', 1e-3)}"
                   f"{f' ({p[3] * 1e3:g})' if p else ''} | {_cell(summary, m, 'learning_time_s')} | "
                   f"{_cell(summary, m, 'total_time_s')} |")
    return out


def table2(summary: pd.DataFrame, runs: int) -> list[str]:
    out = [f"### P1-sim2 (table 2), {runs} runs", "",
           "| scheme | method | outage 20-50 s: max horiz. [m] (paper) | max vert. [m] (paper) | "
           "outage 70-100 s: max horiz. [m] (paper) | max vert. [m] (paper) | time per epoch [ms] (paper) |",
           "|---|---|---|---|---|---|---|"]
    keys = ["outage0_horizontal_max_m", "outage0_vertical_max_m", "outage1_horizontal_max_m",
            "outage1_vertical_max_m"]
    for m in ORDER:
        p = PAPER_T2.get(m)
        cells = [f"{_cell(summary, m, k)}{f' ({p[i]})' if p else ''}" for i, k in enumerate(keys)]
        cells.append(f"{_cell(summary, m, 'epoch_time_mean_us', 1e-3)}{f' ({p[4] * 1e3:g})' if p else ''}")
        out.append(f"| {PAPER_SCHEME[m]} | {m} | " + " | ".join(cells) + " |")
    return out


LATE_GROSS = "`gross.start = 20`, written by `late_gross_variant`"


URBAN = "5-6 satellites instead of 8, written by `urban_variant`"


def urban_variant(out: Path) -> Path:
    """P1-sim1 with a 30 deg elevation mask (5-6 satellites instead of 8: a weaker geometry,
    where each gross error weighs more), everything else as shipped; returns the TOML."""
    from mixnav.config.loader import resolve
    text, _ = resolve("P1-sim1")
    assert text.count('mask = "10 deg"') == 1
    p = out / "P1-sim1-urban.toml"
    p.write_text(text.replace('mask = "10 deg"', 'mask = "30 deg"').replace('name = "P1-sim1"',
                                                                            'name = "P1-sim1-urban"'))
    return p


RANDOM_GROSS = ("each pseudorange gross with probability 0.05 at every epoch, independently, "
                "instead of all of them every 20 epochs; written by `random_gross_variant`")


def random_gross_variant(out: Path) -> Path:
    """P1-sim1 with the 2.5 m gross errors hitting each pseudorange independently with
    probability 0.05 at every epoch (multipath-like; the same rate as the shipped one in 20
    epochs), the rows independent as the learned mixtures assume; returns the TOML."""
    from mixnav.config.loader import resolve
    text, _ = resolve("P1-sim1")
    old = '{ type = "gross", size = "2.5 m", every = 20 }'
    assert text.count(old) == 1
    p = out / "P1-sim1-random-gross.toml"
    p.write_text(text.replace(old, '{ type = "gross", size = "2.5 m", probability = 0.05 }')
                 .replace('name = "P1-sim1"', 'name = "P1-sim1-random-gross"'))
    return p


CONSUMER = ("a consumer-grade IMU: gyro bias 20 deg/h, ARW 0.5 deg/sqrt(h), scale factors 1 %, "
            "accelerometer bias 1 mg, VRW 100 ug/sqrt(Hz); written by `consumer_variant`")
_SHIPPED_IMU = ('errors = { gyro_bias = "2 deg/h", gyro_bias_instability = "0 deg/h", arw = "0.1 deg/sqrt(h)", '
                'gyro_scale = "0.3 %", accel_bias = "0.1 mg", accel_bias_instability = "0 ug", '
                'vrw = "30 ug/sqrt(Hz)", accel_scale = "0.3 %" }')


def consumer_variant(out: Path) -> Path:
    """P1-sim1 with a consumer-grade IMU (ten times the shipped gyro bias, five times its
    ARW, 1 % scale factors): the attitude then depends on how the GNSS rows are weighted,
    which is where a noise model can matter (issue 20); returns the TOML."""
    from mixnav.config.loader import resolve
    text, _ = resolve("P1-sim1")
    assert text.count(_SHIPPED_IMU) == 1
    worse = ('errors = { gyro_bias = "20 deg/h", gyro_bias_instability = "0 deg/h", arw = "0.5 deg/sqrt(h)", '
             'gyro_scale = "1 %", accel_bias = "1 mg", accel_bias_instability = "0 ug", vrw = "100 ug/sqrt(Hz)", '
             'accel_scale = "1 %" }')
    p = out / "P1-sim1-consumer.toml"
    p.write_text(text.replace(_SHIPPED_IMU, worse).replace('name = "P1-sim1"', 'name = "P1-sim1-consumer"'))
    return p


def late_gross_variant(out: Path) -> Path:
    """P1-sim1 with the first gross error at epoch 20 instead of 0 (P1.md point 2), everything
    else as shipped; returns the TOML written into ``out``."""
    from mixnav.config.loader import resolve
    text, _ = resolve("P1-sim1")
    old = '{ type = "gross", size = "2.5 m", every = 20 }'
    assert text.count(old) == 1
    p = out / "P1-sim1-late-gross.toml"
    p.write_text(text.replace(old, '{ type = "gross", size = "2.5 m", every = 20, start = 20 }'))
    return p


PAIRED = (("pitch_rmse_deg", "pitch RMSE [deg]"), ("roll_rmse_deg", "roll RMSE [deg]"),
          ("yaw_rmse_deg", "yaw RMSE [deg]"), ("horizontal_rmse_m", "horizontal RMSE [m]"))


def paired_table(folder: Path, title: str) -> list[str]:
    """Each method minus the EKF over the same seeds (mean ± 95 % t half width, runs better),
    and the runs *lost*: position NEES above 3x the EKF's of the same seed (issue 20)."""
    from scipy import stats
    d = pd.read_parquet(folder / "results.parquet")
    nees = d.pivot_table(index="seed", columns="method", values="nees_pos_mean")
    out = [f"#### {title}: paired differences to the EKF over the same {len(nees)} seeds", "",
           "| method | " + " | ".join(label for _, label in PAIRED) + " | runs lost |",
           "|---|" + "---|" * (len(PAIRED) + 1)]
    for m in [x for x in ORDER if x in nees.columns and x != "ekf"]:
        cells = []
        for key, _ in PAIRED:
            p = d.pivot_table(index="seed", columns="method", values=key)
            x = (p[m] - p["ekf"]).dropna()
            h = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
            cells.append(f"{x.mean():+.4g} ± {h:.2g} ({int((x < 0).sum())}/{len(x)} better)")
        lost = int((nees[m] > 3 * nees["ekf"]).sum())
        out.append(f"| {m} | " + " | ".join(cells) + f" | {lost} |")
    return out + [""]


def main(root: Path) -> None:
    lines = ["# P1 reproduction: the numbers", "",
             "Generated by `benchmarks/reproductions/make_p1.py` from the experiment folders; the "
             "discussion is in P1.md. Cells: mean over runs ± half width of the 95 % CI; in "
             "parentheses the paper's value.", ""]
    for name, fn in (("P1-sim1", table1), ("P1-sim2", table2), ("P1-sim1-late-gross", table1),
                     ("P1-sim1-urban", table1), ("P1-sim1-random-gross", table1), ("P1-sim1-consumer", table1)):
        d = root / name
        if (d / "summary.csv").exists():
            s = pd.read_csv(d / "summary.csv")
            runs = int(s["n"].max())
            t = fn(s, runs)
            if name.endswith("late-gross"):
                t[0] = (f"### P1-sim1 with the gross errors from epoch 20 ({LATE_GROSS}), {runs} runs "
                        "(the paper's values beside it are those of the shipped reading)")
            if name.endswith("random-gross"):
                t[0] = (f"### P1-sim1 with independent gross errors ({RANDOM_GROSS}), {runs} runs "
                        "(the paper's values beside it are those of the shipped reading)")
            if name.endswith("consumer"):
                t[0] = (f"### P1-sim1 with {CONSUMER}, {runs} runs "
                        "(the paper's values beside it are those of the shipped reading)")
            if name.endswith("urban"):
                t[0] = (f"### P1-sim1 with a 30 deg elevation mask ({URBAN}), {runs} runs "
                        "(the paper's values beside it are those of the shipped reading)")
            lines += t + [""]
            if (d / "results.parquet").exists():
                lines += paired_table(d, name)
    (HERE / "P1_tables.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "runs"))
