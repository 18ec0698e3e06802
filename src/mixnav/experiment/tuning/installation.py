"""The installation mixnav estimates as states, written back into the file when the criterion agrees.

The tuned method is run once on the span with the antenna lever-arm correction
(``estimate = ["gnss_lever"]``) and, when it has NHC or odometer aiding, the vehicle mounting
(``"mounting"``: pitch and yaw) as extra states; the final causal estimate (every fix up to
the span's end used) and its sigma are the proposal. The proposal is written into a copy of
the file (``installation.antenna_position`` plus the correction; ``aiding.vehicle_mounting``
plus the pitch and yaw), each component only when it is beyond :data:`SIGNIFICANT_Z` of its
own sigma, and kept only when the cross-validation criterion improves, so an estimate that is
not significant, or that the data cannot use, leaves the file as it was.

The estimate is judged *cross-fitted* (:func:`cross_fitted_score`): each fold's withheld fixes
score a file whose installation was estimated without them. An estimate made from every fix
of the span has seen the withheld ones, and the criterion then rewards it for fitting its own
truth (on drive-0708's first half a -0.56 deg mounting yaw, 2.3 of its sigmas, was kept that
way for a gain of 0.014 in a criterion whose standard error is 0.54; cross-fitted, the gain was
the same there, and the significance rule is what leaves that file as it was).
"""

from __future__ import annotations

import numpy as np
import tomlkit

from ... import units as u
from .parameters import Parameter, get_value, set_value

ANTENNA = Parameter("installation.antenna_position", ("installation", "antenna_position"), u.LENGTH, "m", "shift",
                    (), (), -100.0, 100.0, default=(0.0, 0.0, 0.0), about="antenna position in the body frame")
MOUNTING = Parameter("aiding.vehicle_mounting", ("aiding", "vehicle_mounting"), u.ANGLE, "deg", "shift", (), (),
                     -np.pi, np.pi, default=(0.0, 0.0, 0.0), about="roll, pitch, yaw of the IMU body in the vehicle")


#: a component of the estimated correction is written only beyond this many of its own sigmas
#: (five components are tested at once, and the filter's sigmas are those of a tuned, not a
#: true, model: a 2-sigma correction is what half a drive gives by chance)
SIGNIFICANT_Z = 3.0


def proposal(evaluator, doc_text: str, withheld=(), mask=None):
    """``(document with the estimates written in, {key: (value text, how)}, mask, {key: how}
    of the keys with no component written)`` or None when the method cannot estimate them (not
    a loose EKF, or no estimate came out).

    Only the components of the correction (antenna x, y, z; mounting pitch, yaw) beyond
    :data:`SIGNIFICANT_Z` of their final causal sigmas are written (``mask``, five booleans:
    which ones, decided by the caller instead: a fold's run of :func:`cross_fitted_score` writes
    the components the whole span's run found). ``withheld``: windows [s] whose fixes the
    estimating run does not use (a fold's)."""
    ds = evaluator.dataset(doc_text)
    if not ds.methods or getattr(ds.methods[0], "type", None) != "loose-ekf":
        return None
    m = ds.methods[0]
    want = ["gnss_lever"] + (["mounting"] if {"nhc", "odometer"} & set(m.aiding or ()) else [])
    ds = ds.model_copy(update={"methods": [m.model_copy(update={"estimate": sorted(set(m.estimate or ()) | set(want))})]})
    po = evaluator.run(ds, list(withheld))
    res = po.results.get(m.name)
    if res is None or "gnss_lever" not in res.estimates or not len(res.estimates["gnss_lever"]):
        return None
    doc = tomlkit.parse(doc_text)
    notes = {}
    dl = np.asarray(res.estimates["gnss_lever"][-1], float)
    sl = np.asarray(res.sigma[-1][res.layout.slice("gnss_lever")], float)
    mounted = "mounting" in res.estimates and len(res.estimates["mounting"]) and "aiding" in doc
    dm = np.asarray(res.estimates["mounting"][-1], float) if mounted else np.zeros(2)   # pitch, yaw [rad]
    sm = np.asarray(res.sigma[-1][res.layout.slice("mounting")], float) if mounted else np.ones(2)
    if mask is None:
        mask = np.r_[np.abs(dl) > SIGNIFICANT_Z * sl, (np.abs(dm) > SIGNIFICANT_Z * sm) & bool(mounted)]
    mask = np.asarray(mask, bool)
    ant = get_value(doc, ANTENNA) + np.where(mask[:3], dl, 0.0)
    ratio = lambda d, s: ", ".join(f"{x / y:+.1f}" for x, y in zip(d, s))   # noqa: E731
    rule = f"written where beyond {SIGNIFICANT_Z:g}"
    unwritten = {}
    how = ("estimated as a state (gnss_lever) over the span, final causal estimate; correction "
           f"[{', '.join(f'{x:+.3f}' for x in dl)}] +- [{', '.join(f'{x:.3f}' for x in sl)}] m "
           f"([{ratio(dl, sl)}] sigmas; {rule})")
    if mask[:3].any():
        set_value(doc, ANTENNA, ant)
        notes[ANTENNA.name] = (f"[{', '.join(f'{x:.3f}' for x in ant)}] m", how)
    else:
        unwritten[ANTENNA.name] = how
    if mounted:
        how = ("estimated as states (mounting pitch, yaw) over the span, final causal estimate; "
               f"correction [{np.degrees(dm[0]):+.3f}, {np.degrees(dm[1]):+.3f}] +- "
               f"[{np.degrees(sm[0]):.3f}, {np.degrees(sm[1]):.3f}] deg ([{ratio(dm, sm)}] sigmas; {rule})")
        if mask[3:].any():
            mount = get_value(doc, MOUNTING)
            mount[1:3] += np.where(mask[3:], dm, 0.0)
            set_value(doc, MOUNTING, mount)
            notes[MOUNTING.name] = (f"[{', '.join(f'{np.degrees(x):.3f}' for x in mount)}] deg", how)
        else:
            unwritten[MOUNTING.name] = how
    return doc, notes, mask, unwritten


def cross_fitted_part(evaluator, doc_text: str, k: int, mask, keep_as_given=()):
    """Fold ``k`` of :func:`cross_fitted_score`: the installation estimated with fold k's windows
    withheld, written into ``doc_text`` (``mask``: the components, the whole span's; the keys
    ``keep_as_given`` put back), and fold k's run of that file scored
    (:meth:`~.criterion.Evaluator.fold_part`); an error text when it cannot be estimated."""
    prop = proposal(evaluator, doc_text, withheld=evaluator.windows[k], mask=mask)
    if prop is None:
        return "no installation estimate came out of the fold's run"
    return evaluator.fold_part(tomlkit.dumps(kept_as_given(prop[0], doc_text, keep_as_given)), k)


def cross_fitted_task(setup: tuple, doc_text: str, k: int, mask, keep_as_given) -> tuple:
    """``(k, cross_fitted_part(...))`` on a worker (its evaluator built once per process from ``setup``,
    :mod:`.scoring`)."""
    from .scoring import _evaluator
    return k, cross_fitted_part(_evaluator(setup), doc_text, k, mask, keep_as_given)


def cross_fitted_score(evaluator, doc_text: str, mask, keep_as_given=(), scorer=None):
    """The criterion of "estimate the installation, then predict": fold k's withheld windows
    scored by the file whose installation was estimated with them withheld too (every fold's
    estimate from the other folds' fixes), as a :class:`~.criterion.Score` (failed, with the
    error, when a fold's run cannot estimate it). ``mask``: the components written
    (:func:`proposal`'s, from the whole span). ``keep_as_given``: keys (:data:`ANTENNA`,
    :data:`MOUNTING` names) put back to ``doc_text``'s values (fixed by the user). ``scorer``:
    the folds run on its workers (:meth:`~.scoring.Scorer.map`), else here."""
    from .criterion import combined
    n = len(evaluator.windows)
    if scorer is not None:
        done = scorer.map(cross_fitted_task, [(doc_text, k, [bool(x) for x in mask], tuple(keep_as_given))
                                              for k in range(n)])
        parts = [part for _, part in sorted(done, key=lambda kp: kp[0])]   # they come as they finish
    else:
        parts = [cross_fitted_part(evaluator, doc_text, k, mask, keep_as_given) for k in range(n)]
    return combined(parts)


def kept_as_given(doc, given_text: str, keys):
    """``doc`` with ``keys`` put back to ``given_text``'s values."""
    given = tomlkit.parse(given_text)
    for p in (ANTENNA, MOUNTING):
        if p.name in keys and get_value(given, p) is not None:
            set_value(doc, p, get_value(given, p))
    return doc
