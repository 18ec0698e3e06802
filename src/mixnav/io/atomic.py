"""Atomic writers: a results file is either complete or absent, never half written.

Each writer writes a temporary file in the target's folder, flushes and
fsyncs it, then renames it over the target (``os.replace`` is atomic on
POSIX and Windows); on any error the temporary file is removed and the target
is left as it was.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def _atomic(path, mode="wb"):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as fh:
            yield fh, tmp
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def atomic_write_bytes(path, data: bytes) -> None:
    with _atomic(path, "wb") as (fh, _):
        fh.write(data)


def atomic_write_text(path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def _find_nan(obj, where="$"):
    if isinstance(obj, float) and not math.isfinite(obj):
        return where
    if isinstance(obj, dict):
        for k, v in obj.items():
            hit = _find_nan(v, f"{where}.{k}")
            if hit:
                return hit
    if isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            hit = _find_nan(v, f"{where}[{i}]")
            if hit:
                return hit
    return None


def atomic_write_json(path, obj) -> None:
    """Write JSON; a NaN or infinity anywhere is an error naming its key path."""
    bad = _find_nan(obj)
    if bad:
        raise ValueError(f"refusing to write {path}: non-finite number at {bad}")
    atomic_write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


def atomic_write_dataframe(path, df) -> None:
    """CSV or Parquet by the suffix of ``path``."""
    path = Path(path)
    if path.suffix == ".csv":
        atomic_write_text(path, df.to_csv(index=False, float_format="%.10g"))
    elif path.suffix == ".parquet":
        with _atomic(path, "wb") as (fh, _):
            df.to_parquet(fh, index=False)
    else:
        raise ValueError(f"unknown table format '{path.suffix}' for {path}; use .csv or .parquet")
