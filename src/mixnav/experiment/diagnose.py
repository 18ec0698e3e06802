"""``mixnav diagnose``: the residual diagnostics of one column of a CSV or Parquet
file (:func:`mixnav.noise.diagnostics.diagnose`), written as ``diagnostics.json``
and figures into an output folder (docs/outputs.md)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import ArgumentError, DataError
from ..io.atomic import atomic_savefig, atomic_write_json
from ..io.outdir import check_out_dir, staged_output
from ..noise.diagnostics import FIGURE_FILES, MIN_SAMPLES, diagnose, figures

__all__ = ["diagnose_file"]

#: Q-Q points kept in diagnostics.json (the figure uses them all)
_JSON_QQ_POINTS = 1000


def _read_column(path: Path, column: str) -> np.ndarray:
    import pandas as pd

    src = str(path)
    if not path.is_file():
        raise DataError("no such file", file=src)
    suffix = path.suffix.lower()
    csv = suffix != ".parquet"
    try:
        if csv:
            # read as text so that a non-numeric cell can be quoted back to the user
            df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
        else:
            df = pd.read_parquet(path)
    except Exception as exc:   # malformed file: say so with the file name
        raise DataError(f"cannot read {'CSV' if csv else 'Parquet'} file: {exc}", file=src) from None
    if column not in df.columns:
        raise DataError(f"no column '{column}'; columns are: {', '.join(map(str, df.columns))}", file=src)
    raw = df[column]
    values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        i = int(bad[0])
        cell = raw.iloc[i]
        if isinstance(cell, str) and not cell.strip():
            what = "is empty (missing)"
        elif np.isinf(values[i]):
            what = f"is not finite: {cell!r}"
        elif not isinstance(cell, str) or cell.strip().lower() in ("nan", "na", "n/a", "null", "none"):
            what = "is NaN"
        else:
            what = f"is not a number: {cell!r}"
        more = f" ({bad.size} bad value(s) in all)" if bad.size > 1 else ""
        where = f"row {i}" + (f" (line {i + 2} of the file)" if csv else "")
        raise DataError(f"column '{column}', {where}: value {what}{more}", file=src,
                        line=i + 2 if csv else None)
    if values.size < MIN_SAMPLES:
        raise DataError(f"column '{column}' has {values.size} values; at least {MIN_SAMPLES} are needed",
                        file=src)
    return values


def _json_ready(result: dict) -> dict:
    """The result with Q-Q data thinned to at most 1000 evenly spaced quantiles."""
    out = dict(result)
    th, sa = result["qq"]["theoretical"], result["qq"]["sample"]
    if th.size > _JSON_QQ_POINTS:
        idx = np.unique(np.round(np.linspace(0, th.size - 1, _JSON_QQ_POINTS)).astype(int))
        out["qq"] = {"theoretical": th[idx], "sample": sa[idx], "thinned_from": int(th.size)}
    return out


def diagnose_file(path, column: str, out_dir, max_lag: int | None = None, n_components: int | None = None,
                  seed: int = 0, overwrite: bool = False) -> dict:
    """Diagnose one column of a CSV or Parquet file; write JSON and PNG figures.

    Parameters
    ----------
    path : str or PathLike
        ``.parquet`` is read as Parquet, anything else as CSV with a header.
    column : str
        Column name.
    out_dir : str or PathLike
        Created if missing; receives ``diagnostics.json`` and ``qq.png``,
        ``acf.png``, ``histogram.png`` (each written atomically).
    max_lag : int, optional
        Largest autocorrelation lag; default 50, clipped to the series length - 1 for a short
        series (as :func:`diagnose` clips it). Given explicitly it must be below the number of
        values: a larger one is an ArgumentError naming ``--max-lag`` (docs/validation.md),
        not clipped silently.
    n_components, seed
        As in :func:`diagnose`.

    Returns
    -------
    dict
        What was written to diagnostics.json: the :func:`diagnose` result
        (Q-Q data thinned to at most 1000 quantiles), plus ``source``
        {``file``, ``column``} and ``figures`` {name: file name}.

    Raises
    ------
    DataError
        Missing file or column, unreadable file, a non-numeric, empty, NaN or
        infinite value (the message names the file, column and row; ``line``
        is the CSV line), fewer than 20 values, or a constant column.
    """
    path = Path(path)
    check_out_dir(out_dir, "diagnose", overwrite, [path])   # refused before any work
    x = _read_column(path, column)
    if max_lag is None:
        max_lag = 50   # clipped to the series length by diagnose
    elif not isinstance(max_lag, bool) and isinstance(max_lag, (int, np.integer)) and max_lag >= x.size:
        raise ArgumentError(f"{max_lag} is not below the number of values in column '{column}' of "
                            f"{path} ({x.size}); give at most {x.size - 1}", "--max-lag")
    if (n_components is not None and not isinstance(n_components, bool)
            and isinstance(n_components, (int, np.integer)) and n_components > x.size // 2):
        raise ArgumentError(f"{n_components} components need at least {2 * n_components} values; column "
                            f"'{column}' of {path} has {x.size}", "--components")
    try:
        result = diagnose(x, max_lag=max_lag, n_components=n_components, seed=seed)
    except ValueError as exc:
        raise DataError(f"column '{column}': {exc}", file=str(path)) from None
    figs = figures(result)
    doc = {"source": {"file": os.fspath(path), "column": column}, **_json_ready(result),
           "figures": dict(FIGURE_FILES)}
    with staged_output(out_dir, "diagnose", overwrite, [path], complete_file="diagnostics.json") as folder:
        for name, fig in figs.items():
            atomic_savefig(fig, folder.file(FIGURE_FILES[name]), dpi=110)
        atomic_write_json(folder.file("diagnostics.json"), doc)
    return doc
