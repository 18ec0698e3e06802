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
directly, never pyplot). Reading a column of a file and writing the output folder
(``mixnav diagnose``) is the experiment layer's:
:func:`mixnav.experiment.diagnose.diagnose_file`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats


__all__ = ["diagnose", "figures", "MIN_SAMPLES", "FIGURE_FILES"]

#: fewest values :func:`diagnose` accepts (normaltest needs 8; 20 keeps it meaningful)
MIN_SAMPLES = 20
#: figure name -> file name written by :func:`diagnose_file`
FIGURE_FILES = {"qq": "qq.png", "acf": "acf.png", "histogram": "histogram.png"}
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
