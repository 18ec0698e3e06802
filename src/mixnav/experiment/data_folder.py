"""The data folder of a dataset config (every pipeline reads its files from it)."""

from __future__ import annotations

import os
from pathlib import Path

from ..config.dataset_schema import Dataset
from ..errors import DataError


#: the checkout this module is in (src/mixnav/experiment/data_folder.py -> its root), where
#: the shipped configs' data_dir (../shared/data) is relative to
_REPOSITORY = Path(__file__).resolve().parents[3]


def find_data_dir(ds: Dataset, data: str | None, source: str) -> Path:
    """The data folder: ``--data``, else the config's ``data_dir`` relative to
    the working directory, to the folder of the config file, or to the
    repository (for the shipped configs); ``$MIXNAV_DATA/<name>`` last."""
    if data is not None:
        p = Path(data)
        if not p.is_dir():
            raise DataError(f"data folder given with --data does not exist: {p}")
        return p
    d = Path(ds.dataset.data_dir)
    tried = []
    candidates = [d] if d.is_absolute() else [Path.cwd() / d, Path(source).parent / d,
                                               _REPOSITORY / d]
    if "MIXNAV_DATA" in os.environ:
        candidates.append(Path(os.environ["MIXNAV_DATA"]) / d.name)
    for c in candidates:
        tried.append(str(c))
        if c.is_dir():
            return c
    raise DataError(f"data folder '{ds.dataset.data_dir}' not found (tried {', '.join(tried)}); "
                    "give it with --data DIR", file=source)
