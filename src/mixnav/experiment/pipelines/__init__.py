"""One pipeline per dataset kind, behind one dispatch table (:data:`PIPELINES`).

A pipeline is a module with

- ``load(ds, source, folder) -> inputs``: read the dataset's files (the readers registered
  for their formats, :mod:`mixnav.io.readers`), timed as ``read_time_s``;
- ``run(ds, source, folder, inputs, seed=0) -> output``: align and run every method (the
  output has ``dataset``, ``source``, ``results``);
- ``tables(output)``: method name -> solution table (docs/outputs.md);
- ``metrics(output, tables)``: method name -> its metrics;
- ``truth(output)``: the reference trajectory as a table, or None;
- ``write(out_dir, output, config_text=None, overwrite=False, sweeps=()) -> metrics.json's dict``
  (``sweeps``: :class:`~mixnav.experiment.sweep.SweepResult` s written beside);
- optionally ``with_start(ds, start) -> ds``: the dataset run as if it began at ``start`` [s]
  (the start sweep; kinds that start from their own data).

The CLI (``mixnav process``), the API (:func:`mixnav.process_dataset`,
``RunResult.write``) and :mod:`mixnav.experiment.process` find the pipeline here. A new
dataset kind inside mixnav is its pipeline module plus one line in :data:`PIPELINES` (and its
schema in :mod:`mixnav.config`); from outside mixnav (a plug-in, a notebook, a test) it is
one call, :func:`register_pipeline` (kind, module, schema), and nothing in mixnav is edited
(tests/test_pipelines.py adds a toy kind that way and processes it through the API and the
CLI).
"""

from __future__ import annotations

from types import ModuleType

from ...errors import ConfigError
from ..data_folder import find_data_dir
from . import gnss_raw, ins_fixes, ins_rinex, odometry_gnss

#: dataset kind (``ins-gnss`` split by its GNSS input: ``[gnss]`` fixes or ``[raw_gnss]``) -> pipeline
PIPELINES: dict[str, ModuleType] = {
    "ins-gnss": ins_fixes,
    "ins-gnss+raw-gnss": ins_rinex,
    "gnss-raw": gnss_raw,
    "odometry-gnss": odometry_gnss,
}


#: what a pipeline module must have (``with_start`` is optional)
PIPELINE_FUNCTIONS = ("load", "run", "tables", "metrics", "truth", "write")


def register_pipeline(kind: str, module, schema=None) -> None:
    """Add the dataset kind ``kind``: ``module`` (a module or any object with the functions of
    this package's docstring) as its pipeline, and ``schema`` (a pydantic model whose
    ``dataset`` has ``name``, ``kind`` and ``data_dir``) as what its files validate against
    (:func:`mixnav.config.loader.register_dataset_schema`; None: the kind's files are validated
    by a schema mixnav has already). A kind with a pipeline already is a ValueError; a
    module without one of :data:`PIPELINE_FUNCTIONS` is a TypeError naming them."""
    if kind in PIPELINES:
        raise ValueError(f"dataset kind '{kind}' has a pipeline already ({', '.join(PIPELINES)})")
    missing = [f for f in PIPELINE_FUNCTIONS if not callable(getattr(module, f, None))]
    if missing:
        raise TypeError(f"the pipeline of '{kind}' has no {', '.join(missing)} (a pipeline has "
                        f"{', '.join(PIPELINE_FUNCTIONS)}: mixnav.experiment.pipelines)")
    if schema is not None:
        from ...config.loader import register_dataset_schema
        register_dataset_schema(kind, schema)
    PIPELINES[kind] = module


def pipeline_key(ds) -> str:
    """The :data:`PIPELINES` key of a dataset config: its ``dataset.kind``, with ``+raw-gnss``
    for an ``ins-gnss`` dataset whose GNSS is a ``[raw_gnss]`` table (RINEX)."""
    kind = ds.dataset.kind
    if kind == "ins-gnss" and ds.raw_gnss is not None:
        return "ins-gnss+raw-gnss"
    return kind


def pipeline(ds, source: str | None = None) -> ModuleType:
    """The pipeline of a dataset config; a kind without one is a ConfigError naming
    ``dataset.kind`` and the kinds that have one."""
    key = pipeline_key(ds)
    try:
        return PIPELINES[key]
    except KeyError:
        raise ConfigError(f"no pipeline for dataset kind '{key}' (pipelines: {', '.join(PIPELINES)})",
                          file=source, key="dataset.kind") from None


def process(ds, source: str, data: str | None = None, seed: int = 0):
    """Find the data folder (``data``, else the config's ``data_dir``), load and run the
    dataset's pipeline; its output."""
    p = pipeline(ds, source)
    folder = find_data_dir(ds, data, source)
    return p.run(ds, source, folder, p.load(ds, source, folder), seed)
