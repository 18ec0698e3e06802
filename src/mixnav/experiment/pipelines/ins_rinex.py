"""The ``ins-gnss`` pipeline with a RINEX observation file (``[raw_gnss]``): the tightly
coupled INS on pseudoranges and Doppler (of every system of ``[raw_gnss] systems``), the loose methods on the SPP fixes
(:mod:`mixnav.experiment.rinex_ins`, steps in its docstring). Tables, metrics and outputs
are those of every INS dataset (:mod:`mixnav.experiment.pipelines.ins_fixes`)."""

from __future__ import annotations

from pathlib import Path

from ...config.dataset_schema import Dataset
from ..ins_common import ProcessOutput
from ..rinex_ins import RinexInputs, read_rinex_ins, run_rinex_ins
from .ins_fixes import metrics, tables, truth, write

__all__ = ["load", "run", "tables", "metrics", "truth", "write"]


def load(ds: Dataset, source: str, folder: Path) -> RinexInputs:
    """The IMU, observation, navigation and reference files."""
    return read_rinex_ins(ds, source, folder)


def run(ds: Dataset, source: str, folder: Path, inputs: RinexInputs, seed: int = 0) -> ProcessOutput:
    """SPP, alignment, the tight and loose methods (``seed``: unused, the methods' streams are their own)."""
    return run_rinex_ins(ds, source, folder, inputs)
