"""``mixnav tune``: a recording's filter tuned from its own data, without any reference.

:func:`tune` reads the dataset file, takes ``[reference]`` and ``[reference_point]`` out of it
before anything is loaded, and then, for an IMU + GNSS-fixes dataset (``ins-gnss`` with
``[gnss]``):

1. **from the data alone** (:mod:`.data_stage`): the IMU's white noise per axis from the
   still segments (overlapping Allan deviation at 1 s, :mod:`.allan`) and the ZUPT/ZARU
   thresholds from the stillness statistics;
2. **by the criterion** (:mod:`.criterion`): cross-validation on the recording's own GNSS
   (withheld windows dealt to folds, the withheld fixes as truth, the mean negative log
   predictive density minimised) with the GNSS innovation log-likelihood reported beside it;
   a coordinate search (:mod:`.search`) over the noise scales, bias walks, NHC sigmas, the
   fixes' sigma floor, the IMU time offset and the GNSS velocity delay
   (:func:`.parameters.ins_parameters`), each candidate's folds run in parallel on local
   processes or a Dask cluster;
3. writes ``tuned.toml`` (the dataset file with each tuned value and a comment saying how it
   was found and its spread), ``tune.json`` (every evaluation, the chosen values, the
   criteria of the file as given and as tuned) and ``report.md`` with ``tune.png``.

An ``odometry-gnss`` dataset (wheel odometry + pseudoranges) is tuned by :mod:`.vehicle`
instead: the whole causal pipeline from several starts, scored by the innovation
log-likelihood (or withheld satellites); a ``gnss-raw`` dataset (a phone log, RINEX, u-blox)
by :mod:`.raw_gnss`: the SPP and the constant-velocity filter from several starts, scored by
the innovation log-likelihood.

Deterministic (no random draw: ``seed`` is recorded only), and resumable: every evaluation
is appended to ``tune_journal.jsonl`` in the output folder as it finishes, keyed by the
candidate file's hash, and a rerun into the same folder (``resume=True``) takes them from
there. docs/tuning.md says what is tuned, how, and what is not.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import tomlkit

from ...errors import ArgumentError, ConfigError
from .adapt import Recording, adapted
from .criterion import Evaluator, cv_windows, without_reference
from .parameters import Parameter, get_value, ins_parameters, set_value
from .scoring import Scorer
from .search import MIN_GAIN

__all__ = ["tune", "TuneResult", "tunable_keys", "default_budget"]

#: the evaluations an IMU + GNSS-fixes tuning may spend unless told: on drive-0708's halves the
#: search spends about 145 with its second coarse pass (search's module docstring), 95 without;
#: the whole drive took 63-65 s on two cores here (benchmarks/results/tune_speed.md; a machine
#: half as fast would pass the 2-minute bound). A smaller budget drops the second coarse pass
#: first, then the fine pass's last keys
DEFAULT_BUDGET = 160
#: the same for odometry + pseudorange and raw-GNSS datasets: their searches end by themselves
#: within it (50-70 evaluations on the recordings in benchmarks/results/tune_raw_gnss.md and
#: tune_smartloc.md) and have no second coarse pass; the budget their results were measured at
PSEUDORANGE_DEFAULT_BUDGET = 96


def default_budget(kind: str) -> int:
    """The budget :func:`tune` spends unless told, for a dataset of ``kind`` (``[dataset] kind``)."""
    return PSEUDORANGE_DEFAULT_BUDGET if kind in ("odometry-gnss", "gnss-raw") else DEFAULT_BUDGET

#: what a tune folder holds
TUNE_FILES = ("tuned.toml", "tune.json", "report.md", "tune.png", "tune_journal.jsonl")


def tunable_keys() -> list[str]:
    """The names ``--fix`` accepts (IMU + GNSS-fixes datasets), plus the data-stage keys."""
    # an element with a ``length`` (the vertical gyro's ARW) is fixed with its whole key
    return [p.name for p in ins_parameters() if p.length is None] + ["aiding.zupt.accel_std", "aiding.zupt.gyro_rate",
                                                 "installation.antenna_position", "aiding.vehicle_mounting"]


@dataclass
class TuneResult:
    """What :func:`tune` found (also written to ``out``)."""

    tuned_text: str
    chosen: dict                      # key -> {"value": text, "how": str, "spread": text or None}
    given: dict                       # Score.as_dict() of the file as given
    tuned: dict                       # Score.as_dict() of the tuned file
    evaluations: list = field(default_factory=list)   # every candidate: {"changed", "score"}
    not_tuned: dict = field(default_factory=dict)     # key -> why it kept its value
    runs: int = 0                     # filter runs made (evaluations x folds; journal hits excluded)
    out: Path | None = None
    kept_as_given: str | None = None  # why tuned.toml is the file as given (None: it was tuned)
    found: dict = field(default_factory=dict)   # kept as given: what the search's best had moved,
    #                                             key -> {"value", "how"} (not written)
    curves: dict = field(default_factory=dict)  # per searched key, its evaluated points (the report's figure)


def _seconds(value, argument: str) -> float:
    from ..sweep import _seconds as seconds
    return seconds(value, argument)


def _value_text(p: Parameter, v) -> str:
    v = np.atleast_1d(v)
    parts = [f"{x / p.scale:.4g}" for x in v]
    return (parts[0] if len(parts) == 1 else "[" + ", ".join(parts) + "]") + f" {p.unit}"


def _target_method(ds, method: str | None) -> str:
    names = [m.name for m in ds.methods]
    if method is not None:
        if method not in names:
            raise ArgumentError(f"no method '{method}' in the dataset (it has {', '.join(names)})",
                                argument="method")
        return method
    # the most-aided method: the aiding sigmas are tuned on it, the IMU noise serves all
    return max(ds.methods, key=lambda m: len(getattr(m, "aiding", None) or ())).name


def tune(dataset, out, *, budget: int | None = None, workers: int | None = None, scheduler: str | None = None,
         data: str | None = None, fix=(), span=None, window="30 s", folds: int = 6, method: str | None = None,
         criterion: str | None = None, resume: bool = False, overwrite: bool = False, progress: bool = False, seed: int = 0) -> TuneResult:
    """Tune a dataset file from its own data (never its reference) and write ``out``.

    Parameters
    ----------
    dataset : str or Path
        A shipped dataset name or a dataset file; ``ins-gnss`` with ``[gnss]`` fixes,
        ``odometry-gnss`` (:mod:`.vehicle`) or ``gnss-raw`` (:mod:`.raw_gnss`).
    out : str or Path
        Output folder: ``tuned.toml``, ``tune.json``, ``report.md``, ``tune.png``,
        ``tune_journal.jsonl``.
    budget : int
        Largest number of candidate settings evaluated by the criterion (each is ``folds``
        filter runs; odometry + pseudoranges: six pipeline runs); at least 1. Default
        (None): :func:`default_budget`, 160 for IMU + GNSS fixes, 96 for odometry +
        pseudoranges and raw GNSS.
    workers : int, optional
        Local worker processes (default: all cores); ``scheduler``: a Dask scheduler
        address instead.
    data : str, optional
        Another copy of the data folder.
    fix : iterable of str
        Keys kept as the file gives them (:func:`tunable_keys`).
    span : (start, end), optional
        The part of the recording tuned on, seconds since the first IMU sample (numbers or
        text with a unit); default: from 10 s after the filter starts to the last fix. Only
        data inside it enters the criterion and the still segments.
    window : str or float
        Length of the cross-validation windows (default 30 s), one starting every half window;
        ``folds`` runs deal them out (at least 4, so that a fold's windows do not overlap and
        leave a window of GNSS between them: with the default 6, 90 s apart).
    method : str, optional
        The method tuned (default: the one with most aiding; odometry + pseudoranges: the first
        epoch mixture).
    criterion : str, optional
        Odometry + pseudorange datasets: ``"likelihood"`` (default) or ``"withheld-satellites"``
        (:mod:`.vehicle`); IMU + GNSS-fixes datasets have one criterion (None).
    resume : bool
        Reuse the evaluations ``out/tune_journal.jsonl`` holds (same file, data and span).
    overwrite : bool
        Write into a folder that has outputs (the journal is kept only with ``resume``).
    progress : bool
        A progress bar on stderr.
    seed : int
        Recorded only: the tuning draws nothing at random.
    """
    from ...config.loader import load_dataset_text, resolve
    from ...io.outdir import check_out_dir, clear_folder, write_marker
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, (int, np.integer)) or budget < 1):
        raise ArgumentError(f"must be a whole number of evaluations >= 1, got {budget!r}", argument="budget")
    if isinstance(folds, bool) or not isinstance(folds, (int, np.integer)) or folds < 4:
        raise ArgumentError(f"must be a whole number >= 4 (windows start every half window; a fold's must "
                            f"not overlap), got {folds!r}", argument="folds")
    fix = list(fix or ())
    w = _seconds(window, "window")
    if w <= 0:
        raise ArgumentError(f"must be positive, got {window!r}", argument="window")

    from ..sweep import _dataset_ref
    text, source = resolve(_dataset_ref(dataset), "datasets", "dataset")
    stripped = without_reference(text)
    ds, _, _ = load_dataset_text(stripped, source)
    vehicle = ds.dataset.kind == "odometry-gnss"
    raw = ds.dataset.kind == "gnss-raw"
    budget = default_budget(ds.dataset.kind) if budget is None else int(budget)
    if not (vehicle or raw) and (getattr(ds, "gnss", None) is None or getattr(ds, "imu", None) is None):
        raise ConfigError("mixnav tune needs an IMU + GNSS-fixes dataset ([imu] and [gnss]), an odometry + "
                          "pseudorange one or a raw-GNSS one; tuning an IMU with raw GNSS (RINEX) is not built yet "
                          "(docs/tuning.md)", file=source, key="dataset.kind")
    if not vehicle and criterion is not None and not (raw and criterion == "likelihood"):
        raise ArgumentError("an IMU + GNSS-fixes dataset is tuned by cross-validation only, a raw-GNSS one by the "
                            "innovation likelihood only; --criterion chooses for odometry + pseudorange datasets",
                            argument="criterion")
    if not (vehicle or raw):
        unknown = [k for k in fix if k not in tunable_keys()]
        if unknown:
            raise ArgumentError(f"unknown key(s) {', '.join(unknown)}; tunable: {', '.join(tunable_keys())}",
                                argument="fix")
        target = _target_method(ds, method)
    # the folder is built in place (resumable, like `experiment`): marked incomplete until the end
    from ..data_folder import find_data_dir
    protect = [Path(source)] if Path(source).exists() else []
    data_folder = find_data_dir(ds, data, source)
    protect.append(data_folder)
    out, state = check_out_dir(out, "tune", overwrite=overwrite, protect=protect, resume=resume)
    if state == "clear" or (state == "same" and not resume):
        clear_folder(out)
    out.mkdir(parents=True, exist_ok=True)
    write_marker(out, "tune", False, TUNE_FILES)
    journal = out / "tune_journal.jsonl"
    if vehicle or raw:
        from .report import write_outputs
        header = {"dataset": str(dataset), "source": source, "budget": budget, "seed": seed, "fixed": fix}
        common = dict(text=text, stripped=stripped, source=source, ds=ds, out=out, data=data, data_folder=data_folder,
                      journal=journal, budget=budget, workers=workers, scheduler=scheduler, fix=fix, method=method,
                      progress=progress, header=header)
        if vehicle:
            from .vehicle import tune_vehicle
            result = tune_vehicle(**common, criterion=criterion or "likelihood")
        else:
            from .raw_gnss import tune_raw
            result = tune_raw(**common)
        write_outputs(out, result, header)
        write_marker(out, "tune", True, TUNE_FILES)
        return result

    # a probe run: where the filter starts and the fixes' span (no window withheld)
    probe = Evaluator(stripped, source, data, target, [[]], (0.0, math.inf))
    pds = probe.dataset(stripped)
    po = probe.run(pds, [])
    t_first, t_last = float(po.init.time) + 10.0, float(po.all_fixes.time[-1])
    if span is not None:
        a, b = _seconds(span[0], "span"), _seconds(span[1], "span")
        if not b > a:
            raise ArgumentError(f"end must be after start, got {span!r}", argument="span")
        t_first, t_last = max(a, t_first), min(b, t_last)
    own = [tuple(map(float, x)) for x in ds.gnss.withhold]
    windows = cv_windows(t_first, t_last, w, folds, avoid=own, step=w / 2.0)
    n_kept = sum(len(f) for f in windows)
    if n_kept < 2:   # folds left empty by a short span are dropped below
        n_all = sum(len(f) for f in cv_windows(t_first, t_last, w, folds, step=w / 2.0))
        why = (f"; the file's own withheld windows ({', '.join(f'{a:g}-{b:g} s' for a, b in own)}, and "
               f"{w:g} s of reconvergence after each) leave out {n_all - n_kept} of "
               f"{n_all}: they are the user's evaluation, never tuned on (remove gnss.withhold to tune there)"
               ) if own and n_all > n_kept else ""
        raise ArgumentError(f"the span {t_first:.1f}-{t_last:.1f} s holds {n_kept} "
                            f"cross-validation windows of {w:g} s; at least 2 are needed (a shorter "
                            f"window or a longer span){why}", argument="span")
    windows = [f for f in windows if f]
    setup = ("mixnav.experiment.tuning.criterion:Evaluator", stripped, source, None if data is None else str(data),
             target, windows, (t_first, t_last))
    scorer = Scorer(setup, journal, workers, scheduler, progress, budget, len(windows))

    searched_best = tolerance = kept_as_given = None
    found: dict = {}
    searched_curves: dict = {}
    try:
        doc = tomlkit.parse(stripped)
        chosen, not_tuned, evaluations = {}, {}, []

        # one evaluator on the span for the stages' single runs here (it keeps the data it read)
        local = Evaluator(stripped, source, data, target, windows, (t_first, t_last))
        # 1. the data stage: the search's start from the data alone
        start_doc = _data_stage(doc, po, (t_first, t_last), fix, chosen, not_tuned, local)

        # 2. the criterion: the file as given, the data stage's start, then the coordinate search
        given_text, start_text = tomlkit.dumps(doc), tomlkit.dumps(start_doc)
        given, started = scorer.score([given_text, start_text])
        if given is None or started is None:
            raise ArgumentError("a budget of at least 2 evaluations is needed to score the file as given "
                                "and the data's start", argument="budget")
        evaluations += [{"changed": "the file as given", "score": given},
                        {"changed": "the data stage (Allan noise, smoothed bias walks, stillness thresholds)", "score": started}]
        if _start_kept(started, given, chosen, not_tuned):
            cur_doc, cur = start_doc, started
        else:
            cur_doc, cur = tomlkit.parse(given_text), given
        from .search import (CONSERVATIVE_KEYS, CONSERVATIVE_STEPS, conservative_pass, conservative_tolerance,
                             coordinate_search)
        from .parameters import NHC_RATE
        # each key's search fitted to this recording where it needs to be (.adapt)
        recording = Recording(po, (t_first, t_last), fix, chosen, not_tuned)
        searched = [adapted(p, recording)
                    for p in ins_parameters() if not _fixed(p.name, fix) and _applies(cur_doc, p, pds)
                    and not chosen.get(p.name, {}).get("measured") and not _carries_fixed(p, fix)]
        # the NHC rate last of all, after the conservative pass (below): its step carries the
        # sigmas so that the information per second stays, so the other keys' optima hardly move
        # with it, and every evaluation after a faster rate would cost more
        searched_names = {q.name for q in searched}
        rate = [p for p in searched if p.name == NHC_RATE.name]
        searched = [p for p in searched if p.name != NHC_RATE.name]
        RATE_RESERVE = len(NHC_RATE.coarse) + 1 if rate and budget >= 40 else 0
        CONSERVATIVE_RESERVE = (len(CONSERVATIVE_KEYS) * len(CONSERVATIVE_STEPS) if budget >= 40 else 0) + RATE_RESERVE
        for p in ins_parameters():
            if _fixed(p.name, fix):
                not_tuned[p.name] = "fixed by the user (--fix)"
            elif _carries_fixed(p, fix):
                not_tuned[p.name] = "a key its step moves with it is fixed by the user (--fix)"
            elif p.name not in searched_names and not chosen.get(p.name, {}).get("measured"):
                not_tuned[p.name] = _why_not(cur_doc, p, pds)
        before, left_before = tomlkit.dumps(cur_doc), scorer.left()
        cur_doc, cur, curves = coordinate_search(cur_doc, cur, searched, scorer, evaluations, grids=("coarse",),
                                                 reserve=CONSERVATIVE_RESERVE)
        # the coarse grid again from where the first pass left every key (search's module docstring),
        # when the budget holds as many evaluations as the first pass spent besides the installation's,
        # the fine pass's and the reserves'. Without the data's moves (the turn-rate lag): they were
        # measured from the file's values, which the first pass has left
        first_cost = left_before - scorer.left()
        fine_cost = 1 + sum(len(p.fine) for p in searched)
        if tomlkit.dumps(cur_doc) != before and scorer.left() >= CONSERVATIVE_RESERVE + fine_cost + first_cost:
            cur_doc, cur, curves = coordinate_search(cur_doc, cur, [replace(p, data_steps=()) for p in searched],
                                                     scorer, evaluations, grids=("coarse",), curves=curves,
                                                     reserve=CONSERVATIVE_RESERVE + fine_cost)
        # the installation mixnav estimates as states, kept when the criterion agrees; between the
        # passes, after the time offset and velocity delay (a lever arm would otherwise absorb a
        # timing error along the track)
        cur_doc, cur = _installation_stage(cur_doc, cur, fix, scorer, evaluations, chosen, not_tuned, local)
        cur_doc, cur, curves = coordinate_search(cur_doc, cur, searched, scorer, evaluations, grids=("fine",),
                                                 curves=curves, reserve=CONSERVATIVE_RESERVE)
        # the most cautious setting the criterion cannot tell from the best (search.conservative_pass),
        # unless the file as given is one of those (_kept_as_given)
        n_windows = sum(len(f) for f in windows)
        searched_best = cur["nlpd"]
        tolerance = conservative_tolerance(cur, n_windows)
        kept_as_given = _kept_as_given(given, cur, tolerance, n_windows)
        if not kept_as_given:
            cur_doc, cur = conservative_pass(cur_doc, cur, searched, scorer, evaluations, tolerance, curves,
                                             reserve=RATE_RESERVE)
            cur_doc, cur, curves = coordinate_search(cur_doc, cur, rate, scorer, evaluations, grids=("coarse",),
                                                     curves=curves)
        searched = searched + rate
        searched_curves = {p.name: [list(c) for c in curves.get(p.name, [])] for p in searched}
        as_given = tomlkit.parse(given_text)
        # per searched key: does the scored file hold another value than the file as given
        moved = {p.name: get_value(cur_doc, p) is not None and
                 not np.array_equal(get_value(cur_doc, p), get_value(as_given, p)) for p in searched}
        for p in searched:
            curve = curves.get(p.name, [])
            v = get_value(cur_doc, p)
            if len(curve) < 2:   # only the current point: the budget ran out first
                entry = chosen.get(p.name)
                if entry and "from_data" in entry and moved[p.name]:
                    # the data stage's value, scored with the rest: tuned.toml holds what was scored
                    entry.update({"value": _value_text(p, v), "spread": None,
                                  "how": f"{entry['data_how']}; the budget ran out before the search reached it"})
                    continue
                if kept_as_given and scorer.left() > 0:
                    why = ("not reached: the search's last evaluations were held for the conservative pass, "
                           "which does not run when the file as given is kept")
                else:
                    why = "the budget ran out before the search reached it"
                if moved[p.name] and not kept_as_given:
                    # an element of a key another parameter moved (the vertical gyro's ARW with the ARW)
                    not_tuned[p.name] = f"{why}; its value moved with the key it is part of: {_value_text(p, v)}"
                else:
                    not_tuned[p.name] = f"{why}: the file's value kept"
                chosen.pop(p.name, None)
                continue
            spread = _spread(p, curve, n_windows)
            entry = chosen.setdefault(p.name, {})
            entry.update({"value": _value_text(p, v), "how": _how(p, curve, cur, entry),
                          "spread": spread, "curve": [list(c) for c in curve]})
        if kept_as_given:
            # what the search's best (and the data and installation stages) had, for the report;
            # then the file as given, as it was scored
            for name, c in list(chosen.items()):
                # a key not searched (installation, stillness, suspension) is in chosen only when moved
                if moved.get(name, True) and "value" in c:
                    found[name] = {"value": c["value"], "how": c.get("how", "")}
                not_tuned[name] = (f"{c['value']} found, not written: the file as given is kept" if name in found
                                   else "the file as given is kept (its value stands)")
                chosen.pop(name)
            cur_doc, cur = as_given, given
            searched = []

    finally:
        scorer.close()
    tuned_text = _write_tuned(text, cur_doc, chosen, [p for p in searched if p.name in chosen])
    if kept_as_given:
        tuned_text = f"# mixnav tune: the file as given, kept: {kept_as_given}\n" + tuned_text
    tuned_text = _data_dir_from(tuned_text, ds.dataset.data_dir, data_folder, out)
    result = TuneResult(tuned_text=tuned_text, chosen=chosen, given=given, tuned=cur, evaluations=evaluations,
                        not_tuned=not_tuned, runs=scorer.runs, out=out, kept_as_given=kept_as_given, found=found,
                        curves=searched_curves)
    from .report import write_outputs
    write_outputs(out, result, {"dataset": str(dataset), "source": source, "method": target, "budget": budget,
                                "evaluations_spent": len(scorer.seen), "filter_runs": scorer.runs, "seed": seed,
                                "span_s": [t_first, t_last], "window_s": w, "folds": len(windows),
                                "cv_windows": windows, "fixed": fix, "criterion_best_searched": searched_best,
                                "conservative_tolerance": tolerance, "kept_as_given": kept_as_given,
                                "found_not_written": found})
    write_marker(out, "tune", True, TUNE_FILES)
    return result


def _kept_as_given(given: dict, best: dict, tolerance: float, n_windows: int | None = None) -> str | None:
    """Why the file as given is the tuned file (None: it is not): its criterion is within
    ``tolerance`` (one standard error, at least 2 / n_windows: :func:`.search.conservative_tolerance`) of the search's
    best. The criterion cannot tell the two apart, and the user's file carries what the data
    cannot (a data sheet, a fit by hand); the conservative pass would otherwise widen from the
    best up to the bar and could hand back a file the criterion scores worse than the one given
    (the shipped drive-0708 file: 1.102 as given, 1.221 tuned)."""
    g, b = given.get("nlpd"), best.get("nlpd")
    if g is None or b is None or not (math.isfinite(g) and math.isfinite(b)) or g > b + tolerance:
        return None
    se = best.get("criterion_se")
    parts = (f"the larger of one standard error, {se:.3f}, and 2 / {n_windows} windows"
             if se is not None and n_windows else "one standard error, at least 2 / n_windows")
    if g <= b:   # keys judged otherwise (timing: the innovation likelihood) can take the search above its start
        return (f"its criterion ({g:.3f}) is at or below the search's best ({b:.3f}; the timing keys follow "
                f"the innovation likelihood and the installation its cross-fitted score, not this criterion): "
                f"nothing the search found beats it")
    return (f"its criterion ({g:.3f}) is within the criterion's bar ({tolerance:.3f}: {parts}) of the "
            f"search's best ({b:.3f}): the cross-validation cannot tell them apart")


def _data_stage(doc, po, span, fix, chosen: dict, not_tuned: dict, local: Evaluator):
    """The search's start from the data alone (:mod:`.data_stage`): a copy of ``doc`` with the
    still segments' Allan noise, the stillness thresholds and the smoothed bias walks; ``po``:
    the probe run (its IMU and fixes on the run's time axis); ``local``: an evaluator on the
    span. What was found goes into ``chosen``, what could not be into ``not_tuned``."""
    from .data_stage import BIAS_INCREMENT_S, LOOSEN, bias_walks, imu_noise, stillness_thresholds
    # the fixes the filter uses, throughout the data stage: the fixes in the file's own withheld
    # windows are the user's truth and stay out of the tuning, as the cross-validation keeps them
    # out (the IMU inside those windows is data the filter runs on, and is used)
    noise = imu_noise(po.imu, po.fixes, span)
    params = {p.name: p for p in ins_parameters()}
    start_doc = tomlkit.parse(tomlkit.dumps(doc))
    for name, attr, rel in (("imu.errors.arw", "arw", "arw_rel_sigma"), ("imu.errors.vrw", "vrw", "vrw_rel_sigma")):
        p = params[name]
        if name in fix:
            not_tuned[name] = "fixed by the user (--fix)"
            continue
        if noise is None:
            not_tuned[name + " (Allan)"] = ("no still segment of 3 s or more in the span: the white noise was "
                                            "not read from the data; the file's value is the search's start")
            continue
        if get_value(doc, p) is None:
            not_tuned[name] = "not in the file"
            continue
        set_value(start_doc, p, getattr(noise, attr))
        chosen[name] = {"from_data": _value_text(p, getattr(noise, attr)),
                        "data_how": f"Allan deviation at 1 s over {noise.segments} still segments "
                                    f"({noise.still_s:.0f} s), +-{100 * getattr(noise, rel):.0f} % (1 sigma)"}
    if "aiding" in doc and "zupt" in doc["aiding"]:
        for k, (val, how) in stillness_thresholds(po.imu, po.fixes, span).items():
            name = f"aiding.zupt.{k}"
            if name in fix:
                not_tuned[name] = "fixed by the user (--fix)"
            elif val is None:
                not_tuned[name] = how
            else:
                unit = "m/s^2" if k == "accel_std" else "rad/s"
                item = tomlkit.string(f"{val:.4g} {unit}")
                item.comment(f"mixnav tune: {how}")
                start_doc["aiding"]["zupt"][k] = item
                chosen[name] = {"value": f"{val:.4g} {unit}", "how": how, "spread": None}
    _suspension_stage(doc, start_doc, po, span, fix, chosen, not_tuned, local)
    wanted = [n for n in ("imu.errors.gyro_bias_walk", "imu.errors.accel_bias_walk") if n not in fix]
    if not wanted:
        return start_doc
    walks = bias_walks(local, tomlkit.dumps(start_doc), span)
    if walks is None:
        for n in wanted:
            not_tuned[n + " (smoothed)"] = ("the span holds fewer than three 10 s increments, or the method "
                                            "cannot be smoothed: the walks were not read from the data")
        return start_doc
    for n in wanted:
        p = params[n]
        v = walks[n.rsplit(".", 1)[1]]
        set_value(start_doc, p, v)
        chosen[n] = {"from_data": _value_text(p, v),
                     "data_how": f"RTS-smoothed bias increments over {BIAS_INCREMENT_S:g} s "
                                 f"({walks['increments']} increments; the file's walks loosened "
                                 f"x{LOOSEN:g} for that run)"}
    return start_doc


def _start_kept(started: dict, given: dict, chosen: dict, not_tuned: dict) -> bool:
    """Whether the data stage's file (score ``started``) starts the search rather than the file
    as given (``given``). When it does not, what the data stage found is marked or withdrawn in
    ``chosen`` (``tuned.toml`` is the file that was scored): the noise values say they were not
    kept, a measured suspension gain goes back to the search from the file's value, and the
    stillness thresholds move to ``not_tuned`` with the reason."""
    if started["nlpd"] <= given["nlpd"]:
        return True
    for name in ("imu.errors.arw", "imu.errors.vrw", "imu.errors.gyro_bias_walk", "imu.errors.accel_bias_walk"):
        if name in chosen and "data_how" in chosen[name]:
            chosen[name]["data_how"] += " (not kept: the criterion preferred the file's value)"
    chosen.pop("aiding.nhc.pitch_per_accel", None)
    for name in ("aiding.zupt.accel_std", "aiding.zupt.gyro_rate"):
        if name in chosen:
            not_tuned[name] = (f"{chosen.pop(name)['how']}; not kept: the data stage's file as a whole "
                               "scored worse than the file as given")
    return False


def _suspension_stage(doc, start_doc, po, span, fix, chosen: dict, not_tuned: dict, local: Evaluator) -> None:
    """``[aiding.nhc] pitch_per_accel`` measured from the data (:func:`.data_stage.suspension_pitch`,
    a run of the tuned method without the NHC) into ``start_doc``; a measured gain is not searched
    (``chosen[...]["measured"]``): over a flat or steady span the criterion hardly sees it (on
    drive-0708's parking lot it moved by 0.01 across 0-0.4 deg per m/s^2, inside its standard
    error of 0.3) and would pick it by rounding, while the fit is a property of the car."""
    from .data_stage import suspension_pitch
    name = "aiding.nhc.pitch_per_accel"
    if "aiding" not in doc or "nhc" not in doc["aiding"]:
        return
    if name in fix:
        not_tuned[name] = "fixed by the user (--fix)"
        return
    ds = local.dataset(tomlkit.dumps(start_doc))
    if not ds.methods or not hasattr(ds.methods[0], "aiding") or "nhc" not in (ds.methods[0].aiding or []):
        return
    m = ds.methods[0]
    ds = ds.model_copy(update={"methods": [m.model_copy(update={"aiding": [a for a in m.aiding if a != "nhc"]})]})
    res = local.run(ds, []).results.get(local.method)
    if res is None:
        return
    k, how = suspension_pitch(res, po.fixes, span, ds.aiding.vehicle_mounting)
    if k is None:
        not_tuned[name + " (data)"] = how + "; searched by the criterion instead"
        return
    p = next(q for q in ins_parameters() if q.name == name)
    set_value(start_doc, p, np.array([k]), comment=f"mixnav tune: {how}")
    chosen[name] = {"value": _value_text(p, np.array([k])), "how": how, "spread": None, "measured": True}


def _installation_stage(cur_doc, cur: dict, fix, scorer, evaluations: list, chosen: dict, not_tuned: dict,
                        local: Evaluator):
    """The antenna lever arm and vehicle mounting estimated as states (:mod:`.installation`): the
    components beyond their significance written into the file when the criterion, cross-fitted
    (each fold's estimate made without its withheld fixes), improves by more than MIN_GAIN (a
    fixed key keeps the file's value). Returns the (possibly new) document and its score."""
    from .installation import ANTENNA, MOUNTING, cross_fitted_score, kept_as_given, proposal
    if all(k in fix for k in (ANTENNA.name, MOUNTING.name)):
        for k in (ANTENNA.name, MOUNTING.name):
            not_tuned[k] = "fixed by the user (--fix)"
        return cur_doc, cur
    if scorer.left() <= 0:
        return cur_doc, cur
    given_text = tomlkit.dumps(cur_doc)
    prop = proposal(local, given_text)
    if prop is None:
        not_tuned[ANTENNA.name] = "the tuned method cannot estimate the installation (not a loose EKF)"
        return cur_doc, cur
    pdoc, notes, mask, unwritten = prop
    for k, how in unwritten.items():
        not_tuned[k] = f"{how}: no component beyond it, so the file's value stands"
    for k in (ANTENNA.name, MOUNTING.name):
        if k in fix:
            notes.pop(k, None)
            not_tuned[k] = "fixed by the user (--fix)"
    pdoc = kept_as_given(pdoc, given_text, fix)
    if not notes:
        return cur_doc, cur
    # judged cross-fitted: the whole span's estimate has seen every fold's withheld fixes; on
    # the scorer's workers (two runs per fold), not journaled: deterministic, a resumed tuning
    # computes the same
    crossed = cross_fitted_score(local, given_text, mask, keep_as_given=fix, scorer=scorer)
    if not math.isfinite(crossed.nlpd):
        for k in notes:
            not_tuned[k] = "a fold's run could not estimate the installation"
        return cur_doc, cur
    crossed = crossed.as_dict()
    evaluations.append({"changed": "installation estimated as states, each fold's without its windows",
                        "score": crossed})
    keep = crossed["nlpd"] < cur["nlpd"] - MIN_GAIN
    sc = None
    if keep:
        (sc,) = scorer.score([tomlkit.dumps(pdoc)])
        keep = sc is not None
        if keep:
            evaluations.append({"changed": "installation estimated as states", "score": sc})
    for k, (val, how) in notes.items():
        if keep:
            chosen[k] = {"value": val, "how": f"{how}; the criterion, cross-fitted, {cur['nlpd']:.3f} -> "
                                              f"{crossed['nlpd']:.3f}", "spread": None}
        else:
            not_tuned[k] = (f"{how}; not written: the criterion, each fold's estimate made without its "
                            f"withheld fixes, did not improve ({cur['nlpd']:.3f} -> {crossed['nlpd']:.3f})")
    return (pdoc, sc) if keep else (cur_doc, cur)


def _fixed(name: str, fix) -> bool:
    """``name`` kept as the file gives it: named in ``fix``, or an element (``X[i]``) of a key
    named there (fixing ``imu.errors.arw`` fixes its vertical element too)."""
    return name in fix or name.split("[", 1)[0] in fix


def _carries_fixed(p: Parameter, fix) -> bool:
    """A key whose step moves a key the user fixed (the NHC rate carries the NHC sigmas), other
    than the clock drift's time offset (the drift then turns about the stamps' start)."""
    return any(_fixed(q.name, fix) or any(_fixed(f"{q.name}[{i}]", fix) for i in range(3))
               for q, _ in p.carries) and p.name != "installation.imu_clock_drift"


def _applies(doc, p: Parameter, ds) -> bool:
    return _why_not(doc, p, ds) is None


def _why_not(doc, p: Parameter, ds) -> str | None:
    """Why a parameter is not searched on this file (None: it is); ``ds``: the dataset with the
    tuned method only."""
    if p.path[0] == "aiding":
        table = p.path[1] if len(p.path) > 2 else "nhc"   # aiding.vehicle_point serves the NHC
        if "aiding" not in doc or table not in doc["aiding"]:
            return f"no [aiding.{table}] in the file"
        # a constraint the tuned method does not apply: moving it could not change the criterion
        if table in ("nhc", "odometer") and not any(table in (getattr(m, "aiding", None) or [])
                                                    for m in ds.methods):   # ds: the tuned method only
            return f"the tuned method does not use the {'NHC' if table == 'nhc' else 'odometer'}"
    if p.name == "gnss.velocity_delay" and (not ds.gnss.use_velocity or ds.gnss.format != "rtklib-pos"):
        return "the fixes' velocities are not used, or their format is not rtklib-pos"
    if get_value(doc, p) is None:
        return "not in the file (the IMU grade's value is used)"
    if p.name == "aiding.nhc.rate" and get_value(doc, p)[0] >= p.upper:
        # the bound is the search's cost, not the data's: a faster rate the user chose stays
        return f"the file's rate is at or above the {p.upper:g} Hz the search tries: kept"
    return None


def _last_visit(curve) -> list:
    """The points of the search's last visit of a key (they differ in that key only)."""
    return [c for c in curve if c[4] == curve[-1][4]] if curve else []


def _spread(p: Parameter, curve, n_windows: int) -> str | None:
    """The values tried in the key's last visit whose criterion (for a timing key: minus the
    innovation log-likelihood per update) is within 2 / n_windows of that visit's best (a
    likelihood-ratio interval counting each window as one independent observation: the fixes
    within a window are strongly correlated); the other keys are the same across a visit's
    points."""
    pts = _last_visit(curve)
    if len(pts) < 2:
        return None
    from .search import judged
    # what the search followed along this key (a timing key: the innovation log-likelihood per
    # update), read with the same count of independent observations (the windows)
    val = [judged(p, {"criterion": c[2], "innovation_ll_per_update": c[3]}) for c in pts]
    best = min(val)
    ok = [c[1] for c, v in zip(pts, val) if v <= best + 2.0 / max(n_windows, 1)]
    what = "" if p.index is not None or p.kind != "log" else " (x axis; the search scales all)"
    return f"{min(ok):.4g}-{max(ok):.4g} {p.unit}{what}"


def _how(p: Parameter, curve, cur: dict, entry: dict) -> str:
    base = entry.get("data_how")
    n = len(curve)
    s = (f"GNSS innovation log-likelihood of the cross-validation runs ({n} values tried along this key)"
         if p.judged_by == "innovation" else
         f"cross-validation on the recording's own GNSS ({n} values tried along this key)")
    return f"start: {base}; then {s}" if base else s


def _data_dir_from(text: str, written: str, folder: Path, out: Path) -> str:
    """``dataset.data_dir`` as seen from the output folder when the file's relative path would
    not find the data from there (tuned.toml lives in ``out``, not beside the dataset file)."""
    if Path(written).is_absolute() or (out / written).is_dir():
        return text
    doc = tomlkit.parse(text)
    item = tomlkit.string(Path(os.path.relpath(Path(folder).resolve(), out.resolve())).as_posix())
    item.comment(f"mixnav tune: the data folder as seen from this file (the dataset file said {written!r})")
    doc["dataset"]["data_dir"] = item
    return tomlkit.dumps(doc)


def _write_tuned(text: str, cur_doc, chosen: dict, searched) -> str:
    """The dataset file as given (its reference sections kept) with the tuned values, each
    with a comment saying how it was found and its spread."""
    doc = tomlkit.parse(text)
    seen = set()
    for p in searched:
        key = p.path
        if key in seen:
            continue
        seen.add(key)
        v = get_value(cur_doc, p)
        names = [q.name for q in searched if q.path == key]
        notes = []
        for n in names:
            c = chosen.get(n, {})
            notes.append(f"{c.get('how', '')}" + (f"; within the criterion's spread: {c['spread']}"
                                                   if c.get("spread") else ""))
        set_value(doc, p, v, comment="mixnav tune: " + " | ".join(notes))
    for p in searched:           # a carried key as it was scored, searched itself or not
        for q, _ in p.carries:
            if q.path not in seen:
                seen.add(q.path)
                set_value(doc, q, get_value(cur_doc, q), comment=f"mixnav tune: moved with {p.name}")
    from .installation import ANTENNA, MOUNTING
    for p in (ANTENNA, MOUNTING):
        if p.name in chosen:
            set_value(doc, p, get_value(cur_doc, p), comment=f"mixnav tune: {chosen[p.name]['how']}")
    params = {p.name: p for p in ins_parameters()}
    for name, c in chosen.items():
        if c.get("measured") and name in params:      # from the data stage, not searched
            set_value(doc, params[name], get_value(cur_doc, params[name]), comment=f"mixnav tune: {c['how']}")
    for name, c in chosen.items():
        if name.startswith("aiding.zupt.") and "value" in c and "aiding" in doc and "zupt" in doc["aiding"]:
            item = tomlkit.string(c["value"])
            item.comment(f"mixnav tune: {c['how']}")
            doc["aiding"]["zupt"][name.rsplit(".", 1)[1]] = item
    return tomlkit.dumps(doc)
