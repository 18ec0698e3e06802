"""``mixnav process``: run the methods of a dataset config on real recorded data.

The work is the dataset kind's pipeline's (:mod:`mixnav.experiment.pipelines`: one module
per kind, one dispatch table); these are the entry points by their long-standing names.
Times inside a run are seconds since the first IMU sample (the start of its first increment); the absolute time
of that origin (as the files give it) is ``time_origin_s`` in metrics.json.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from .data_folder import find_data_dir  # noqa: F401
from .ins_common import ProcessOutput, _shift, data_checks, gnss_section, initial_state, install  # noqa: F401
from .ins_common import read_imu, read_reference, run_ins_methods  # noqa: F401
from .pipelines import pipeline, process as _process
from .pipelines.ins_fixes import _corrupt, read_gnss, read_odometer, withheld_windows  # noqa: F401
from .pipelines.ins_fixes import tables as process_tables  # noqa: F401


def process(ds, source: str, data: str | None = None):
    """Read, align and filter a dataset with every configured method: the pipeline of its
    kind (:func:`mixnav.experiment.pipelines.process`). An ``ins-gnss`` dataset gives a
    ``ProcessOutput``; a ``gnss-raw`` one an ``SppOutput``
    (:mod:`mixnav.experiment.spp_process`), an ``odometry-gnss`` one a ``VehicleOutput``."""
    return _process(ds, source, data)


def write_process(out_dir: Path, po, config_text: str | None = None, overwrite: bool = False) -> dict:
    """Solutions, metrics, figures and report of a processed dataset, by its pipeline (the
    folder policy of :mod:`mixnav.io.outdir`)."""
    return pipeline(po.dataset).write(Path(out_dir), po, config_text, overwrite=overwrite)


def tables(po) -> dict[str, pd.DataFrame]:
    """Every method's solution table of a processed dataset, by its pipeline."""
    return pipeline(po.dataset).tables(po)
