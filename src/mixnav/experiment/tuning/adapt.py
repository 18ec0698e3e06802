"""A key's search fitted to the recording before it starts.

A few tuned keys need something only this recording can tell before the coordinate search
moves them: the scale a zero sigma floor is moved to (the fixes' own sigmas), the point the
IMU clock drift turns about (the tuning span's middle), a latency beyond the time offset's
grid (the turn rate against the fixes' course rate). Each such need is one function here,
registered under the key's name in :data:`ADAPTERS`; the driver (:func:`mixnav.tune`) passes
every key it searches through :func:`adapted`, so a new key with such a need touches this
file and :mod:`.parameters` only.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from .parameters import IMU_CLOCK_DRIFT, Parameter, ins_parameters, pivoted

IMU_TIME_OFFSET = "installation.imu_time_offset"


@dataclass
class Recording:
    """What an adapter may read of the recording and what it reports.

    Attributes
    ----------
    po : object or None
        The processed run of the file as given (``.imu``, ``.fixes``: the fixes the filter
        uses, never the file's own withheld windows, which are the user's evaluation).
    span : (float, float)
        The tuning span [s].
    fix : sequence of str
        The keys the user fixed (``--fix``).
    chosen, not_tuned : dict
        The driver's reports: an adapter that measured something says how in
        ``chosen[key]["data_how"]``, one that could not in ``not_tuned``.
    """

    po: object
    span: tuple
    fix: tuple | list = ()
    chosen: dict = field(default_factory=dict)
    not_tuned: dict = field(default_factory=dict)


def sigma_floor_from_fixes(p: Parameter, rec: Recording) -> Parameter:
    """``gnss.min_sigma`` moved from the fixes' own median horizontal sigma in the span when the
    file's floor is zero (the schema's default): the log grid then tries x2, x4 (x16) of it.
    From the 1 mm lower bound the candidates left RTK's 1 cm sigmas untouched: the key was never
    searched."""
    fx = rec.po.fixes
    sel = (fx.time >= rec.span[0]) & (fx.time <= rec.span[1])
    sig = np.asarray(fx.pos_sigma, float).reshape(len(fx.time), -1)[sel][:, :2]
    if not sig.size or not np.isfinite(sig).all():
        return p
    return replace(p, zero_from=float(np.clip(np.median(sig), p.lower, p.upper)))


def drift_about_span_middle(p: Parameter, rec: Recording) -> Parameter:
    """The IMU clock drift turned about the span's middle (it carries the time offset,
    :func:`.parameters.pivoted`) unless the user fixed the offset. From the stamps' start a
    drift step would move the whole span and be refused by the offset's misfit (the two keys
    are nearly one along the drive)."""
    if IMU_TIME_OFFSET in rec.fix:
        return p
    offset = next(q for q in ins_parameters() if q.name == IMU_TIME_OFFSET)
    return pivoted(p, offset, 0.5 * (rec.span[0] + rec.span[1]))


def offset_with_turn_rate_lag(p: Parameter, rec: Recording) -> Parameter:
    """The IMU time offset with the move the turn-rate cross-correlation measured
    (:func:`.data_stage.turn_rate_lag`) tried beside its coarse grid, when that move lies beyond
    the grid's reach (a logger's latency of half a second: from the grid's +-0.1 s steps the
    search would stop a few tenths short, and every key after it would absorb the rest). A lag
    within reach leaves the key as it is; a lag the data cannot show is said in ``not_tuned``."""
    from .data_stage import turn_rate_lag
    found = turn_rate_lag(rec.po.imu, rec.po.fixes, rec.span)
    if found[0] is None:
        rec.not_tuned[p.name + " (turn-rate lag)"] = found[1]
        return p
    lag, corr, pairs = found
    move = round(-lag, 3)
    if abs(move) <= max(abs(s) for s in p.coarse):
        return p
    rec.chosen.setdefault(p.name, {})["data_how"] = (
        f"the IMU's turn rate against the fixes' course rate peaks {lag:+.3f} s late (correlation {corr:.2f}, "
        f"{pairs} chord pairs): a move of {move:+g} s tried beside the grid")
    return replace(p, data_steps=(move,))


#: the adapters by key name; a key not named here is searched as :mod:`.parameters` defines it
ADAPTERS: dict[str, Callable[[Parameter, Recording], Parameter]] = {
    "gnss.min_sigma": sigma_floor_from_fixes,
    IMU_CLOCK_DRIFT.name: drift_about_span_middle,
    IMU_TIME_OFFSET: offset_with_turn_rate_lag,
}


def adapted(p: Parameter, rec: Recording) -> Parameter:
    """``p`` fitted to the recording by its adapter (:data:`ADAPTERS`), or ``p`` itself."""
    adapt = ADAPTERS.get(p.name)
    return p if adapt is None else adapt(p, rec)
