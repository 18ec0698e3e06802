"""``mixnav tune`` for odometry + pseudorange datasets (``kind = "odometry-gnss"``).

There are no GNSS fixes to withhold: the receiver gives pseudoranges with metres of
non-line-of-sight error, and the track alignment, which needs them, begins every run. So the
whole causal pipeline (track alignment, then the tuned method) runs from several starts
(``[alignment] start``: a setting must work from several places of the drive) and the rows
from each start plus ``SCORE_AFTER`` seconds are scored (every candidate scores the same rows:
the alignment windows searched are at most that long). Two criteria (``criterion``):

* ``"likelihood"`` (default): the tuned method's innovation log-likelihood, each pseudorange
  row's log predictive density before the row is used (the epoch mixture's own LOS/NLOS
  density; other estimators: the Gaussian one of the engine's record), summed over the rows
  and the starts; minimised as minus that per row.
* ``"withheld-satellites"``: each start runs twice, each run with half the satellites
  (:func:`satellite_folds`), and the withheld half is scored: per epoch the median over them
  of how far each one's residual lies from the epoch's median residual
  (:func:`withheld_deviation`, metres; the receiver clock cancels). Meant to be blind to a
  filter that follows its own satellites' errors; on smartLoc it is not (satellites behind the
  same buildings share their reflections) and it tuned worse than the likelihood
  (benchmarks/results/tune_smartloc.md).

The likelihood is the criterion benchmarks/smartloc_choose_settings.py chose smartLoc's
shipped window and bands by (the same rows and starts; a sum there, per row here, the rows the
same for every candidate), and the search repeats its stages (window, bands, window again);
from the file without them it finds the same window and bands (the results file above).
Neither criterion can judge the LOS errors' correlation time, which is therefore not
searched: the track alignment measures it on its window (the epoch mixture inflates its
update's row variances by the correlation factor but scores each row's density as if the
rows were independent, so the likelihood always prefers no correlation, while the filter
gets worse against the reference).

What is searched (:func:`vehicle_parameters`, in this order): the alignment window, the C/N0
band edges (a discrete scan over the recording's own C/N0 quantiles: :func:`edge_candidates`;
written into the epoch mixture's options, :func:`set_edges`), the window again (coarse grid,
with the bands), the start sigmas of position and heading, the dead reckoning's lateral and vertical velocity
noise, the receiver clock's noise (coarse grid); then the band edges again and the fine grid
over all.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import tomlkit

from ... import units as u
from .parameters import Parameter

#: the criteria for this kind of dataset; the first is the default
CRITERIA = ("likelihood", "withheld-satellites")
#: starts of the pipeline [s after the first odometry sample] per criterion: one every
#: (STARTS_EVERY) s, at most (MAX_STARTS); both cost six pipeline runs per candidate
STARTS_EVERY = {"likelihood": 30.0, "withheld-satellites": 60.0}
MAX_STARTS = {"likelihood": 6, "withheld-satellites": 3}
#: pipeline runs per start
RUNS_PER_START = {"likelihood": 1, "withheld-satellites": 2}
#: the longest alignment window searched [s]; rows are scored from a start plus this
SCORE_AFTER = 40.0
#: a start needs this much data scored after ``S + SCORE_AFTER`` [s]
MIN_SCORED = 60.0
_LOG2PI = math.log(2.0 * math.pi)
_LOG_COARSE, _LOG_FINE = (0.25, 0.5, 2.0, 4.0), (2.0 ** -0.5, 2.0 ** 0.5)

#: the alignment's C/N0 band edges (scanned over discrete candidates, not moved by steps)
CN0_EDGES = "alignment.cn0_edges"


def vehicle_parameters() -> list[Parameter]:
    """The keys searched step by step for an odometry + pseudorange dataset, in visiting order."""
    return [
        Parameter("alignment.window", ("alignment", "window"), u.TIME, "s", "shift", (-10.0, -5.0, 5.0, 10.0),
                  (-2.5, 2.5), 10.0, SCORE_AFTER, default=20.0,
                  about="the track alignment's window (the filters start at its end)"),
        Parameter("alignment.position_sigma", ("alignment", "position_sigma"), u.LENGTH, "m", "log", _LOG_COARSE,
                  _LOG_FINE, 0.5, 200.0, default=10.0, about="the filter's start position 1-sigma"),
        Parameter("alignment.heading_sigma", ("alignment", "heading_sigma"), u.ANGLE, "deg", "log", _LOG_COARSE,
                  _LOG_FINE, 0.1 * u.DEG, 60.0 * u.DEG, default=0.1, about="the filter's start heading 1-sigma"),
        Parameter("motion.lateral_sigma", ("motion", "lateral_sigma"), u.VELOCITY, "m/s", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-3, 5.0, default=0.1, about="the dead reckoning's sideways velocity noise"),
        Parameter("motion.vertical_sigma", ("motion", "vertical_sigma"), u.VELOCITY, "m/s", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-3, 5.0, default=0.1, about="the dead reckoning's vertical velocity noise"),
        Parameter("motion.clock_q_bias", ("motion", "clock_q_bias"), u.DIMENSIONLESS, "m^2/s", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-6, 1e3, default=0.01, plain=True, about="receiver clock bias noise density"),
        Parameter("motion.clock_q_drift", ("motion", "clock_q_drift"), u.DIMENSIONLESS, "m^2/s^3", "log",
                  _LOG_COARSE, _LOG_FINE, 1e-7, 1e2, default=1e-3, plain=True,
                  about="receiver clock drift noise density"),
    ]


def vehicle_keys() -> list[str]:
    """What ``--fix`` accepts for an odometry + pseudorange dataset."""
    return [p.name for p in vehicle_parameters()] + [CN0_EDGES]


def edge_candidates(cn0: np.ndarray) -> list[tuple[str, list[float]]]:
    """C/N0 band edge candidates from the recording's own C/N0 (every row, no reference): no
    bands, and the K-quantiles (K = 2 ... 12, 15, 20) rounded to whole dB-Hz."""
    c = np.asarray(cn0, float)
    c = c[np.isfinite(c)]
    out = [("no bands", [])]
    if len(c) < 20:
        return out
    seen = set()
    for k in (2, 3, 4, 5, 6, 8, 10, 12, 15, 20):
        e = sorted({float(v) for v in np.round(np.percentile(c, np.arange(1, k) * 100.0 / k), 0)})
        if tuple(e) not in seen:
            seen.add(tuple(e))
            out.append((f"{k}-quantiles", e))
    return out


def starts_for(duration: float, criterion: str = "likelihood") -> list[float]:
    """The pipeline's starts [s] for a recording of ``duration`` s of odometry: 0, then one every
    ``STARTS_EVERY[criterion]`` s while ``MIN_SCORED`` s are left to score after the start plus
    ``SCORE_AFTER``; at most ``MAX_STARTS[criterion]``."""
    out, s = [], 0.0
    while s + SCORE_AFTER + MIN_SCORED <= duration + 1e-9 and len(out) < MAX_STARTS[criterion]:
        out.append(s)
        s += STARTS_EVERY[criterion]
    return out


def set_edges(doc, edges: list[float], method: str, comment: str | None = None) -> None:
    """Write the band edges into ``[alignment]`` and into the tuned method's options: always
    for an epoch mixture (it takes no bands from the alignment's hand-over, only the weights
    learned on its own bands: filters/epoch_mixture.py, ``_build_epoch_mixture``; written into
    ``[alignment]`` alone, the filter would run without bands and the scan would score the
    alignment's bands only), for another method when it names its own."""
    item = tomlkit.array()
    item.extend(float(e) for e in edges)
    if comment:
        item.comment(comment)
    if "alignment" not in doc:
        doc["alignment"] = tomlkit.table()
    doc["alignment"]["cn0_edges"] = item
    for m in doc.get("methods", []):
        if m.get("name") != method:
            continue
        names_own = "options" in m and "cn0_edges" in m["options"]
        if not (names_own or m.get("estimator") == "epoch-mixture"):
            continue
        if "options" not in m:
            m["options"] = tomlkit.table()
        m["options"]["cn0_edges"] = tomlkit.array()
        m["options"]["cn0_edges"].extend(float(e) for e in edges)


def get_edges(doc) -> list[float]:
    return [float(e) for e in doc.get("alignment", {}).get("cn0_edges", [])]


def epoch_log_density(res) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per update of a result: time [s], the sum of its rows' log predictive densities, and its
    rows. The estimator's own density when it records one (the epoch mixture), else the
    Gaussian innovation density of the engine's record (needs
    :func:`mixnav.filters.ekf.innovation_likelihood` around the run)."""
    out = res.outputs or {}
    if "innovation_log_density" in out:
        return (np.asarray(out["innovation_log_density_time"], float), np.asarray(out["innovation_log_density"], float),
                np.asarray(out["innovation_rows"], np.int64))
    if res.nis_time is None or res.nis_logdet is None:
        return np.zeros(0), np.zeros(0), np.zeros(0, np.int64)
    ok = np.isfinite(res.nis_logdet) & np.isfinite(res.nis)
    ll = -0.5 * (res.nis + res.nis_logdet + res.nis_dim * _LOG2PI)
    return res.nis_time[ok], ll[ok], np.asarray(res.nis_dim, np.int64)[ok]


class VehicleEvaluator:
    """Runs candidate files of one odometry + pseudorange dataset from several starts, each
    start twice with half the satellites withheld, and scores them (module docstring). The
    files are read once (the tuned keys do not change what is read). Same interface as
    :class:`.criterion.Evaluator`."""

    def __init__(self, text: str, source: str, data: str | None, method: str, starts, score_after: float,
                 criterion: str = "likelihood"):
        from ...config.loader import load_dataset_text
        from ..data_folder import find_data_dir
        from ..vehicle_process import read_vehicle
        if criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}")
        self.source, self.method, self.starts, self.score_after = source, method, list(starts), float(score_after)
        self.criterion = criterion
        ds, _, _ = load_dataset_text(text, source)
        self.folder = find_data_dir(ds, data, source)
        self.inputs = read_vehicle(ds, source, self.folder)
        inc = self.inputs.inc
        self.t0 = float(inc.time[0] - inc.dt[0])
        # the likelihood: one run with every satellite (nothing held); withheld satellites: two folds
        self.folds = (satellite_folds(self.inputs.epochs) if criterion == "withheld-satellites"
                      else [(self.inputs.epochs, None)])

    def dataset(self, doc_text: str):
        from ...config.loader import load_dataset_text
        ds, _, _ = load_dataset_text(doc_text, self.source)
        methods = [m.model_copy(update={"smooth": False}) for m in ds.methods if m.name == self.method]
        return ds.model_copy(update={"methods": methods})

    def evaluate(self, doc_text: str):
        from dataclasses import replace
        from ...errors import MixnavError
        from ...filters.ekf import innovation_likelihood
        from ..vehicle_process import run_vehicle
        try:
            ds = self.dataset(doc_text)
            ll_total, updates, rows, per_start, dev = 0.0, 0, 0, [], []
            for s in self.starts:
                d = ds.model_copy(update={"alignment": ds.alignment.model_copy(update={"start": s})})
                start_dev, start_ll = [], 0.0
                for used, held in self.folds:
                    with innovation_likelihood(), warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        vo = run_vehicle(d, self.source, self.folder, replace(self.inputs, epochs=used))
                    res = vo.results[self.method]
                    t, ll, m = epoch_log_density(res)
                    sel = (t - self.t0) > s + self.score_after
                    start_ll += float(ll[sel].sum())
                    updates += int(sel.sum())
                    rows += int(m[sel].sum())
                    if held is not None:
                        start_dev.append(withheld_deviation(res, held, self.t0 + s + self.score_after))
                if not updates:
                    raise ValueError(f"no update after {s + self.score_after:g} s")
                ll_total += start_ll
                if self.criterion == "likelihood":
                    per_start.append(start_ll)
                    continue
                per = np.concatenate(start_dev)
                if len(per) == 0:
                    raise ValueError(f"no epoch after {s + self.score_after:g} s with 3 withheld satellites")
                dev.append(per)
                per_start.append(float(per.mean()))
        except (MixnavError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
            return VehicleScore(math.inf, math.inf, -math.inf, [], 0, error=f"{type(exc).__name__}: {exc}")
        if self.criterion == "likelihood":
            if not math.isfinite(ll_total):
                return VehicleScore(math.inf, math.inf, -math.inf, per_start, 0, error="a log density was not finite")
            return VehicleScore(-ll_total / rows, None, ll_total / updates, per_start, updates, rows=rows)
        allv = np.concatenate(dev)
        if not np.isfinite(allv).all() or not math.isfinite(ll_total):
            return VehicleScore(math.inf, math.inf, -math.inf, per_start, 0, error="a score was not finite")
        # the standard error of the mean over roughly independent 10 s blocks (neighbouring
        # epochs share the state's error and the satellites' multipath)
        per_block = max(1, int(round(len(allv) / max(_blocks(self.starts, self.duration_s, self.score_after)
                                                     * len(self.folds), 1))))
        n_blocks = max(2, len(allv) // per_block)
        se = float(np.std(allv) / math.sqrt(n_blocks))
        return VehicleScore(float(allv.mean()), se, ll_total / max(updates, 1), per_start, len(allv))

    @property
    def duration_s(self) -> float:
        """The odometry's span [s], from its first sample's start."""
        return float(self.inputs.inc.time[-1]) - self.t0


def satellite_folds(epochs) -> list[tuple]:
    """Two folds of the pseudorange epochs: each keeps the satellites of one parity of
    ``sat_id + system`` for the filter and withholds the others (half of each system, as far
    as the numbering allows). Returns ``[(used, held), ...]``: ``used`` a PseudorangeEpochs,
    ``held`` (time, pseudorange, sat_ecef) of the withheld rows."""
    from ...gnss.pseudoranges import PseudorangeEpochs
    row_t = np.repeat(epochs.time, np.diff(epochs.start))
    parity = (epochs.sat_id + epochs.system) % 2
    out = []
    for f in (0, 1):
        keep = parity != f
        used = PseudorangeEpochs.from_rows(row_t[keep], epochs.pseudorange[keep], epochs.variance[keep],
                                           epochs.sat_ecef[keep], epochs.sat_id[keep], epochs.system[keep],
                                           epochs.elevation[keep], epochs.cn0[keep], epochs.source,
                                           None if epochs.sat_vel is None else epochs.sat_vel[keep],
                                           None if epochs.range_rate is None else epochs.range_rate[keep])
        out.append((used, (row_t[~keep], epochs.pseudorange[~keep], epochs.sat_ecef[~keep])))
    return out


def withheld_deviation(res, held, after: float) -> np.ndarray:
    """Per epoch after ``after`` [s] with at least three withheld satellites: the median over
    them of ``|r_j - median_k r_k|``, ``r_j`` the withheld pseudorange minus the range from the
    filter's position at that epoch (Earth rotation during the travel time applied) [m]. The
    receiver clock (common to the epoch's rows) cancels; what is left is the position error
    projected on the differences of the lines of sight, plus the withheld rows' own errors,
    which do not depend on the setting: the medians keep their NLOS delays from dominating."""
    from ...geodesy.frames import lla_to_ecef
    from ...gnss.geometry import C_LIGHT, earth_rotation_correction
    t, rho, sat = held
    ok = (t > after) & (t > res.time[0]) & (t <= res.time[-1] + 1e-9)
    if not ok.any():
        return np.zeros(0)
    t, rho, sat = t[ok], rho[ok], sat[ok]
    j = np.clip(np.searchsorted(res.time, t - 1e-9), 0, len(res.time) - 1)
    pos = lla_to_ecef(res.nav[j, 7:10])
    rng = np.linalg.norm(sat - pos, axis=1)
    r = rho - np.linalg.norm(earth_rotation_correction(sat, rng / C_LIGHT) - pos, axis=1)
    epochs, inv, n = np.unique(t, return_inverse=True, return_counts=True)
    out = []
    order = np.argsort(inv, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(n)])
    rs = r[order]
    for k in range(len(epochs)):
        if n[k] < 3:
            continue
        x = rs[bounds[k]:bounds[k + 1]]
        out.append(np.median(np.abs(x - np.median(x))))
    return np.asarray(out, float)


class VehicleScore:
    """One candidate's scores. ``criterion`` (minimised): minus the innovation log-likelihood
    per pseudorange row ("likelihood"), or the withheld satellites' median deviation [m]
    (:func:`withheld_deviation`) averaged over the epochs of every start and fold, with ``se``
    its standard error ("withheld-satellites"); ``per_start`` the log-likelihood or the mean
    deviation of each start; beside them the innovation log-likelihood per update of the rows
    the filter used."""

    def __init__(self, criterion, se, ll_per_update, per_start, epochs, error=None, rows=0):
        self.criterion, self.se, self.ll_per_update = criterion, se, ll_per_update
        self.per_start, self.epochs, self.error, self.rows = per_start, epochs, error, rows

    def as_dict(self) -> dict:
        return {"criterion": self.criterion, "criterion_se": self.se,
                "innovation_ll_per_update": self.ll_per_update, "per_start": self.per_start,
                "epochs_scored": self.epochs, "rows_scored": self.rows, "error": self.error}


def target_method(ds, method: str | None) -> str:
    """The method tuned: the one named, else the first epoch mixture (it uses the alignment's
    mixture and bands), else the first."""
    from ...errors import ArgumentError
    names = [m.name for m in ds.methods]
    if method is not None:
        if method not in names:
            raise ArgumentError(f"no method '{method}' in the dataset (it has {', '.join(names)})", argument="method")
        return method
    for m in ds.methods:
        if m.estimator == "epoch-mixture":
            return m.name
    return names[0]



def _blocks(starts, duration: float, score_after: float) -> int:
    """Roughly independent 10 s blocks the criterion sums over (the spread's unit): the rows
    of one epoch, and of neighbouring epochs, share the state's error and the LOS errors'
    correlation."""
    return max(1, int(sum(max(duration - s - score_after, 0.0) for s in starts) // 10.0))


def _criterion_text(criterion: str, starts) -> str:
    if criterion == "likelihood":
        return f"innovation log-likelihood over {len(starts)} starts"
    return f"withheld satellites' deviation over {len(starts)} starts x 2 folds"


def record_searched(searched, curves: dict, cur_doc, chosen: dict, not_tuned: dict, criterion: str, starts,
                    n_blocks: int, given: dict) -> None:
    """Each searched key's value in ``cur_doc``, how it was found and its spread into ``chosen``
    (a key the budget never reached into ``not_tuned``), for the tuners that run the whole
    pipeline from several ``starts`` (this module's and :mod:`.raw_gnss`)."""
    from . import _spread, _value_text
    from .parameters import get_value
    for p in searched:
        curve = curves.get(p.name, [])
        if len(curve) < 2:
            not_tuned[p.name] = "the budget ran out before the search reached it: the file's value kept"
            continue
        chosen[p.name] = {"value": _value_text(p, get_value(cur_doc, p)),
                          "how": f"{_criterion_text(criterion, starts)} ({len(curve)} values tried along this key)",
                          "spread": _spread(p, curve, n_blocks if given.get("criterion_se") is None
                                            else 2.0 / max(given["criterion_se"], 1e-9)),
                          "curve": [list(c) for c in curve]}


def tune_vehicle(*, text: str, stripped: str, source: str, ds, out, data, data_folder, journal, budget: int,
                 workers, scheduler, fix, method, progress: bool, header: dict, criterion: str = "likelihood"):
    """:func:`mixnav.tune` on an odometry + pseudorange dataset (module docstring). Returns the
    :class:`~mixnav.experiment.tuning.TuneResult` (its files written by the caller)."""
    from ...errors import ArgumentError
    from . import TuneResult, _data_dir_from, _write_tuned
    from .scoring import Scorer
    from .search import MIN_GAIN, coordinate_search
    unknown = [k for k in fix if k not in vehicle_keys()]
    if unknown:
        raise ArgumentError(f"unknown key(s) {', '.join(unknown)} for an odometry + pseudorange dataset; tunable: "
                            f"{', '.join(vehicle_keys())}", argument="fix")
    if criterion not in CRITERIA:
        raise ArgumentError(f"must be one of {', '.join(CRITERIA)} for an odometry + pseudorange dataset, got "
                            f"{criterion!r}", argument="criterion")
    target = target_method(ds, method)
    local = VehicleEvaluator(stripped, source, data, target, [], SCORE_AFTER)
    duration = local.duration_s
    starts = starts_for(duration, criterion)
    if not starts:
        raise ArgumentError(f"the recording has {duration:.0f} s of odometry; tuning needs at least "
                            f"{SCORE_AFTER + MIN_SCORED:g} s ({SCORE_AFTER:g} s for the longest alignment window, "
                            f"{MIN_SCORED:g} s scored after it)", argument="dataset")
    setup = ("mixnav.experiment.tuning.vehicle:VehicleEvaluator", stripped, source,
             None if data is None else str(data), target, starts, SCORE_AFTER, criterion)
    scorer = Scorer(setup, journal, workers, scheduler, progress, budget,
                    len(starts) * RUNS_PER_START[criterion])
    n_blocks = _blocks(starts, duration, SCORE_AFTER)
    chosen, not_tuned, evaluations, curves = {}, {}, [], {}
    params = vehicle_parameters()
    for p in params:
        if p.name in fix:
            not_tuned[p.name] = "fixed by the user (--fix)"
    if CN0_EDGES in fix:
        not_tuned[CN0_EDGES] = "fixed by the user (--fix)"
    searched = [p for p in params if p.name not in fix]
    try:
        doc = tomlkit.parse(stripped)
        (given,) = scorer.score([tomlkit.dumps(doc)])
        evaluations.append({"changed": "the file as given", "score": given})
        cur_doc, cur = doc, given
        first = [p for p in searched if p.name == "alignment.window"]
        rest = [p for p in searched if p.name != "alignment.window"]
        cur_doc, cur, curves = coordinate_search(cur_doc, cur, first, scorer, evaluations, grids=("coarse",),
                                                 curves=curves)
        edges_curve: list = []
        cands = edge_candidates(local.inputs.epochs.cn0)

        def scan_edges(cur_doc, cur, visit: int):
            """Every band-edge candidate from ``cur_doc``; the best kept when it beats ``cur``."""
            if CN0_EDGES in fix or scorer.left() <= 0:
                return cur_doc, cur
            if len(cands) < 2:
                not_tuned[CN0_EDGES] = "fewer than 20 rows with a C/N0: no band edges to scan"
                return cur_doc, cur
            texts = []
            for _, e in cands:
                d = tomlkit.parse(tomlkit.dumps(cur_doc))
                set_edges(d, e, target)
                texts.append(tomlkit.dumps(d))
            best = None
            for (name, e), t_, sc in zip(cands, texts, scorer.score(texts)):
                if sc is None:
                    continue
                evaluations.append({"changed": f"{CN0_EDGES} = {name} {e}", "score": sc})
                edges_curve.append((name, float(len(e)), sc["criterion"], sc["innovation_ll_per_update"], visit))
                if sc["criterion"] < (cur["criterion"] - MIN_GAIN if best is None else best[2]["criterion"]):
                    best = (name, t_, sc, e)
            if best is not None:
                cur_doc, cur = tomlkit.parse(best[1]), best[2]
            last = [c for c in edges_curve if c[4] == visit]
            tol = given.get("criterion_se") or 2.0 / n_blocks
            ok = [c[0] for c in last if c[2] <= min(x[2] for x in last) + tol]
            chosen[CN0_EDGES] = {"value": f"{get_edges(cur_doc)} dB-Hz", "spread": ", ".join(ok) or None,
                                 "how": f"{_criterion_text(criterion, starts)}, {len(edges_curve)} candidates in "
                                        f"{visit + 1} scan(s) (no bands and the recording's own C/N0 K-quantiles, "
                                        "rounded to whole dB-Hz)",
                                 "curve": [list(c) for c in edges_curve]}
            return cur_doc, cur

        cur_doc, cur = scan_edges(cur_doc, cur, 0)
        # the window again on the coarse grid, now with the bands (benchmarks/smartloc_choose_settings.py's
        # third stage): the window the first visit chose without bands is not the one with them
        # (smartLoc: 40 s without bands, 20 s with the octiles), and the fine grid moves it 2.5 s only
        cur_doc, cur, curves = coordinate_search(cur_doc, cur, first, scorer, evaluations, grids=("coarse",),
                                                 curves=curves)
        cur_doc, cur, curves = coordinate_search(cur_doc, cur, rest, scorer, evaluations, grids=("coarse",),
                                                 curves=curves)
        # the second pass: the band edges scanned again from where the first left the others, then
        # the fine grid over every key
        cur_doc, cur = scan_edges(cur_doc, cur, 1)
        cur_doc, cur, curves = coordinate_search(cur_doc, cur, searched, scorer, evaluations, grids=("fine",),
                                                 curves=curves)
        record_searched(searched, curves, cur_doc, chosen, not_tuned, criterion, starts, n_blocks, given)
    finally:
        scorer.close()
    not_tuned["correlation time of the LOS errors"] = (
        "measured by the track alignment on its window (lag-one correlation per satellite), not searched")
    tuned_text = _write_tuned(text, cur_doc, {k: v for k, v in chosen.items() if k != CN0_EDGES},
                              [p for p in searched if p.name in chosen])
    if CN0_EDGES in chosen:
        tdoc = tomlkit.parse(tuned_text)
        c = chosen[CN0_EDGES]
        set_edges(tdoc, get_edges(cur_doc), target, comment=f"mixnav tune: {c['how']}")
        tuned_text = tomlkit.dumps(tdoc)
    tuned_text = _data_dir_from(tuned_text, ds.dataset.data_dir, data_folder, out)
    result = TuneResult(tuned_text=tuned_text, chosen=chosen, given=given, tuned=cur, evaluations=evaluations,
                        not_tuned=not_tuned, runs=scorer.runs, out=out)
    header.update({"method": target, "criterion_kind": criterion, "starts_s": starts,
                   "score_after_s": SCORE_AFTER, "evaluations_spent": len(scorer.seen), "filter_runs": scorer.runs,
                   "independent_blocks": n_blocks})
    return result
