"""The ``odometry-gnss`` pipeline (smartLoc): dead reckoning from wheel speed and yaw rate
corrected by pseudoranges, every method, scored against the reference
(:mod:`mixnav.experiment.vehicle_process`, steps in its docstring)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ...config.vehicle_schema import VehicleDataset
from ..metrics import method_metrics
from ..outputs import lla_frame
from ..vehicle_process import VehicleInputs, VehicleOutput, read_vehicle, run_vehicle, vehicle_tables, write_vehicle

__all__ = ["load", "run", "tables", "metrics", "truth", "write", "with_start"]


def load(ds: VehicleDataset, source: str, folder: Path) -> VehicleInputs:
    """The odometry, pseudorange and reference files."""
    return read_vehicle(ds, source, folder)


def run(ds: VehicleDataset, source: str, folder: Path, inputs: VehicleInputs, seed: int = 0) -> VehicleOutput:
    """Alignment and every method on the dead-reckoning model (``seed``: the engine's stream)."""
    return run_vehicle(ds, source, folder, inputs, seed)


def tables(vo: VehicleOutput) -> dict[str, pd.DataFrame]:
    """Every method's solution table (errors against the reference when there is one)."""
    return vehicle_tables(vo)


def metrics(vo: VehicleOutput, tables: dict[str, pd.DataFrame]) -> dict[str, dict]:
    """Every method's metrics (no GNSS withheld)."""
    return {name: method_metrics(res, tables[name], []) for name, res in vo.results.items()}


def truth(vo: VehicleOutput) -> pd.DataFrame | None:
    """The reference trajectory as a table (None without one)."""
    return None if vo.reference is None else lla_frame(vo.reference.time, vo.reference.lla)


write = write_vehicle


def with_start(ds: VehicleDataset, start: float) -> VehicleDataset:
    """The dataset run as if its recording began ``start`` [s] after its first odometry
    sample (``[alignment] start``: the start sweep, :mod:`mixnav.experiment.sweep`)."""
    return ds.model_copy(update={"alignment": ds.alignment.model_copy(update={"start": float(start)})})

