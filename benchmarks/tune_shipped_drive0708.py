"""`mixnav tune` on the shipped, hand-fitted drive-0708 file: does the tuner improve it?

    python benchmarks/tune_shipped_drive0708.py [--workers 2]

Tunes src/mixnav/config/datasets/drive-0708.toml at the default budget (the file's own three
GNSS_IMU windows are never used by the tuner: they and their reconvergence are left out of the
cross-validation), then processes the file as shipped and as tuned and scores the three windows
against the reference (the causal `aided` filter and its smoother): an out-of-sample check of
the criterion on windows nobody tuned on by this tool. Writes
benchmarks/results/tune_shipped_drive0708.md and .json.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def windows(path: str, out: Path) -> dict:
    """Each method's horizontal maximum and mean position NEES in the file's withheld windows."""
    from mixnav.config import load_dataset
    from mixnav.experiment.data_folder import find_data_dir
    from mixnav.experiment.pipelines import pipeline
    ds, src, _ = load_dataset(path)
    p = pipeline(ds, src)
    folder = find_data_dir(ds, None, src)
    po = p.run(ds, src, folder, p.load(ds, src, folder))
    met = p.metrics(po, p.tables(po))
    return {m: [{"start_s": o["start_s"], "horizontal_max_m": o["horizontal_max_m"],
                 "nees_pos_mean": o.get("nees_pos_mean")} for o in met[m]["outages"]]
            for m in ("aided", "aided-smoothed")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "tune_shipped_drive0708"))
    a = ap.parse_args(argv)
    import mixnav
    with tempfile.TemporaryDirectory() as tmp:
        r = mixnav.tune("drive-0708", Path(tmp) / "tune", workers=a.workers)
        res = {"criterion_as_shipped": r.given, "criterion_tuned": r.tuned,
               "chosen": {k: c.get("value") for k, c in r.chosen.items()},
               "kept_as_given": r.kept_as_given,
               "found_not_written": r.found,
               **{k: json.loads((Path(tmp) / "tune" / "tune.json").read_text())[k]
                  for k in ("criterion_best_searched", "conservative_tolerance")},
               "as_shipped": windows("drive-0708", Path(tmp)),
               "tuned": windows(str(Path(tmp) / "tune" / "tuned.toml"), Path(tmp))}
    Path(a.out + ".json").write_text(json.dumps(res, indent=1, default=float) + "\n")
    g, t = res["criterion_as_shipped"], res["criterion_tuned"]
    lines = ["# mixnav tune on the shipped drive-0708 file", "",
             "`python benchmarks/tune_shipped_drive0708.py`: the hand-fitted drive-0708.toml tuned at the default "
             "budget (its three GNSS_IMU windows never used by the tuner), then both files scored in those windows "
             "against the reference.", "",
             "| | CV mean NLPD | CV median / p90 horizontal max vs own GNSS [m] |", "|---|---|---|",
             f"| as shipped | {g['nlpd']:.3f} | {g['cv_median_hmax_m']:.2f} / {g['cv_p90_hmax_m']:.2f} |",
             f"| tuned | {t['nlpd']:.3f} | {t['cv_median_hmax_m']:.2f} / {t['cv_p90_hmax_m']:.2f} |", "",
             "| file | method | the three windows: horizontal max [m] (mean position NEES) |", "|---|---|---|"]
    for label in ("as_shipped", "tuned"):
        for m, ws in res[label].items():
            lines.append(f"| {label.replace('_', ' ')} | {m} | " + ", ".join(
                f"{w['horizontal_max_m']:.2f} ({w['nees_pos_mean']:.1f})" for w in ws) + " |")
    if res["kept_as_given"]:
        lines += ["", f"tuned.toml is the file as shipped: {res['kept_as_given']}. The search's best had (not "
                  "written): " + ("; ".join(f"`{k}` = {v['value']}" for k, v in res["found_not_written"].items())
                                  or "nothing moved")]
    else:
        lines += ["", "Chosen: " + "; ".join(f"`{k}` = {v}" for k, v in res["chosen"].items())]
    Path(a.out + ".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
