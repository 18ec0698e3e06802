"""The search: coordinate-wise, on a grid of moves per key, in passes.

Each key in turn is moved by every step of its grid (factors for scale parameters, offsets
for times, :class:`~.parameters.Parameter`), the candidates are scored together (in
parallel), and the best replaces the current setting when it lowers the criterion. A pass
uses the coarse grid (x0.25 ... x4; a winner at the grid's edge is followed one step
further) or the fine one (x0.71, x1.41) about the values the passes before it left. The IMU
tuner (:func:`mixnav.experiment.tuning.tune`) runs the coarse grid twice, then the fine one:
one coarse pass moves each key once, with the keys after it still at the data stage's start,
so the timing keys, visited first, are set against noise scales that have not moved yet,
and each noise scale against the keys after it still unmoved. On drive-0708 the second pass
moved the timing keys again on both halves and on the whole drive, and the innovation
likelihood they follow rose on all three; the cross-validation's best fell by 1.1 standard
errors on the second half and rose by 0.05 and 0.7 on the first half and the whole drive (the
shipped file, at a budget that held the pass; benchmarks/results/tune_drive0708_variants.md,
"Stop 54": the search is not monotone in
either criterion, each key following its own). The second coarse pass is dropped when the
first moved nothing, and when the budget cannot hold as many evaluations as the first pass
spent besides the fine pass and the reserves.

Why not a black-box optimiser: the criterion is smooth in the logarithm of each scale and
the keys interact weakly (noise densities against the GNSS sigma floor, the two NHC sigmas;
weakly, not negligibly: hence the second coarse pass),
so a coordinate search with the candidates of a key run side by side uses two cores fully
and reaches a flat optimum in 40-60 evaluations; every evaluation is also a point of the
report's criterion-against-parameter curves. Measured (benchmarks/tune_search.py,
benchmarks/results/tune_search.md): on drive-0708's first half with 80 evaluations it reached
a lower criterion than scipy's Powell and Nelder-Mead and optuna's TPE. Then
:func:`conservative_pass`.
"""

from __future__ import annotations

import math

import numpy as np
import tomlkit

from .parameters import Parameter, get_value, moved, set_value

#: a move is kept only when it lowers the mean NLPD by more than this: where the criterion is
#: flat in a key (a bias walk swamped by a larger white noise) the file's value stays rather
#: than a grid edge chosen by rounding
MIN_GAIN = 1e-3


def _with(doc, p: Parameter, value) -> str:
    """``doc`` with ``p`` at ``value`` (and the keys it carries moved with it, clipped)."""
    d = tomlkit.parse(tomlkit.dumps(doc))
    if p.carries:
        new, old = float(np.atleast_1d(value)[0]), float(get_value(d, p)[0])
        for q, coefficient in p.carries:
            v = get_value(d, q)
            # not clipped to the carried key's search bounds: the drift's pivot must hold however
            # far the span's centre is from the stamps' start (an hour's recording at 600 ppm)
            v = v + coefficient * (new - old) if p.kind == "shift" else v * (new / old) ** coefficient
            set_value(d, q, v)
    set_value(d, p, value)
    return tomlkit.dumps(d)


def _shown(p: Parameter, value) -> float:
    """The scalar a curve point is drawn at: the element moved, or the first axis of a vector."""
    value = np.atleast_1d(value)
    i = p.index if p.index is not None and p.index < len(value) else 0   # a one-value key: its value
    return float(value[i] / p.scale)


def coordinate_search(doc, cur: dict, params: list[Parameter], scorer, evaluations: list,
                      grids=("coarse", "fine"), curves: dict | None = None, reserve: int = 0):
    """Search ``params`` from ``doc`` (scored ``cur``) with ``scorer`` (its budget, less
    ``reserve`` evaluations kept for later, bounds the evaluations), one pass per grid of
    ``grids``. Returns the best document, its score and per key the evaluated points
    ``(label, shown value, nlpd, innovation log-likelihood per update, visit)`` (added to
    ``curves`` when given; ``visit`` counts the search's visits of the key: the points of one
    visit differ in that key only)."""
    curves = {p.name: [] for p in params} if curves is None else curves
    for p in params:
        curves.setdefault(p.name, [])
    for grid in grids:
        for p in params:
            if scorer.left() <= reserve:
                return doc, cur, curves
            base = get_value(doc, p)
            _point(curves, p, "current", base, cur, new_visit=True)
            grid_steps = list(p.coarse if grid == "coarse" else p.fine)
            data = [s for s in p.data_steps if s not in grid_steps] if grid == "coarse" else []
            doc, cur, best_step = _try(doc, cur, p, base, grid_steps + data, scorer, evaluations, curves, reserve)
            if best_step is not None and best_step in data:
                # a move the data measured, beyond the grid's reach: the grid again about it
                base = get_value(doc, p)
                doc, cur, best_step = _try(doc, cur, p, base, grid_steps, scorer, evaluations, curves, reserve)
            if grid == "coarse" and best_step is not None and best_step in (min(grid_steps), max(grid_steps)):
                further = best_step * best_step if p.kind == "log" else 2 * best_step
                doc, cur, _ = _try(doc, cur, p, base, [further], scorer, evaluations, curves, reserve)
    return doc, cur, curves


def _point(curves: dict, p: Parameter, label: str, value, score: dict, new_visit: bool = False) -> None:
    """One evaluated point of key ``p`` in ``curves`` (see :func:`coordinate_search`)."""
    pts = curves.setdefault(p.name, [])
    visit = (pts[-1][4] if pts else -1) + (1 if new_visit or not pts else 0)
    pts.append((label, _shown(p, value), score["criterion"], score["innovation_ll_per_update"], visit))


#: a move along a key judged by the innovation likelihood is kept only when the log-likelihood
#: of the recording's updates (each counted once, though it is in most folds' runs) rises by
#: more than this: the likelihood-ratio test of one parameter at 1 % (chi-square(1) 99 % point
#: / 2), the updates counted as independent (lenient where they are correlated).
#: comma2k19-example1's half minute moved the IMU time offset by -0.1 s for a rise of 0.0031
#: per update, which made its outages ten times worse
INNOVATION_LR = 3.3174


def gain_needed(p: Parameter, score: dict) -> float:
    """How much :func:`judged` (per update) must fall along ``p`` from ``score`` for a move to be
    kept: :data:`MIN_GAIN`, or for a key judged by the innovation likelihood :data:`INNOVATION_LR`
    over the score's distinct updates (its ``n_updates`` for a journal written before they were
    counted), whichever is larger."""
    if p.judged_by != "innovation":
        return MIN_GAIN
    n = score.get("n_distinct_updates") or score.get("n_updates")
    return max(MIN_GAIN, INNOVATION_LR / n) if n else MIN_GAIN


def judged(p: Parameter, score: dict) -> float:
    """What the search minimises along ``p`` (:attr:`Parameter.judged_by`): the score's
    criterion, or minus its innovation log-likelihood per update (a run without one: +inf)."""
    if p.judged_by == "innovation":
        ll = score.get("innovation_ll_per_update")
        return -float(ll) if ll is not None and math.isfinite(ll) else math.inf
    return score["criterion"]


def _try(doc, cur, p, base, steps, scorer, evaluations, curves, reserve: int = 0):
    """Score ``base`` moved by each step (as many as the budget less ``reserve`` allows); keep
    the best if it beats ``cur``. Returns the (possibly new) document, its score and the
    winning step (None: none won)."""
    values = [moved(p, base, s) for s in steps]
    keep = [(s, v) for s, v in zip(steps, values) if not (v == base).all()][:max(scorer.left() - reserve, 0)]
    if not keep:
        return doc, cur, None
    texts = [_with(doc, p, v) for _, v in keep]
    scores = scorer.score(texts)
    best, best_step = None, None
    for (s, v), text, sc in zip(keep, texts, scores):
        if sc is None:        # beyond the budget
            continue
        evaluations.append({"changed": f"{p.name} x{s:g}" if p.kind == "log" else
                            f"{p.name} {s / p.scale:+g} {p.unit}",
                            "score": sc})
        _point(curves, p, f"{s:g}" if p.kind == "log" else f"{s / p.scale:+g}", v, sc)
        if judged(p, sc) < (judged(p, cur) - gain_needed(p, cur) if best is None else judged(p, best[1])):
            best, best_step = (text, sc), s
    if best is None:
        return doc, cur, None
    return tomlkit.parse(best[0]), best[1], best_step


#: the moves of the conservative pass per key: x2 as long as it is kept (at most
#: :data:`CONSERVATIVE_DOUBLINGS` times); when the first x2 is not, x1.41 once
CONSERVATIVE_STEPS = (2.0, 2.0 ** 0.5)
CONSERVATIVE_DOUBLINGS = 3
#: the keys it widens, in the order they get the bar: the constraint sigmas first, then the
#: process noises
CONSERVATIVE_KEYS = ("aiding.nhc.sigma[1]", "aiding.nhc.sigma[0]", "imu.errors.arw", "imu.errors.vrw",
                     "imu.errors.gyro_bias_walk", "imu.errors.accel_bias_walk")


def conservative_tolerance(best: dict, n_windows: int) -> float:
    """How far above the search's best the conservative pass may go, and within which the file
    as given is kept: one standard error of the best's criterion (the one-standard-error rule of
    cross-validation), the error measured from the spread of its withheld windows
    (:func:`.criterion.criterion_se`: the windows are the independent units), and never less
    than ``2 / n_windows``, a likelihood-ratio interval counting each window as one observation
    (also the bar when the score has no per-window values: a journal written before them).
    Why the floor: a standard error measured from a handful of windows can be small by chance
    (four windows give it three degrees of freedom), and then a gain far below what one
    window's worth of evidence can carry would move the file (comma2k19-example1's half minute:
    standard error 0.005 from 4 windows, the search's best 0.023 per fix below the file as
    given, and its outages on the other half twice as large)."""
    floor = 2.0 / max(n_windows, 1)
    se = best.get("criterion_se")
    return max(float(se), floor) if se is not None and se > 0 else floor


def conservative_pass(doc, cur: dict, params: list[Parameter], scorer, evaluations: list, tolerance: float,
                      curves: dict, reserve: int = 0):
    """Among the settings the criterion cannot tell from the best, take the most cautious.

    Each noise key in turn (:data:`CONSERVATIVE_KEYS`) is widened by x2 again and again (at
    most :data:`CONSERVATIVE_DOUBLINGS` times) while the criterion stays within ``tolerance``
    of the search's best; when the first x2 is already past it, by x1.41 once. The bar is
    fixed: widenings do not add up past it, and the keys earlier in the order get it first.
    ``tolerance`` is one standard error of the best's criterion, floored at 2 / n_windows
    (:func:`conservative_tolerance`).
    Why: a criterion minimised on one stretch of a drive over-fits it;
    benchmarks/results/tune_search.md found the files that pushed the criterion lowest the
    most overconfident on the other half (correlation -0.93 with the share of windows out of
    the NEES band). Preferring the widest setting inside the criterion's own spread is the
    one-standard-error rule of cross-validation, applied to noise scales (the widest, not the
    first widening inside it: one x2 per key was a cap of convenience)."""
    best = cur["criterion"]
    order = {k: i for i, k in enumerate(CONSERVATIVE_KEYS)}
    for p in sorted((q for q in params if q.name in order and q.kind == "log"), key=lambda q: order[q.name]):
        if scorer.left() <= reserve:     # before its "current" point: a visit of one point says nothing
            return doc, cur
        _point(curves, p, "current", get_value(doc, p), cur, new_visit=True)
        steps, doublings = list(CONSERVATIVE_STEPS), 0
        while steps:
            step = steps.pop(0)
            if scorer.left() <= reserve:
                return doc, cur
            value = moved(p, get_value(doc, p), step)
            text = _with(doc, p, value)
            (sc,) = scorer.score([text])
            if sc is None:
                return doc, cur
            evaluations.append({"changed": f"{p.name} x{step:g} (conservative pass)", "score": sc})
            _point(curves, p, f"{step:g}", value, sc)
            if sc["criterion"] > best + tolerance:
                continue             # past the bar: x1.41 next if nothing was kept yet, else done
            doc, cur = tomlkit.parse(text), sc
            if step != CONSERVATIVE_STEPS[0]:
                break
            doublings += 1
            steps = [CONSERVATIVE_STEPS[0]] if doublings < CONSERVATIVE_DOUBLINGS else []
    return doc, cur
