"""The ``gnss-raw`` pipeline: epoch-by-epoch SPP of raw GNSS (an Android log or a RINEX
observation file) and the constant-velocity filters started from it
(:mod:`mixnav.experiment.spp_process`, steps in its docstring), scored against a surveyed
point or a moving reference (:mod:`mixnav.experiment.raw_reference`)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ...config.raw_gnss_schema import RawGnssDataset
from ..spp_process import SppOutput, method_metrics, raw_tables, read_raw, solve_raw, write_raw

__all__ = ["load", "run", "tables", "metrics", "truth", "write", "with_start"]


def load(ds: RawGnssDataset, source: str, folder: Path) -> tuple:
    """``(observations, ephemeris, read time [s])``."""
    return read_raw(ds, source, folder)


def run(ds: RawGnssDataset, source: str, folder: Path, inputs: tuple, seed: int = 0) -> SppOutput:
    """SPP of every epoch (plain, robust) and the filter methods (``seed``: the engine's stream)."""
    obs, eph, read_time = inputs
    return solve_raw(ds, source, folder, obs, eph, read_time, seed)


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

