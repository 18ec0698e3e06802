"""The ``gnss-raw`` pipeline: epoch-by-epoch SPP of raw GNSS (an Android log or a RINEX
observation file) and the constant-velocity filters started from it
(:mod:`mixnav.experiment.spp_process`, steps in its docstring), scored against a surveyed
point or a moving reference (:mod:`mixnav.experiment.raw_reference`)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ...config.raw_gnss_schema import RawGnssDataset
from ..spp_process import (FilterInputs, SppOutput, filter_inputs, method_metrics, raw_tables, read_raw,
                           run_filter_methods, solve_raw, solve_spp, write_raw)

__all__ = ["load", "run", "spp", "filters", "tables", "metrics", "truth", "write", "with_start"]


def load(ds: RawGnssDataset, source: str, folder: Path) -> tuple:
    """``(observations, ephemeris, read time [s])``."""
    return read_raw(ds, source, folder)


def run(ds: RawGnssDataset, source: str, folder: Path, inputs: tuple, seed: int = 0) -> SppOutput:
    """SPP of every epoch (plain, robust) and the filter methods (``seed``: the engine's stream)."""
    obs, eph, read_time = inputs
    return solve_raw(ds, source, folder, obs, eph, read_time, seed)


def spp(ds: RawGnssDataset, source: str, folder: Path, inputs: tuple) -> tuple[SppOutput, FilterInputs]:
    """The part of :func:`run` no filter setting changes: the SPP (plain, robust), and the
    filters' corrected pseudoranges; :func:`filters` runs the filters on them."""
    obs, eph, read_time = inputs
    po = solve_spp(ds, source, folder, obs, eph, read_time)
    return po, filter_inputs(po)


def filters(stage: tuple[SppOutput, FilterInputs], ds: RawGnssDataset, seed: int = 0) -> SppOutput:
    """:func:`run` of ``ds`` from the :func:`spp` stage of a dataset with the same
    ``[raw_gnss]``, references, ``wls`` methods and ``motion.clock_jump`` (``ds`` differs in
    its filter settings, ``[motion]`` and its filter methods only): the same output, bitwise,
    without the SPP."""
    from dataclasses import replace
    base, prepared = stage
    po = replace(base, dataset=ds, results={}, checks={}, filter_time_s=0.0)
    run_filter_methods(po, seed, prepared)
    return po


def tables(po: SppOutput) -> dict[str, pd.DataFrame]:
    """Every method's table, in the order of ``[[methods]]``."""
    return raw_tables(po)


def metrics(po: SppOutput, tables: dict[str, pd.DataFrame]) -> dict[str, dict]:
    """Every method's metrics against the reference point or the moving reference."""
    return {name: method_metrics(po, name, t) for name, t in tables.items()}


def truth(po: SppOutput) -> pd.DataFrame | None:
    """The moving reference (``[reference]``: time_s on the tables' axis, lat_deg, lon_deg,
    height_m), or None (a surveyed point, in the tables' error columns, or no reference)."""
    if po.reference is None:
        return None
    from ..outputs import lla_frame
    return lla_frame(po.reference.trajectory.time, po.reference.trajectory.lla)


write = write_raw


def with_start(ds: RawGnssDataset, start: float) -> RawGnssDataset:
    """The dataset with its filters started at the first SPP fix at or after ``start`` [s since
    the first epoch] (``[motion] start``: the start sweep, :mod:`mixnav.experiment.sweep`)."""
    return ds.model_copy(update={"motion": ds.motion.model_copy(update={"start": float(start)})})

