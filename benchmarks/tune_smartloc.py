"""smartloc-berlin tuned by ``mixnav tune`` from a file without its chosen alignment settings (issue 35).

Run::

    PYTHONPATH=src python benchmarks/tune_smartloc.py [--budget 70] [--workers 2] [--out benchmarks/results]

1. ``mixnav.tune`` on ``benchmarks/configs/smartloc-berlin-untuned.toml`` (the shipped file with
   the alignment window, the C/N0 band edges and the start sigmas taken out: the schema's
   defaults) into ``<tmp>/tune`` (never reading the reference; the withheld-satellite
   criterion, mixnav.experiment.tuning.vehicle).
2. Scored against the reference afterwards (only here): the epoch mixture's causal 2-D RMSE of
   the untuned, the tuned and the shipped file, from each start 0, 30, ..., 150 s of the start
   sweep (each run scored from its own filter start, and all from start + 40 s, the longest
   window: the same epochs for every file), median and worst.
3. The tuner's own criterion (minus the epoch mixture's innovation log-likelihood per row, the
   likelihood tuner's VehicleEvaluator) of the shipped file, of the tuned file and of the values
   the tuner chose before its band edges reached the filter (:data:`BEFORE_FIX`): a search
   that ends above the shipped point on its own criterion has missed it.
4. Why not the innovation likelihood: for settings the two criteria judge differently (the
   shipped file; its LOS correlation time off; its lateral velocity noise x16), the epoch
   mixture's prequential innovation log-likelihood (all satellites, summed over the starts 0,
   30, ..., 150 s, rows from start + 40 s, as benchmarks/smartloc_choose_settings.py), the
   withheld-satellite criterion and the RMSE side by side.

Writes ``tune_smartloc.md`` and ``.json`` into ``--out``. About 10-25 min on two cores.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
UNTUNED = HERE / "configs" / "smartloc-berlin-untuned.toml"
STARTS = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
SCORE_FROM = 40.0
METHOD = "epoch-mixture"
#: what the likelihood tuner chose before its C/N0 band edges reached the epoch mixture
#: (set_edges wrote them into [alignment] only; results/tune_smartloc.md of commit a2afe9c):
#: (alignment keys, motion keys), scored here with the edges in the filter too
BEFORE_FIX = ({"window": "37.5 s", "cn0_edges": [38.0], "position_sigma": "3.536 m", "heading_sigma": "5.73 deg"},
              {"lateral_sigma": "1.6 m/s", "clock_q_drift": 6.25e-05})


def _load(path_or_name, options=None, motion=None):
    from mixnav.config.loader import load_dataset
    from mixnav.experiment.data_folder import find_data_dir
    ds, src, _ = load_dataset(str(path_or_name))
    ms = []
    for m in ds.methods:
        if m.name == METHOD:
            ms.append(m.model_copy(update={"smooth": False, "options": {**m.options, **(options or {})}}))
    ds = ds.model_copy(update={"methods": ms})
    if motion:
        ds = ds.model_copy(update={"motion": ds.motion.model_copy(update=motion)})
    return ds, src, find_data_dir(ds, None, src)


def score_against_reference(path_or_name, options=None, motion=None) -> dict:
    """RMSE per start (own start, and from start + 40 s) and the prequential log-likelihood."""
    from mixnav.experiment.tuning.vehicle import epoch_log_density
    from mixnav.experiment.vehicle_process import read_vehicle, run_vehicle, vehicle_tables
    ds, src, folder = _load(path_or_name, options, motion)
    inputs = read_vehicle(ds, src, folder)
    t0 = float(inputs.inc.time[0] - inputs.inc.dt[0])
    own, same, ll = [], [], 0.0
    for s in STARTS:
        d = ds.model_copy(update={"alignment": ds.alignment.model_copy(update={"start": s})})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            vo = run_vehicle(d, src, folder, inputs)
        tab = vehicle_tables(vo)[METHOD]
        e = np.hypot(tab["err_n_m"], tab["err_e_m"]).to_numpy()
        tt = tab["time_s"].to_numpy() - t0
        own.append(float(np.sqrt(np.mean(e ** 2))))
        same.append(float(np.sqrt(np.mean(e[tt > s + SCORE_FROM] ** 2))))
        t, lg, _ = epoch_log_density(vo.results[METHOD])
        ll += float(lg[(t - t0) > s + SCORE_FROM].sum())
    return {"rmse_own_start_m": own, "rmse_from_start_plus_40s_m": same, "median_own_m": float(np.median(own)),
            "worst_own_m": float(np.max(own)), "median_same_m": float(np.median(same)),
            "worst_same_m": float(np.max(same)), "prequential_log_likelihood": ll}


def _edited(path, alignment, motion, out: Path) -> Path:
    """A copy of the dataset file ``path`` with the alignment and motion keys replaced (the band
    edges by set_edges), written to ``out`` (its data_dir made absolute)."""
    import tomlkit
    from mixnav.experiment.tuning.vehicle import set_edges
    doc = tomlkit.parse(Path(path).read_text())
    doc["dataset"]["data_dir"] = str((Path(path).parent / doc["dataset"]["data_dir"]).resolve())
    for k, v in alignment.items():
        if k == "cn0_edges":
            set_edges(doc, v, METHOD)
        else:
            doc["alignment"][k] = v
    for k, v in motion.items():
        doc["motion"][k] = v
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(tomlkit.dumps(doc))
    return out


def withheld_criterion(path_or_name, options=None, motion=None) -> dict:
    """The tuner's own criterion of a file (reference sections removed first)."""
    import tomlkit
    from mixnav.config.loader import resolve
    from mixnav.experiment.sweep import _dataset_ref
    from mixnav.experiment.tuning.criterion import without_reference
    from mixnav.experiment.tuning.vehicle import SCORE_AFTER, VehicleEvaluator, starts_for
    text, source = resolve(_dataset_ref(str(path_or_name)), "datasets", "dataset")
    doc = tomlkit.parse(without_reference(text))
    for m in doc["methods"]:
        if m["name"] == METHOD and options:
            m.setdefault("options", tomlkit.table())
            for k, v in options.items():
                m["options"][k] = v
    if motion:
        for k, v in motion.items():
            doc["motion"][k] = f"{v} m/s"
    stripped = tomlkit.dumps(doc)
    ev = VehicleEvaluator(stripped, source, None, METHOD, [], SCORE_AFTER, "withheld-satellites")
    ev.starts = starts_for(ev.duration_s, "withheld-satellites")
    return ev.evaluate(stripped).as_dict()


def own_criterion(path_or_name, alignment=None, motion=None) -> dict:
    """The likelihood tuner's criterion of a file (reference sections removed first), the
    alignment and motion keys given replaced (band edges by the tuner's own set_edges)."""
    import tomlkit
    from mixnav.config.loader import resolve
    from mixnav.experiment.sweep import _dataset_ref
    from mixnav.experiment.tuning.criterion import without_reference
    from mixnav.experiment.tuning.vehicle import SCORE_AFTER, VehicleEvaluator, set_edges, starts_for
    text, source = resolve(_dataset_ref(str(path_or_name)), "datasets", "dataset")
    doc = tomlkit.parse(without_reference(text))
    for k, v in (alignment or {}).items():
        if k == "cn0_edges":
            set_edges(doc, v, METHOD)
        else:
            doc["alignment"][k] = v
    for k, v in (motion or {}).items():
        doc["motion"][k] = v
    stripped = tomlkit.dumps(doc)
    ev = VehicleEvaluator(stripped, source, None, METHOD, [], SCORE_AFTER, "likelihood")
    ev.starts = starts_for(ev.duration_s, "likelihood")
    return ev.evaluate(stripped).as_dict()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=70)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--tune-dir", default=None, help="tune into (and resume from) this folder")
    ap.add_argument("--out", default=str(HERE / "results"))
    a = ap.parse_args(argv)
    import mixnav
    tune_dir = Path(a.tune_dir) if a.tune_dir else Path(tempfile.mkdtemp()) / "tune"
    t = time.perf_counter()
    r = mixnav.tune(str(UNTUNED), tune_dir, budget=a.budget, workers=a.workers, resume=True, overwrite=True)
    tune_s = time.perf_counter() - t
    # the other criterion, the same search
    r2 = mixnav.tune(str(UNTUNED), tune_dir.parent / "tune-withheld", budget=a.budget, workers=a.workers,
                     criterion="withheld-satellites", resume=True, overwrite=True)
    files = {"untuned": UNTUNED, "tuned (likelihood, the default)": tune_dir / "tuned.toml",
             "tuned (withheld satellites)": tune_dir.parent / "tune-withheld" / "tuned.toml",
             "shipped": "smartloc-berlin"}
    scores = {k: score_against_reference(v) for k, v in files.items()}
    own = {"shipped": own_criterion("smartloc-berlin"),
           "tuned (likelihood, the default)": own_criterion(tune_dir / "tuned.toml"),
           "the tuner's choice before the fix (edges in [alignment] only), its edges in the filter too":
               own_criterion(UNTUNED, *BEFORE_FIX),
           "untuned": own_criterion(UNTUNED)}
    own_rmse = {"the tuner's choice before the fix (edges in [alignment] only), its edges in the filter too":
                score_against_reference(_edited(UNTUNED, *BEFORE_FIX, tune_dir.parent / "before_fix.toml"))}
    alts = {"shipped": ({}, {}), "shipped, LOS correlation time 0": ({"correlation_time": 0.0}, {}),
            "shipped, lateral velocity noise x16 (1.6 m/s)": ({}, {"lateral_sigma": 1.6})}
    alt = {k: {"reference": score_against_reference("smartloc-berlin", o, m),
               "withheld": withheld_criterion("smartloc-berlin", o, m)} for k, (o, m) in alts.items()}

    lines = ["# smartloc-berlin tuned by `mixnav tune` (issue 35)", "",
             f"Produced by `benchmarks/tune_smartloc.py` ({platform.machine()}, Python {platform.python_version()}); "
             f"numbers in the `.json`. The tuning: {tune_s:.0f} s wall on {a.workers} worker{'s' * (a.workers != 1)} "
             "(other jobs on the "
             f"machine), {len(r.evaluations)} evaluations, {r.runs} pipeline runs, budget {a.budget}.", "",
             "Tuned from `benchmarks/configs/smartloc-berlin-untuned.toml` (the shipped file without its alignment "
             "window, C/N0 band edges and start sigmas: the schema's defaults, window 20 s, no bands, 10 m, "
             "0.1 rad). The tuner never reads the reference (tests/test_tuning_vehicle.py); the RMSE below is "
             "computed afterwards, here.", "",
             "## Chosen", "", "| key | value | spread |", "|---|---|---|"]
    for k, c in r.chosen.items():
        lines.append(f"| `{k}` | {c['value']} | {c.get('spread') or '-'} |")
    lines += ["", f"Criterion (minus the innovation log-likelihood per row): as given {r.given['criterion']:.4f}, "
              f"tuned {r.tuned['criterion']:.4f}.", "",
              f"With `--criterion withheld-satellites` ({len(r2.evaluations)} evaluations): the deviation "
              f"{r2.given['criterion']:.3f} -> {r2.tuned['criterion']:.3f} m (se {r2.given['criterion_se']:.3f}); chose "
              + "; ".join(f"`{k}` {c['value']}" for k, c in r2.chosen.items()) + ".", "",
              "## Against the reference: the epoch mixture, causal, 2-D RMSE [m] per start of the start sweep", "",
              "Own: each run from its own filter start (start + its window). Same epochs: from start + 40 s "
              "(the longest window searched), the same epochs for every file.", "",
              "| file | own, per start 0 ... 150 s | own median / worst | same epochs median / worst |",
              "|---|---|---|---|"]
    for k, s in scores.items():
        lines.append(f"| {k} | {' '.join(f'{x:.2f}' for x in s['rmse_own_start_m'])} | "
                     f"{s['median_own_m']:.2f} / {s['worst_own_m']:.2f} | {s['median_same_m']:.2f} / "
                     f"{s['worst_same_m']:.2f} |")
    lines += ["", "Issue 35's bar: within 10 % of the shipped file's causal RMSE on the same span "
              f"(the issue quoted 6.4 m; today it is {scores['shipped']['rmse_own_start_m'][0]:.2f} m from start 0, "
              f"scored from its own filter start: at most "
              f"{1.1 * scores['shipped']['rmse_own_start_m'][0]:.2f} m); tuned by the default criterion, from start 0: "
              f"{scores['tuned (likelihood, the default)']['rmse_own_start_m'][0]:.2f} m.", "",
              "## The tuner's own criterion at the shipped point", "",
              "Minus the epoch mixture's innovation log-likelihood per pseudorange row, over the rows from each "
              "start + 40 s of the 6 starts (the rows every candidate shares), lower is better: the likelihood "
              "tuner's criterion (`VehicleEvaluator`). A search that ends above the shipped file has missed it.", "",
              "| file | criterion | rows | minus the log-likelihood, sum | RMSE own median / worst [m] "
              "(afterwards) |", "|---|---|---|---|---|"]
    rm = {**scores, **own_rmse}
    for k, v in own.items():
        lines.append(f"| {k} | {v['criterion']:.4f} | {v['rows_scored']} | {v['criterion'] * v['rows_scored']:.0f} | "
                     f"{rm[k]['median_own_m']:.2f} / {rm[k]['worst_own_m']:.2f} |")
    lines += ["",
              "## Which criterion sees what the reference sees", "",
              "| setting | prequential innovation log-likelihood (all satellites, 6 starts; higher is 'better') | "
              "withheld satellites' deviation [m] (lower is better) | RMSE own median / worst [m] |",
              "|---|---|---|---|"]
    for k, v in alt.items():
        lines.append(f"| {k} | {v['reference']['prequential_log_likelihood']:.0f} | "
                     f"{v['withheld']['criterion']:.3f} (se {v['withheld']['criterion_se']:.3f}) | "
                     f"{v['reference']['median_own_m']:.2f} / {v['reference']['worst_own_m']:.2f} |")
    lines.append("")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "tune_smartloc.json").write_text(json.dumps(
        {"tune_wall_s": tune_s, "budget": a.budget, "workers": a.workers, "evaluations": len(r.evaluations),
         "runs": r.runs,
         # the search's path: each candidate's move and its criterion, in the order evaluated
         "search_path": [{"changed": e["changed"], "criterion": e["score"]["criterion"]} for e in r.evaluations],
         "chosen": {k: {kk: vv for kk, vv in c.items() if kk != "curve"} for k, c in r.chosen.items()},
         "withheld_satellites": {"chosen": {k: c["value"] for k, c in r2.chosen.items()}, "given": r2.given,
                                 "tuned": r2.tuned, "runs": r2.runs},
         "criterion_given": r.given, "criterion_tuned": r.tuned, "against_reference": scores,
         "criteria_compared": alt, "own_criterion": own, "before_fix": {"values": BEFORE_FIX, **own_rmse}},
        indent=1, default=float))
    (out / "tune_smartloc.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
