"""``mixnav tune`` for raw-GNSS datasets (``kind = "gnss-raw"``: a phone log, a RINEX or u-blox
file): the constant-velocity filters' motion and clock noise and the epoch mixture's starting
values, from the recording alone.

There are no fixes to withhold: the receiver's own pseudoranges are all there is. So, as for
odometry + pseudoranges (:mod:`.vehicle`), the whole causal pipeline (the SPP, then the tuned
filter started at the first fix at or after ``[motion] start``) runs from several starts, and
the criterion is the tuned method's innovation log-likelihood: each pseudorange row's log
predictive density before the row is used (the epoch mixture's own LOS/NLOS density; other
estimators the engine's Gaussian one), summed over the rows from each start plus
:data:`SETTLE` seconds and over the starts, minimised as minus that per row. The first
seconds after a start are left out because the filter's start (the SPP fix's covariance,
a zero velocity) is not tuned and every candidate's transient would otherwise weigh in.

The SPP solutions do not depend on anything searched here (the pseudorange sigmas, which the
SPP weights with, are not searched), so every candidate starts from the same fixes and
scores the same rows; they, and the filters' corrected pseudoranges, are computed once
(:meth:`RawEvaluator.stage`, keyed by :func:`stage_key`: what they depend on) and every
candidate and start runs the filter alone on them, with the same numbers as the whole
pipeline (tests/test_tuning_raw.py).

What is searched (:func:`raw_parameters`, in this order): the horizontal and vertical
white-acceleration densities (a wide grid: a static receiver wants about 0.01, a car about
1 m/s^2/sqrt(Hz)), the receiver clock's bias and drift noise, and, when the tuned method is
an epoch mixture, its starting line-of-sight weight, delay mean and sd and LOS variance
factor; then the fine grid over all.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import tomlkit

from ... import units as u
from .parameters import Parameter
from .vehicle import VehicleScore, _blocks, epoch_log_density, record_searched

#: starts of the pipeline [s after the first epoch]: one every STARTS_EVERY, at most MAX_STARTS
STARTS_EVERY = 30.0
MAX_STARTS = 6
#: rows are scored from each filter start plus this [s] (the untuned start's transient left out)
SETTLE = 20.0
#: a start needs this much data scored after its settling [s]
MIN_SCORED = 60.0
#: the acceleration densities' grid: a decade each way, a winner at the edge followed once more
_ACCEL_COARSE = (0.1, 10 ** -0.5, 10 ** 0.5, 10.0)
_LOG_COARSE, _LOG_FINE = (0.25, 0.5, 2.0, 4.0), (2.0 ** -0.5, 2.0 ** 0.5)
#: the epoch mixture's starting values that are searched: key -> (kind, coarse, fine, lower, upper,
#: default, unit, about); the defaults are EpochMixtureOptions'
_MIXTURE_START = {
    "los_weight": ("shift", (-0.3, -0.15, 0.15, 0.3), (-0.05, 0.05), 0.05, 1.0, 0.5, "",
                   "the epoch mixture's starting line-of-sight weight"),
    "delay_mean": ("log", _LOG_COARSE, _LOG_FINE, 0.1, 500.0, 10.0, "m",
                   "the epoch mixture's starting mean of the delayed (NLOS) component"),
    "delay_sd": ("log", _LOG_COARSE, _LOG_FINE, 1.0, 500.0, 30.0, "m",
                 "the epoch mixture's starting sd of the delayed component"),
    "los_scale": ("log", _LOG_COARSE, _LOG_FINE, 0.01, 100.0, 1.0, "",
                  "the epoch mixture's starting factor on the model's pseudorange variance"),
}


def raw_parameters(method_index: int | None = None) -> list[Parameter]:
    """The keys searched for a raw-GNSS dataset, in visiting order; with ``method_index`` (the
    tuned epoch mixture's position in ``[[methods]]``) also its starting values
    (``options.<key>`` of that method)."""
    vrw = u.VELOCITY_RANDOM_WALK
    out = [
        Parameter("motion.accel_sigma", ("motion", "accel_sigma"), vrw, "m/s^2/sqrt(Hz)", "log", _ACCEL_COARSE,
                  _LOG_FINE, 1e-4, 30.0, default=1.0,
                  about="the constant-velocity model's horizontal white-acceleration density"),
        Parameter("motion.vertical_accel_sigma", ("motion", "vertical_accel_sigma"), vrw, "m/s^2/sqrt(Hz)", "log",
                  _ACCEL_COARSE, _LOG_FINE, 1e-4, 30.0, default=0.3,
                  about="the constant-velocity model's vertical white-acceleration density"),
        Parameter("motion.clock_q_bias", ("motion", "clock_q_bias"), u.DIMENSIONLESS, "m^2/s", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-6, 1e8, default=1000.0, plain=True, about="receiver clock bias noise density"),
        Parameter("motion.clock_q_drift", ("motion", "clock_q_drift"), u.DIMENSIONLESS, "m^2/s^3", "log",
                  _LOG_COARSE, _LOG_FINE, 1e-7, 1e6, default=1.0, plain=True,
                  about="receiver clock drift noise density"),
    ]
    if method_index is not None:
        for key, (kind, coarse, fine, lo, hi, default, unit, about) in _MIXTURE_START.items():
            out.append(Parameter(f"options.{key}", ("methods", method_index, "options", key), u.DIMENSIONLESS,
                                 unit, kind, coarse, fine, lo, hi, default=default, about=about, plain=True))
    return out


def raw_keys(ds=None) -> list[str]:
    """What ``--fix`` accepts for a raw-GNSS dataset."""
    return [p.name for p in raw_parameters(0)]


def starts_for(duration: float) -> list[float]:
    """The pipeline's starts [s]: 0, then one every STARTS_EVERY s while MIN_SCORED s are left
    after the start plus SETTLE; at most MAX_STARTS."""
    out, s = [], 0.0
    while s + SETTLE + MIN_SCORED <= duration + 1e-9 and len(out) < MAX_STARTS:
        out.append(s)
        s += STARTS_EVERY
    return out


def target_method(ds, method: str | None) -> str:
    """The method tuned: the one named (a filter, not an epoch-by-epoch ``wls``), else the first
    epoch mixture, else the first filter."""
    from ...errors import ArgumentError
    filters = [m for m in ds.methods or () if m.estimator != "wls"]
    if method is not None:
        names = [m.name for m in ds.methods or ()]
        if method not in names:
            raise ArgumentError(f"no method '{method}' in the dataset (it has {', '.join(names)})", argument="method")
        if method not in [m.name for m in filters]:
            raise ArgumentError(f"'{method}' is an epoch-by-epoch solution (estimator 'wls'): nothing of it is "
                                "tuned; name a filter", argument="method")
        return method
    if not filters:
        raise ArgumentError("the dataset has no filter method (only 'wls' solutions): nothing to tune",
                            argument="method")
    for m in filters:
        if m.estimator == "epoch-mixture":
            return m.name
    return filters[0].name


def stage_key(ds) -> str:
    """What the SPP stage of ``ds`` depends on (:func:`~mixnav.experiment.spp_process.solve_spp`
    and :func:`~mixnav.experiment.spp_process.filter_inputs`): ``[raw_gnss]``, ``[reference]``,
    ``[reference_point]``, the ``wls`` methods and ``motion.clock_jump``; never a searched key."""
    import json
    parts = [ds.raw_gnss, ds.reference, ds.reference_point,
             [m for m in ds.run_methods() if m.estimator == "wls"], float(ds.motion.clock_jump)]
    return json.dumps([p.model_dump(mode="json") if hasattr(p, "model_dump") else
                       [q.model_dump(mode="json") for q in p] if isinstance(p, list) else p for p in parts],
                      default=str, sort_keys=True)


class RawEvaluator:
    """Runs candidate files of one raw-GNSS dataset from several starts and scores them
    (module docstring). The files are read once, and the SPP stage (the SPP track, the
    filters' corrected pseudoranges) computed once per :func:`stage_key`; each candidate and
    start runs the filter alone (``cached=False``: the whole pipeline every time, the same
    numbers). Same interface as :class:`.criterion.Evaluator`."""

    def __init__(self, text: str, source: str, data: str | None, method: str, starts, settle: float,
                 cached: bool = True):
        from ...config.loader import load_dataset_text
        from ..data_folder import find_data_dir
        from ..pipelines import gnss_raw
        self.source, self.method, self.starts, self.settle = source, method, list(starts), float(settle)
        self.cached, self._stages = bool(cached), {}
        ds, _, _ = load_dataset_text(text, source)
        self.folder = find_data_dir(ds, data, source)
        self.inputs = gnss_raw.load(ds, source, self.folder)

    def dataset(self, doc_text: str):
        from ...config.loader import load_dataset_text
        ds, _, _ = load_dataset_text(doc_text, self.source)
        methods = [m.model_copy(update={"smooth": False}) for m in ds.methods if m.name == self.method]
        return ds.model_copy(update={"methods": methods})

    def stage(self, ds):
        """The SPP stage of ``ds`` (:func:`~mixnav.experiment.pipelines.gnss_raw.spp`), computed
        once per distinct :func:`stage_key` and reused by every candidate and start."""
        from ..pipelines import gnss_raw
        key = stage_key(ds)
        if key not in self._stages:
            if len(self._stages) >= 2:
                self._stages.clear()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._stages[key] = gnss_raw.spp(ds, self.source, self.folder, self.inputs)
        return self._stages[key]

    def run(self, ds):
        """The pipeline's output for ``ds`` (its own start), with the innovation densities
        recorded: the filters on the cached SPP stage (the same numbers as
        :func:`~mixnav.experiment.pipelines.gnss_raw.run`, which ``cached=False`` runs)."""
        from ...filters.ekf import innovation_likelihood
        from ..pipelines import gnss_raw
        stage = self.stage(ds) if self.cached else None
        with innovation_likelihood(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if stage is None:
                return gnss_raw.run(ds, self.source, self.folder, self.inputs)
            return gnss_raw.filters(stage, ds)

    def evaluate(self, doc_text: str) -> VehicleScore:
        from ...errors import MixnavError
        from ..pipelines import gnss_raw
        try:
            ds = self.dataset(doc_text)
            ll_total, updates, rows, per_start = 0.0, 0, 0, []
            for s in self.starts:
                po = self.run(gnss_raw.with_start(ds, s))
                t, ll, m = epoch_log_density(po.results[self.method])
                sel = t > float(po.init.time) + self.settle
                if not sel.any():
                    raise ValueError(f"no update after {float(po.init.time) + self.settle:g} s")
                per_start.append(float(ll[sel].sum()))
                ll_total += per_start[-1]
                updates += int(sel.sum())
                rows += int(m[sel].sum())
        except (MixnavError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
            return VehicleScore(math.inf, math.inf, -math.inf, [], 0, error=f"{type(exc).__name__}: {exc}")
        if not math.isfinite(ll_total) or rows == 0:
            return VehicleScore(math.inf, math.inf, -math.inf, per_start, 0, error="a log density was not finite")
        return VehicleScore(-ll_total / rows, None, ll_total / updates, per_start, updates, rows=rows)

    def duration_s(self, doc_text: str) -> float:
        """The span [s since the first epoch] the tuned method's solutions cover, from one run of
        ``doc_text`` from its own start."""
        res = self.run(self.dataset(doc_text)).results[self.method]
        return float(np.asarray(res.time, float)[-1])


def tune_raw(*, text: str, stripped: str, source: str, ds, out, data, data_folder, journal, budget: int,
             workers, scheduler, fix, method, progress: bool, header: dict):
    """:func:`mixnav.tune` on a raw-GNSS dataset (module docstring). Returns the
    :class:`~mixnav.experiment.tuning.TuneResult` (its files written by the caller)."""
    from ...errors import ArgumentError
    from . import TuneResult, _data_dir_from, _write_tuned
    from .scoring import Scorer
    from .search import coordinate_search
    target = target_method(ds, method)
    index = [m.name for m in ds.methods].index(target)
    mixture = ds.methods[index].estimator == "epoch-mixture"
    params = raw_parameters(index if mixture else None)
    unknown = [k for k in fix if k not in raw_keys()]
    if unknown:
        raise ArgumentError(f"unknown key(s) {', '.join(unknown)} for a raw-GNSS dataset; tunable: "
                            f"{', '.join(raw_keys())}", argument="fix")
    local = RawEvaluator(stripped, source, data, target, [], SETTLE)
    duration = local.duration_s(stripped)
    starts = starts_for(duration)
    if not starts:
        raise ArgumentError(f"the recording spans {duration:.0f} s; tuning needs at least "
                            f"{SETTLE + MIN_SCORED:g} s ({SETTLE:g} s after the filter's start, {MIN_SCORED:g} s "
                            "scored)", argument="dataset")
    setup = ("mixnav.experiment.tuning.raw_gnss:RawEvaluator", stripped, source,
             None if data is None else str(data), target, starts, SETTLE)
    scorer = Scorer(setup, journal, workers, scheduler, progress, budget, len(starts))
    n_blocks = _blocks(starts, duration, SETTLE)
    chosen, not_tuned, evaluations = {}, {}, []
    for p in params:
        if p.name in fix:
            not_tuned[p.name] = "fixed by the user (--fix)"
    if not mixture:
        not_tuned["options (mixture starting values)"] = f"the tuned method '{target}' is not an epoch mixture"
    others = [m.name for m in ds.methods if m.estimator != "wls" and m.name != target]
    if others:
        not_tuned["the other filters"] = (f"{', '.join(others)}: scored by no criterion here; they run with the "
                                          f"[motion] values tuned for '{target}' (tune one with --method NAME)")
    searched = [p for p in params if p.name not in fix]
    try:
        doc = tomlkit.parse(stripped)
        (given,) = scorer.score([tomlkit.dumps(doc)])
        evaluations.append({"changed": "the file as given", "score": given})
        cur_doc, cur, curves = coordinate_search(doc, given, searched, scorer, evaluations, grids=("coarse", "fine"))
        record_searched(searched, curves, cur_doc, chosen, not_tuned, "likelihood", starts, n_blocks, given)
    finally:
        scorer.close()
    tuned_text = _write_tuned(text, cur_doc, chosen, [p for p in searched if p.name in chosen])
    tuned_text = _data_dir_from(tuned_text, ds.dataset.data_dir, data_folder, out)
    result = TuneResult(tuned_text=tuned_text, chosen=chosen, given=given, tuned=cur, evaluations=evaluations,
                        not_tuned=not_tuned, runs=scorer.runs, out=out)
    header.update({"method": target, "criterion_kind": "likelihood", "starts_s": starts, "score_after_s": SETTLE,
                   "pipeline": "the whole causal pipeline (the SPP, then the filter from the first fix at or after "
                               "each start)",
                   "evaluations_spent": len(scorer.seen), "filter_runs": scorer.runs, "independent_blocks": n_blocks})
    return result
