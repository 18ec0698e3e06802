"""Per-epoch statistics over Monte Carlo runs: RMS errors, filter sigmas, NEES, NIS.

Each finished run leaves ``runs/series_<seed>.parquet`` (see
:mod:`mixnav.experiment.montecarlo`). This module folds them, one file at a
time (memory independent of the number of runs), into one row per
(sweep value, method, epoch):

``n_runs``                 runs with this epoch
``rms_err_<x>``            sqrt(mean over runs of err_<x>^2), same unit as err_<x>
``rms_sig_<x>``            sqrt(mean over runs of the filter's sig_<x>^2)
``mean_nees_<q>``          NEES of quantity q (pos, vel, pv) averaged over runs
``nees_<q>_lo/_hi``        its two-sided 95 % chi-square band: for N runs of a
                           consistent filter, N * mean NEES ~ chi2(N * dof)
``n_nis``, ``mean_nis_per_dof``, ``nis_lo/_hi``
                           the NIS of the updates at this epoch, summed over the
                           runs that had one, divided by the summed measurement
                           dimension D (~ chi2(D) / D when consistent)

The band is for one epoch; over many epochs about 5 % fall outside by chance
(more when epochs are correlated, which they are within a run).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

__all__ = ["summarise_series", "consistency_table", "NEES_DOF"]

#: Degrees of freedom of each NEES column of the series.
NEES_DOF = {"pos": 3, "vel": 3, "pv": 6}


def _group_keys(df: pd.DataFrame) -> list[str]:
    return (["sweep_value"] if "sweep_value" in df.columns else []) + ["method", "time_s"]


def summarise_series(files: list[Path], sweep_values: list[float] | None = None) -> pd.DataFrame:
    """Fold per-run series files into per-epoch statistics (columns in the module docstring).

    Parameters
    ----------
    files : list of Path
        Series files of the finished runs.
    sweep_values : list of float, optional
        The sweep value of each file (same order), for sweep experiments.

    Returns
    -------
    pandas.DataFrame
        Sorted by (sweep_value,) method, time_s; empty when ``files`` is.
    """
    total = None
    for i, f in enumerate(files):
        df = pd.read_parquet(f)
        if sweep_values is not None:
            df.insert(0, "sweep_value", float(sweep_values[i]))
        keys = _group_keys(df)
        errs = [c for c in df.columns if c.startswith(("err_", "sig_"))]
        nees = [c for c in df.columns if c.startswith("nees_")]
        part = df[keys].copy()
        part["n_runs"] = 1.0
        for c in errs:
            part[f"sq_{c}"] = df[c].to_numpy(float) ** 2
        for c in nees:
            part[f"sum_{c}"] = df[c].to_numpy(float)
        has_nis = np.isfinite(df["nis"].to_numpy(float)) if "nis" in df else np.zeros(len(df), bool)
        part["n_nis"] = has_nis.astype(float)
        part["sum_nis"] = np.where(has_nis, df["nis"].to_numpy(float) if "nis" in df else 0.0, 0.0)
        part["sum_nis_dim"] = np.where(has_nis, df["nis_dim"].to_numpy(float) if "nis" in df else 0.0,
                                       0.0)
        part = part.groupby(keys, sort=False).sum()
        total = part if total is None else total.add(part, fill_value=0.0)
    if total is None:
        return pd.DataFrame()
    total = total.sort_index()
    out = pd.DataFrame(index=total.index)
    n = total["n_runs"].to_numpy()
    out["n_runs"] = n.astype(int)
    for c in total.columns:
        if c.startswith("sq_"):
            out[f"rms_{c[3:]}"] = np.sqrt(total[c].to_numpy() / n)
    for c in total.columns:
        if c.startswith("sum_nees_"):
            q = c[len("sum_nees_"):]
            out[f"mean_nees_{q}"] = total[c].to_numpy() / n
            dof = NEES_DOF.get(q, 3)
            out[f"nees_{q}_lo"] = stats.chi2.ppf(0.025, n * dof) / n
            out[f"nees_{q}_hi"] = stats.chi2.ppf(0.975, n * dof) / n
    k, d = total["n_nis"].to_numpy(), total["sum_nis_dim"].to_numpy()
    out["n_nis"] = k.astype(int)
    with np.errstate(invalid="ignore", divide="ignore"):
        out["mean_nis_per_dof"] = np.where(d > 0, total["sum_nis"].to_numpy() / d, np.nan)
        out["nis_lo"] = np.where(d > 0, stats.chi2.ppf(0.025, np.maximum(d, 1)) / d, np.nan)
        out["nis_hi"] = np.where(d > 0, stats.chi2.ppf(0.975, np.maximum(d, 1)) / d, np.nan)
    return out.reset_index()


def consistency_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Per (sweep value,) method and quantity: the time-averaged Monte Carlo NEES/NIS
    and the fraction of epochs inside their 95 % band.

    Columns: ``[sweep_value,] method, quantity, expected, mean, in_band_fraction,
    epochs, runs`` where ``expected`` is the dof for NEES and 1 for NIS per dof.
    """
    if summary.empty:
        return pd.DataFrame()
    keys = ["sweep_value", "method"] if "sweep_value" in summary.columns else ["method"]
    rows = []
    for key, g in summary.groupby(keys, sort=True):
        ident = dict(zip(keys, key if isinstance(key, tuple) else (key,)))
        for q, dof in NEES_DOF.items():
            col = f"mean_nees_{q}"
            if col not in g:
                continue
            v = g[col].to_numpy()
            ok = np.isfinite(v)
            inside = (v >= g[f"nees_{q}_lo"].to_numpy()) & (v <= g[f"nees_{q}_hi"].to_numpy())
            rows.append({**ident, "quantity": f"NEES {q}", "expected": float(dof),
                         "mean": float(np.mean(v[ok])) if ok.any() else np.nan,
                         "in_band_fraction": float(np.mean(inside[ok])) if ok.any() else np.nan,
                         "epochs": int(ok.sum()), "runs": int(g["n_runs"].max())})
        v = g["mean_nis_per_dof"].to_numpy()
        ok = np.isfinite(v)
        if ok.any():
            inside = (v >= g["nis_lo"].to_numpy()) & (v <= g["nis_hi"].to_numpy())
            rows.append({**ident, "quantity": "NIS per dof", "expected": 1.0,
                         "mean": float(np.mean(v[ok])), "in_band_fraction": float(np.mean(inside[ok])),
                         "epochs": int(ok.sum()), "runs": int(g["n_nis"].max())})
    return pd.DataFrame(rows)
