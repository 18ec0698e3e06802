"""Issue 35, the search: the shipped coordinate search against optuna's TPE and scipy's Powell.

    python benchmarks/tune_search.py [--budget 80] [--workers 2] [--searchers coordinate,tpe,powell]

What it measures. :func:`mixnav.tune` minimises its criterion (the mean negative log predictive
density of GNSS fixes withheld in cross-validation windows, :mod:`mixnav.experiment.tuning.criterion`)
with its own two-pass coordinate search (:mod:`mixnav.experiment.tuning.search`). Here three
searchers get the SAME criterion, the SAME start and the SAME budget:

- dataset ``benchmarks/configs/drive-0708-untuned.toml`` tuned on the first half, span 60-295 s
  (as benchmarks/tune_drive0708.py), windows of 30 s, 6 folds, 80 evaluations, 2 workers;
- the start: what :func:`mixnav.tune` does before its search, reproduced with the library's own
  functions (probe run, cross-validation windows, the data stage: Allan white noise, stillness
  thresholds, smoothed bias walks; the file as given and the data stage's file both scored, the
  better one kept). Those two evaluations count against every searcher's budget, as in ``tune``;
- the coordinates: the parameters of :func:`~mixnav.experiment.tuning.parameters.ins_parameters`
  that apply, each moved from the start as ``log10`` of a scale factor in [-2, 2] (``"log"``
  keys: the whole vector scaled, or the element ``index``; a key whose start is 0 -- the fixes'
  sigma floor -- becomes ``lower x 10^x`` for x > 0, as the coordinate search's
  :func:`~mixnav.experiment.tuning.parameters.moved` does) or as an SI offset within three times
  the coarse grid's range (``"shift"`` keys), clipped to the parameter's bounds. The values are
  written into the file by :func:`~mixnav.experiment.tuning.parameters.set_value` (4 significant
  digits): a candidate is a dataset file's text, and a text already scored costs nothing again;
- every candidate scored by the library's ``Scorer`` (mixnav.experiment.tuning.scoring) (journal, budget: each distinct candidate
  counts once) on local worker processes.

The searchers:

- ``coordinate``: the shipped :func:`~mixnav.experiment.tuning.search.coordinate_search` (a key's
  grid moves scored side by side, 2-4 candidates a batch);
- ``tpe``: optuna's TPE sampler (``seed=0``, ``constant_liar=True``), the start enqueued as the
  first trial, ``study.ask()`` in batches of ``--workers`` candidates scored together;
  ``tpe-sN`` the same with seed N (the seed's spread: TPE draws at random);
- ``powell``: ``scipy.optimize.minimize(method="Powell")`` from the start, on the coordinates
  rescaled to [-1, 1] (bounded); sequential by nature, so one candidate at a time (one core);
- ``nelder-mead`` (optional, ``--searchers``): scipy's bounded Nelder-Mead, an initial simplex of
  a quarter of each coordinate's range.

For each: the best criterion against the number of evaluations (a curve), the final criterion,
the wall time, the filter runs; then the best file of each (its reference sections put back) is
scored by the outage sweep on the OTHER half, 295-530 s (``mixnav.outage_sweep(path, "30 s",
"10 s", ("295 s", "530 s"))``), against the reference: the ``aided`` method's median, p90 and
worst of the windows' horizontal maxima and the share of windows whose mean position NEES is
within the chi-square(3) 99 % point. The start file is scored the same way as a baseline.

Writes benchmarks/results/tune_search.md and .json (a "## Reading" section written below the
tables by hand is kept on a rerun). Two cores: 1-2 minutes a searcher, 10-15 s an outage sweep.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import tomlkit

ROOT = Path(__file__).resolve().parents[1]
UNTUNED = ROOT / "benchmarks" / "configs" / "drive-0708-untuned.toml"
TUNE_SPAN = ("60 s", "295 s")
EVAL_SPAN = ("295 s", "530 s")
LABELS = {"criterion_other_half": "the criterion on the other half", "median_m": "the outage sweep's median",
          "p90_m": "its p90", "worst_m": "its worst", "nees_out_of_band_share": "its share of NEES out of band"}
SEARCHERS = ("coordinate", "tpe", "powell", "nelder-mead")


# ---------------------------------------------------------------- the start, as tune() makes it

def prepare(window: float = 30.0, folds: int = 6) -> dict:
    """The setup of the criterion and the two texts :func:`mixnav.tune` scores before its search
    (the file as given, the data stage's file): the lines of ``tune()`` up to the search,
    calling the library's functions."""
    from mixnav.config.loader import load_dataset_text, resolve
    from mixnav.experiment.sweep import _dataset_ref
    from mixnav.experiment.tuning import _seconds, _target_method
    from mixnav.experiment.tuning.criterion import Evaluator, cv_windows, without_reference
    from mixnav.experiment.tuning.data_stage import bias_walks, imu_noise, stillness_thresholds
    from mixnav.experiment.tuning.parameters import get_value, ins_parameters, set_value

    text, source = resolve(_dataset_ref(str(UNTUNED)), "datasets", "dataset")
    stripped = without_reference(text)
    ds, _, _ = load_dataset_text(stripped, source)
    target = _target_method(ds, None)
    probe = Evaluator(stripped, source, None, target, [[]], (0.0, math.inf))
    pds = probe.dataset(stripped)
    po = probe.run(pds, [])
    t_first, t_last = float(po.init.time) + 10.0, float(po.all_fixes.time[-1])
    t_first = max(_seconds(TUNE_SPAN[0], "span"), t_first)
    t_last = min(_seconds(TUNE_SPAN[1], "span"), t_last)
    own = [tuple(map(float, x)) for x in ds.gnss.withhold]
    windows = [f for f in cv_windows(t_first, t_last, window, folds, avoid=own, step=window / 2.0) if f]
    setup = ("mixnav.experiment.tuning.criterion:Evaluator", stripped, source, None, target, windows,
             (t_first, t_last))

    doc = tomlkit.parse(stripped)
    start_doc = tomlkit.parse(tomlkit.dumps(doc))
    params = {p.name: p for p in ins_parameters()}
    noise = imu_noise(po.imu, po.all_fixes, (t_first, t_last))
    for name, attr in (("imu.errors.arw", "arw"), ("imu.errors.vrw", "vrw")):
        if noise is not None and get_value(doc, params[name]) is not None:
            set_value(start_doc, params[name], getattr(noise, attr))
    if "aiding" in doc and "zupt" in doc["aiding"]:
        for k, (val, _how) in stillness_thresholds(po.imu, po.all_fixes, (t_first, t_last)).items():
            if val is not None:
                start_doc["aiding"]["zupt"][k] = f"{val:.4g} {'m/s^2' if k == 'accel_std' else 'rad/s'}"
    local = Evaluator(stripped, source, None, target, windows, (t_first, t_last))
    walks = bias_walks(local, tomlkit.dumps(start_doc), (t_first, t_last))
    if walks is not None:
        for n in ("imu.errors.gyro_bias_walk", "imu.errors.accel_bias_walk"):
            set_value(start_doc, params[n], walks[n.rsplit(".", 1)[1]])
    # the same criterion on the other half (for the ranking check only: never searched on)
    e0, e1 = _seconds(EVAL_SPAN[0], "span"), min(_seconds(EVAL_SPAN[1], "span"), float(po.all_fixes.time[-1]))
    other = [f for f in cv_windows(e0, e1, window, folds, avoid=own, step=window / 2.0) if f]
    held_out = Evaluator(stripped, source, None, target, other, (e0, e1))
    return {"text": text, "source": source, "ds": ds, "setup": setup, "folder": str(probe.folder),
            "held_out": held_out,
            "given_text": tomlkit.dumps(doc), "start_text": tomlkit.dumps(start_doc),
            "span": (t_first, t_last), "windows": windows}


# ---------------------------------------------------------------- the scorer, recording a curve

def recording_scorer(prep: dict, journal: Path, workers: int, budget: int):
    """The library's ``Scorer`` (mixnav.experiment.tuning.scoring) (fresh journal) that records, per candidate counted against the
    budget, its criterion in the order counted."""
    from mixnav.experiment.tuning.scoring import Scorer

    class Recording(Scorer):
        def __init__(self, *a):
            super().__init__(*a)
            self.order: list[tuple[str, float]] = []     # (key, nlpd) per counted candidate
            self.texts: dict[str, str] = {}

        def score(self, texts):
            before = set(self.seen)
            out = super().score(texts)
            for t, sc in zip(texts, out):
                k = self.key(t)
                if k not in before and k in self.seen and k not in self.texts:
                    self.texts[k] = t
                    nl = sc["nlpd"] if sc is not None and sc["nlpd"] is not None else math.inf
                    self.order.append((k, float(nl)))
            return out

        def best(self) -> tuple[str, float]:
            k, nl = min(self.order, key=lambda r: r[1])
            return self.texts[k], nl

        def curve(self) -> list[float]:
            return [float(x) for x in np.minimum.accumulate([nl for _, nl in self.order])]

    if journal.exists():
        journal.unlink()
    return Recording(prep["setup"], journal, workers, None, False, budget, len(prep["setup"][5]))


# ---------------------------------------------------------------- the common coordinates

class Space:
    """The searched parameters' coordinates about the start document: ``log10`` of a factor in
    [-2, 2] ("log"), an SI offset within 3x the coarse grid's range ("shift")."""

    def __init__(self, start_doc, params):
        from mixnav.experiment.tuning.parameters import get_value
        self.doc_text, self.params = tomlkit.dumps(start_doc), params
        self.base = {p.path: get_value(start_doc, p) for p in params}
        self.lo = np.array([-2.0 if p.kind == "log" else -3.0 * max(map(abs, p.coarse)) for p in params])
        self.hi = -self.lo

    def values(self, x) -> dict:
        """Per TOML path the whole value (SI) at coordinates ``x``."""
        vals = {k: np.array(v, float) for k, v in self.base.items()}
        for p, xi in zip(self.params, x):
            v, b = vals[p.path], self.base[p.path]
            sel = slice(None) if p.index is None else p.index
            if p.kind == "log":
                f = 10.0 ** float(xi)
                v[sel] = np.where(b[sel] > 0, b[sel] * f, p.lower * f if xi > 0 else b[sel])
            else:
                v[sel] = b[sel] + float(xi)
            v[sel] = np.clip(v[sel], p.lower, p.upper)
        return vals

    def text(self, x) -> str:
        from mixnav.experiment.tuning.parameters import set_value
        doc = tomlkit.parse(self.doc_text)
        vals = self.values(x)
        for p in self.params:
            if p.path in vals:
                set_value(doc, p, vals.pop(p.path))
        return tomlkit.dumps(doc)

    def to_unit(self, x):
        return 2.0 * (np.asarray(x) - self.lo) / (self.hi - self.lo) - 1.0

    def from_unit(self, u):
        return self.lo + (np.asarray(u) + 1.0) * 0.5 * (self.hi - self.lo)


class _Spent(Exception):
    """The budget is spent: the scipy optimiser is stopped."""


# ---------------------------------------------------------------- the searchers

def run_coordinate(scorer, start_doc, cur, params, workers):
    from mixnav.experiment.tuning.search import coordinate_search
    coordinate_search(start_doc, cur, params, scorer, [])


def run_tpe(scorer, start_doc, cur, params, workers, seed=0):
    import optuna
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sp = Space(start_doc, params)
    names = [p.name for p in params]
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=seed, constant_liar=True))
    study.enqueue_trial({n: 0.0 for n in names})
    worst = [cur["nlpd"]]
    for _ in range(20 * scorer.budget):     # duplicates (same text) cost nothing: a guard only
        if scorer.left() <= 0:
            break
        trials = [study.ask() for _ in range(max(1, workers))]
        xs = [[t.suggest_float(n, lo, hi) for n, lo, hi in zip(names, sp.lo, sp.hi)] for t in trials]
        texts = [sp.text(x) for x in xs]
        scores = scorer.score(texts)
        for t, sc in zip(trials, scores):
            if sc is None:                      # beyond the budget
                study.tell(t, state=optuna.trial.TrialState.FAIL)
                continue
            nl = sc["nlpd"]
            if math.isfinite(nl):
                worst[0] = max(worst[0], nl)
            study.tell(t, nl if math.isfinite(nl) else 10.0 * abs(worst[0]))


def run_scipy(scorer, start_doc, cur, params, workers, method="Powell"):
    from scipy.optimize import minimize
    sp = Space(start_doc, params)
    n = len(params)
    worst = [cur["nlpd"]]
    calls = [0]

    def f(u):
        calls[0] += 1
        if scorer.left() <= 0 or calls[0] > 50 * scorer.budget:
            # a text already scored costs nothing: let a cached point through, else stop
            text = sp.text(sp.from_unit(np.clip(u, -1, 1)))
            if scorer.key(text) not in scorer.seen or calls[0] > 50 * scorer.budget:
                raise _Spent
        sc = scorer.score([sp.text(sp.from_unit(np.clip(u, -1, 1)))])[0]
        if sc is None:
            raise _Spent
        nl = sc["nlpd"]
        if math.isfinite(nl):
            worst[0] = max(worst[0], nl)
            return nl
        return 10.0 * abs(worst[0])

    u0 = sp.to_unit(np.zeros(n))
    opts = {"maxfev": 50 * scorer.budget, "xtol": 1e-3, "ftol": 1e-4}
    kw = {}
    if method == "Nelder-Mead":
        simplex = np.vstack([u0] + [u0 + 0.25 * np.eye(n)[i] for i in range(n)])
        opts = {"maxfev": 50 * scorer.budget, "xatol": 1e-3, "fatol": 1e-4, "initial_simplex": simplex}
    try:
        minimize(f, u0, method=method, bounds=[(-1.0, 1.0)] * n, options=opts, **kw)
    except _Spent:
        pass


RUNNERS = {"coordinate": run_coordinate, "tpe": run_tpe, "powell": run_scipy,
           "nelder-mead": lambda *a: run_scipy(*a, method="Nelder-Mead")}


# ---------------------------------------------------------------- scoring on the other half

def with_reference(prep: dict, text: str, path: Path) -> str:
    """The candidate text with the original file's reference sections and an absolute data folder."""
    from mixnav.experiment.tuning.criterion import REFERENCE_SECTIONS
    orig = tomlkit.parse(prep["text"])
    doc = tomlkit.parse(text)
    for k in REFERENCE_SECTIONS:
        if k in orig:
            doc[k] = orig[k]
    doc["dataset"]["data_dir"] = prep["folder"]
    path.write_text(tomlkit.dumps(doc))
    return str(path)


def summary(rows, method="aided") -> dict:
    from mixnav.experiment.sweep import NEES_POS_99
    g = rows[rows.method == method]
    h, ne = g.horizontal_max_m.to_numpy(float), g.nees_pos_mean.to_numpy(float)
    return {"windows": int(len(g)), "median_m": float(np.median(h)), "p90_m": float(np.percentile(h, 90)),
            "worst_m": float(h.max()), "nees_in_band_share": float(np.mean(ne <= NEES_POS_99))}


def chosen_values(text: str, params) -> dict:
    from mixnav.experiment.tuning import _value_text
    from mixnav.experiment.tuning.parameters import get_value
    doc = tomlkit.parse(text)
    return {p.name: _value_text(p, get_value(doc, p)) for p in params}


# ---------------------------------------------------------------- main

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=80)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--searchers", default="coordinate,tpe,powell",
                    help=f"comma-separated, of {', '.join(SEARCHERS)}; tpe-sN: TPE with seed N (tpe: seed 0)")
    ap.add_argument("--work", default="/tmp/tune_search", help="folder for journals and best files")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "tune_search"))
    a = ap.parse_args(argv)
    names = [s.strip() for s in a.searchers.split(",") if s.strip()]
    bad = [s for s in names if s not in SEARCHERS and not (s.startswith("tpe-s") and s[5:].isdigit())]
    if bad:
        ap.error(f"unknown searcher(s) {bad}")
    import mixnav
    from mixnav.experiment.tuning import _applies
    from mixnav.experiment.tuning.parameters import ins_parameters

    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    prep = prepare()
    prep_s = time.perf_counter() - t0
    print(f"start prepared in {prep_s:.1f} s: span {prep['span'][0]:.1f}-{prep['span'][1]:.1f} s, "
          f"{sum(map(len, prep['windows']))} windows in {len(prep['windows'])} folds", flush=True)

    res = {"dataset": str(UNTUNED.relative_to(ROOT)), "tune_span": TUNE_SPAN, "eval_span": EVAL_SPAN,
           "window_s": 30.0, "folds": len(prep["windows"]), "budget": a.budget, "workers": a.workers,
           "start_prepare_s": prep_s, "searchers": {}}
    params = None
    start_text = None
    for name in names:
        scorer = recording_scorer(prep, work / f"{name}.jsonl", a.workers, a.budget)
        t1 = time.perf_counter()
        given, started = scorer.score([prep["given_text"], prep["start_text"]])
        if started["nlpd"] <= given["nlpd"]:
            start_doc, cur = tomlkit.parse(prep["start_text"]), started
        else:
            start_doc, cur = tomlkit.parse(prep["given_text"]), given
        start_text = tomlkit.dumps(start_doc)
        params = [p for p in ins_parameters() if _applies(start_doc, p, prep["ds"])]
        if name.startswith("tpe-s"):
            run_tpe(scorer, start_doc, cur, params, a.workers, seed=int(name[5:]))
        else:
            RUNNERS[name](scorer, start_doc, cur, params, a.workers)
        wall = time.perf_counter() - t1
        best_text, best = scorer.best()
        curve = scorer.curve()
        res["searchers"][name] = {"criterion_given": given["nlpd"], "criterion_start": cur["nlpd"],
                                  "criterion_best": best, "evaluations": len(scorer.order),
                                  "filter_runs": scorer.runs, "wall_s": wall, "curve": curve,
                                  "chosen": chosen_values(best_text, params)}
        print(f"{name}: {len(scorer.order)} evaluations, {scorer.runs} filter runs, {wall:.1f} s, criterion "
              f"{cur['nlpd']:.3f} -> {best:.3f}", flush=True)
        path = with_reference(prep, best_text, work / f"best-{name}.toml")
        t2 = time.perf_counter()
        s = summary(mixnav.outage_sweep(path, "30 s", "10 s", EVAL_SPAN, workers=a.workers))
        res["searchers"][name]["outage_sweep"] = s
        res["searchers"][name]["criterion_other_half"] = prep["held_out"].evaluate(best_text).nlpd
        print(f"  on {EVAL_SPAN}: median {s['median_m']:.2f}  p90 {s['p90_m']:.2f}  worst {s['worst_m']:.2f} m  "
              f"NEES in band {100 * s['nees_in_band_share']:.0f} % ({time.perf_counter() - t2:.0f} s)", flush=True)
        Path(a.out + ".json").write_text(json.dumps(res, indent=1) + "\n")
    if start_text is not None:
        path = with_reference(prep, start_text, work / "start.toml")
        res["start_outage_sweep"] = summary(mixnav.outage_sweep(path, "30 s", "10 s", EVAL_SPAN, workers=a.workers))
        res["start_criterion_other_half"] = prep["held_out"].evaluate(start_text).nlpd
        res["searched_parameters"] = [p.name for p in params]
    if len(res["searchers"]) >= 3:
        from scipy.stats import spearmanr
        r = list(res["searchers"].values())
        crit = [x["criterion_best"] for x in r]
        res["spearman_vs_criterion"] = {
            k: float(spearmanr(crit, v).statistic) for k, v in (
                ("criterion_other_half", [x["criterion_other_half"] for x in r]),
                ("median_m", [x["outage_sweep"]["median_m"] for x in r]),
                ("p90_m", [x["outage_sweep"]["p90_m"] for x in r]),
                ("worst_m", [x["outage_sweep"]["worst_m"] for x in r]),
                ("nees_out_of_band_share", [1 - x["outage_sweep"]["nees_in_band_share"] for x in r]))}
    Path(a.out + ".json").write_text(json.dumps(res, indent=1) + "\n")
    write_md(res, a.out + ".md", " ".join(f"--{k} {v}" for k, v in (("budget", a.budget), ("workers", a.workers),
                                                                    ("searchers", ",".join(names)))))


def write_md(res: dict, out: str, args: str) -> None:
    marks = [n for n in (10, 20, 40, 60, 80) if n <= res["budget"]]
    lines = ["# The search: coordinate search vs optuna TPE vs scipy (issue 35)", "",
             f"`python benchmarks/tune_search.py {args}`; `{res['dataset']}` tuned on "
             f"{res['tune_span'][0]}-{res['tune_span'][1]} (windows {res['window_s']:g} s, {res['folds']} folds), "
             f"the same criterion (mean NLPD of the withheld fixes, lower is better), the same start (the data "
             f"stage's file, as `mixnav tune` makes it) and the same budget of {res['budget']} evaluations "
             "(the file as given and the start included), "
             f"{res['workers']} workers. The best file of each scored by the outage sweep on "
             f"{res['eval_span'][0]}-{res['eval_span'][1]} (30 s windows every 10 s) against the reference, "
             "causal `aided`.", "",
             "| " + " | ".join(["searcher", "criterion start -> best"] + [f"best @{n}" for n in marks] +
                               ["evaluations", "filter runs", "wall [s]", "criterion, other half", "median [m]",
                                "p90 [m]", "worst [m]", "NEES in band"]) + " |",
             "|---|---|" + "---|" * len(marks) + "---|---|---|---|---|---|---|---|"]
    for name, r in res["searchers"].items():
        c = r["curve"]
        pts = "".join(f"{c[min(n, len(c)) - 1]:.3f} | " for n in marks)
        s = r["outage_sweep"]
        lines.append(f"| {name} | {r['criterion_start']:.3f} -> {r['criterion_best']:.3f} | {pts}"
                     f"{r['evaluations']} | {r['filter_runs']} | {r['wall_s']:.0f} | {r['criterion_other_half']:.3f} | "
                     f"{s['median_m']:.2f} | "
                     f"{s['p90_m']:.2f} | {s['worst_m']:.2f} | {100 * s['nees_in_band_share']:.0f} % |")
    if "start_outage_sweep" in res:
        s = res["start_outage_sweep"]
        lines.append(f"| (the start) | {next(iter(res['searchers'].values()))['criterion_start']:.3f} | "
                     + "".join(" |" for _ in marks) + f" | | | {res['start_criterion_other_half']:.3f} | "
                     f"{s['median_m']:.2f} | {s['p90_m']:.2f} | "
                     f"{s['worst_m']:.2f} | {100 * s['nees_in_band_share']:.0f} % |")
    if "spearman_vs_criterion" in res:
        lines += ["", "Spearman rank correlation, over the searchers' best files, of the criterion reached (first "
                  "half) with: " + "; ".join(f"{LABELS.get(k, k)} {v:+.2f}"
                                             for k, v in res["spearman_vs_criterion"].items()) + "."]
    lines += ["", "Best values found:", ""]
    for name, r in res["searchers"].items():
        lines.append(f"- {name}: " + "; ".join(f"`{k}` = {v}" for k, v in r["chosen"].items()))
    # a hand-written reading below the tables survives a rerun
    old = Path(out).read_text() if Path(out).exists() else ""
    keep = old[old.index("\n## Reading"):] if "\n## Reading" in old else ""
    Path(out).write_text("\n".join(lines) + "\n" + keep)


if __name__ == "__main__":
    main()
