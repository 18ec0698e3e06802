"""Is a residual series non-Gaussian, and is it coloured?

:func:`diagnose` computes, for a 1-D series (residuals, innovations, the
error of a fix against truth):

- Q-Q data: theoretical standard-normal quantiles (Blom plotting positions
  ``(i - 3/8) / (n + 1/4)``) against the sorted standardized samples;
- the sample autocorrelation up to ``max_lag`` with the 95 % white-noise band
  ``+-1.96 / sqrt(n)`` and the Ljung-Box test of whiteness;
- normality tests: D'Agostino-Pearson K^2 (``scipy.stats.normaltest``) and
  Jarque-Bera, statistic and p-value;
- skewness and excess kurtosis (0 for a Gaussian);
- the lag-1 least-squares AR(1) coefficient;
- optionally a fitted K-component Gaussian mixture (scikit-learn's EM for now;
  mixnav's own VB learner will replace it).

:func:`figures` draws Q-Q, ACF and histogram figures (``matplotlib.figure.Figure``
directly, never pyplot), and :func:`diagnose_file` does it all for one column
of a CSV or Parquet file, writing ``diagnostics.json`` and PNGs atomically.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from scipy import stats

from ..errors import ArgumentError, DataError

__all__ = ["diagnose", "figures", "diagnose_file", "MIN_SAMPLES", "FIGURE_FILES"]

#: fewest values :func:`diagnose` accepts (normaltest needs 8; 20 keeps it meaningful)
MIN_SAMPLES = 20
#: figure name -> file name written by :func:`diagnose_file`
FIGURE_FILES = {"qq": "qq.png", "acf": "acf.png", "histogram": "histogram.png"}
_JSON_QQ_POINTS = 1000
_ALPHA = 0.05


def _acf(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased sample autocorrelation r_0..r_L of a demeaned series (FFT), shape (L+1,)."""
    n = x.size
    nfft = 1 << int(math.ceil(math.log2(2 * n - 1)))
    f = np.fft.rfft(x, nfft)
    acov = np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1]
    return acov / acov[0]


def diagnose(x, max_lag: int = 50, n_components: int | None = None, seed: int = 0) -> dict:
    """Non-Gaussianity and colour diagnostics of a residual series.

    Parameters
    ----------
    x : array_like (n,)
        The series, any unit (results keep it), n >= 20, finite, not constant.
    max_lag : int, default 50
        Largest autocorrelation lag; clipped to n - 1.
    n_components : int, optional
        If given, fit a Gaussian mixture with this many components.
    seed : int, default 0
        Seed of the mixture fit's initialisation (results are reproducible).

    Returns
    -------
    dict
        ``n``, ``mean``, ``std`` (ddof=1) [unit];
        ``qq``: {``theoretical`` (n,), ``sample`` (n,)} standardized;
        ``acf``: {``lags`` (L+1,), ``values`` (L+1,), ``band`` = 1.96/sqrt(n),
        ``fraction_outside`` (of lags 1..L), ``max_lag``};
        ``ljung_box``: {``statistic``, ``p_value``, ``lags``};
        ``normality``: {``test``, ``statistic``, ``p_value``, ``rejected``} (5 %);
        ``jarque_bera``: {``statistic``, ``p_value``};
        ``skewness``, ``excess_kurtosis`` (bias-corrected);
        ``ar1``: {``coefficient`` (lag-1 least squares on the demeaned series),
        ``innovation_std`` [unit]};
        ``mixture``: None or {``n_components``, ``weights``, ``means``,
        ``sigmas`` [unit], sorted by decreasing weight, ``converged``, ``bic``,
        ``excess_kurtosis`` (of the fitted mixture)};
        ``verdict``: {``non_gaussian``, ``coloured``, ``summary``} at 5 %.

    Raises
    ------
    ValueError
        Not 1-D, fewer than 20 values, non-finite values, a constant series,
        ``max_lag < 1`` or ``n_components < 1``.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"expected a 1-D series (n,), got shape {x.shape}")
    n = x.size
    if n < MIN_SAMPLES:
        raise ValueError(f"need at least {MIN_SAMPLES} values to diagnose a series, got {n}")
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise ValueError(f"value {bad[0]} is not finite ({x[bad[0]]}); {bad.size} such value(s)")
    if np.abs(x).max() > 1e150:   # their squares (variances, kurtosis) would overflow
        k = int(np.argmax(np.abs(x) > 1e150))
        raise ValueError(f"value {k} ({x[k]:.3g}) is beyond 1e150 in magnitude: rescale the series")
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)) or max_lag < 1:
        raise ValueError(f"max_lag must be a positive integer, got {max_lag!r}")
    if n_components is not None and (isinstance(n_components, bool)
                                     or not isinstance(n_components, (int, np.integer)) or n_components < 1):
        raise ValueError(f"n_components must be a positive integer, got {n_components!r}")
    mean, std = float(x.mean()), float(x.std(ddof=1))
    if not std > 0 or np.ptp(x) == 0:
        raise ValueError("the series is constant: nothing to diagnose")
    d = x - mean
    z = np.sort(d / std)
    pp = (np.arange(1, n + 1) - 0.375) / (n + 0.25)
    lag = int(min(max_lag, n - 1))
    r = _acf(d, lag)
    band = 1.96 / math.sqrt(n)
    k = np.arange(1, lag + 1)
    q_lb = float(n * (n + 2) * np.sum(r[1:] ** 2 / (n - k)))
    p_lb = float(stats.chi2.sf(q_lb, lag))
    nt = stats.normaltest(x)
    jb = stats.jarque_bera(x)
    phi = float(np.dot(d[1:], d[:-1]) / np.dot(d[:-1], d[:-1]))
    innov = d[1:] - phi * d[:-1]
    result = {
        "n": int(n),
        "mean": mean,
        "std": std,
        "qq": {"theoretical": stats.norm.ppf(pp), "sample": z},
        "acf": {"lags": np.arange(lag + 1), "values": r, "band": band,
                "fraction_outside": float(np.mean(np.abs(r[1:]) > band)), "max_lag": lag},
        "ljung_box": {"statistic": q_lb, "p_value": p_lb, "lags": lag},
        "normality": {"test": "D'Agostino-Pearson K^2 (scipy.stats.normaltest)",
                      "statistic": float(nt.statistic), "p_value": float(nt.pvalue),
                      "rejected": bool(nt.pvalue < _ALPHA)},
        "jarque_bera": {"statistic": float(jb.statistic), "p_value": float(jb.pvalue)},
        "skewness": float(stats.skew(x, bias=False)),
        "excess_kurtosis": float(stats.kurtosis(x, fisher=True, bias=False)),
        "ar1": {"coefficient": phi, "innovation_std": float(innov.std(ddof=1))},
        "mixture": _fit_mixture(x, n_components, seed) if n_components else None,
    }
    non_gauss = result["normality"]["rejected"]
    coloured = bool(p_lb < _ALPHA)
    summary = ("non-Gaussian" if non_gauss else "consistent with Gaussian") + \
        f" (normaltest p={nt.pvalue:.3g}, excess kurtosis {result['excess_kurtosis']:.3g}); " + \
        ("coloured" if coloured else "consistent with white") + \
        f" (Ljung-Box p={p_lb:.3g} over {lag} lags, lag-1 AR coefficient {phi:.3g})"
    result["verdict"] = {"non_gaussian": bool(non_gauss), "coloured": coloured, "summary": summary}
    return result


def _fit_mixture(x: np.ndarray, k: int, seed: int) -> dict:
    from sklearn.mixture import GaussianMixture as SkGM   # imported lazily: sklearn is slow to import

    if k > x.size // 2:
        raise ValueError(f"n_components={k} is too many for {x.size} values")
    # tol far below sklearn's 1e-3: with heavy tails EM creeps, and 1e-3 stops it
    # visibly short of the optimum (weights off by 0.1 on 1e5 samples)
    gm = SkGM(n_components=k, covariance_type="full", random_state=seed, tol=1e-6, max_iter=1000)
    gm.fit(x[:, None])
    order = np.argsort(-gm.weights_)
    w = gm.weights_[order]
    mu = gm.means_[order, 0]
    s = np.sqrt(gm.covariances_[order, 0, 0])
    m = float(w @ mu)
    dv = mu - m
    m2 = float(w @ (s ** 2 + dv ** 2))
    m4 = float(w @ (3 * s ** 4 + 6 * s ** 2 * dv ** 2 + dv ** 4))
    return {"n_components": int(k), "weights": w, "means": mu, "sigmas": s,
            "converged": bool(gm.converged_), "bic": float(gm.bic(x[:, None])),
            "excess_kurtosis": m4 / m2 ** 2 - 3.0, "method": "EM (sklearn.mixture.GaussianMixture)"}


def figures(result: dict) -> dict:
    """Q-Q, ACF and histogram figures of a :func:`diagnose` result.

    Parameters
    ----------
    result : dict
        As returned by :func:`diagnose` (or read back from diagnostics.json).

    Returns
    -------
    dict[str, matplotlib.figure.Figure]
        ``"qq"``, ``"acf"``, ``"histogram"`` (in the series' unit, with the
        fitted normal density and, if fitted, the mixture density).
    """
    from matplotlib.figure import Figure

    out = {}
    th = np.asarray(result["qq"]["theoretical"], dtype=float)
    sa = np.asarray(result["qq"]["sample"], dtype=float)
    fig = Figure(figsize=(5, 5))
    ax = fig.add_subplot()
    ax.plot(th, sa, ".", ms=2, label="samples")
    lim = [min(th.min(), sa.min()), max(th.max(), sa.max())]
    ax.plot(lim, lim, "k--", lw=1, label="normal")
    ax.set_xlabel("standard normal quantile")
    ax.set_ylabel("standardized sample quantile")
    ax.set_title(f"Q-Q plot (excess kurtosis {result['excess_kurtosis']:.2f})")
    ax.legend(loc="upper left")
    fig.tight_layout()
    out["qq"] = fig

    acf = result["acf"]
    lags, r, band = np.asarray(acf["lags"]), np.asarray(acf["values"], dtype=float), acf["band"]
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    ax.vlines(lags[1:], 0, r[1:], lw=1.5)
    ax.plot(lags[1:], r[1:], "o", ms=3)
    ax.axhline(0, color="k", lw=0.8)
    ax.axhspan(-band, band, color="tab:orange", alpha=0.25, label=f"95 % white-noise band (+-{band:.3g})")
    ax.set_xlabel("lag [epochs]")
    ax.set_ylabel("autocorrelation")
    ax.set_title(f"ACF (lag-1 AR coefficient {result['ar1']['coefficient']:.3f})")
    ax.legend(loc="upper right")
    fig.tight_layout()
    out["acf"] = fig

    mean, std = result["mean"], result["std"]
    xs = mean + std * sa      # the sorted samples (or their quantiles) in the series' unit
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    ax.hist(xs, bins=min(100, max(10, int(np.sqrt(xs.size)))), density=True, alpha=0.5, label="samples")
    grid = np.linspace(xs.min(), xs.max(), 400)
    ax.plot(grid, stats.norm.pdf(grid, mean, std), "k--", label="normal (same mean, sd)")
    mix = result.get("mixture")
    if mix:
        w, mu, s = (np.asarray(mix[k], dtype=float) for k in ("weights", "means", "sigmas"))
        dens = np.sum(w * stats.norm.pdf(grid[:, None], mu, s), axis=1)
        ax.plot(grid, dens, "r-", label=f"fitted mixture (K={mix['n_components']})")
    ax.set_yscale("log")
    ax.set_ylim(bottom=max(1e-4 / std, 0.5 / (xs.size * std)))
    ax.set_xlabel("value")
    ax.set_ylabel("density")
    ax.set_title("histogram")
    ax.legend(loc="upper right")
    fig.tight_layout()
    out["histogram"] = fig
    return out


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
    max_lag, n_components, seed
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
    from ..io.atomic import atomic_savefig, atomic_write_json
    from ..io.outdir import check_out_dir, staged_output

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
