"""Fit and remove AR(1) colour in residual series with gaps.

A residual series per channel (a satellite's pseudorange residuals, an axis
of a position error) is modelled as first-order autoregressive::

    d_k = x_k - mu,    d_k = psi d_{k-1} + w_k,    w_k ~ white, var sigma_w^2

with one ``psi`` per channel, counted per *sample* (epoch index k), whatever
the spacing of the epochs.

Missing samples
---------------
Satellites come and go, so a channel has gaps: NaN values, or samples marked
in ``mask`` (True = missing, as in :mod:`numpy.ma`). Only *consecutive valid
pairs* ``(x_{k-1}, x_k)`` enter the fit; a gap ends one piece and the next
valid sample starts another, so fitting a gapped series equals fitting its
pieces jointly with one mean per channel (tested). Nothing is interpolated.

Estimator
---------
:func:`fit_ar1` uses **least squares on the demeaned series** (conditional
maximum likelihood under Gaussian innovations), over the set P of
consecutive valid pairs of a channel::

    mu      = mean of the valid samples
    psi     = sum_P d_k d_{k-1} / sum_P d_{k-1}^2
    e_k     = d_k - psi d_{k-1}                       (k in P)
    sigma_w^2 = sum_P e_k^2 / (m - 2)                 (m = |P|; psi and mu fitted)
    se(psi) = sqrt(sigma_w^2 / sum_P d_{k-1}^2)       (the regression standard error)
    CI      = psi -+ z_{(1+level)/2} se(psi)          (normal approximation)
    stationary variance = sigma_w^2 / (1 - psi^2)     (inf when |psi| >= 1)

For a stationary Gaussian AR(1) the standard error tends to the asymptotic
``sqrt((1 - psi^2) / m)``; least squares and Yule-Walker differ by O(1/m).
The least-squares choice matches the lag-1 coefficient reported by
:func:`mixnav.noise.diagnostics.diagnose` (same formula without gaps).

Whitening (P2 eqs. 13-20)
-------------------------
:func:`whiten_ar1` forms ``x_k - psi x_{k-1}``: the measurement differencing
``L*_k = L_{k+1} - Psi L_k`` of paper P2 (eq. 15), whose error ``e*_k``
(eq. 17) no longer contains the coloured part. Where ``x_k`` or ``x_{k-1}``
is missing the innovation is NaN.

:func:`autocorrelation` gives the gap-aware sample autocorrelation per
channel (pairs at lag L where both samples are valid).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = ["Ar1Fit", "fit_ar1", "whiten_ar1", "autocorrelation", "valid_mask", "MIN_PAIRS"]

#: fewest consecutive valid pairs :func:`fit_ar1` accepts per channel by default
MIN_PAIRS = 10


@dataclass(frozen=True)
class Ar1Fit:
    """AR(1) fit per channel (every array has shape (c,)).

    Attributes
    ----------
    psi : ndarray (c,)
        Least-squares AR(1) coefficient of the demeaned series [-].
    mean : ndarray (c,)
        Mean of the valid samples [unit].
    innovation_variance : ndarray (c,)
        ``sigma_w^2`` [unit^2] (residual sum of squares over m - 2).
    stationary_variance : ndarray (c,)
        ``sigma_w^2 / (1 - psi^2)`` [unit^2]; ``inf`` where ``|psi| >= 1``.
    sample_variance : ndarray (c,)
        Variance of the valid samples (ddof=1) [unit^2], for comparison.
    n_pairs : ndarray of int (c,)
        Consecutive valid pairs used.
    n_valid : ndarray of int (c,)
        Valid samples.
    std_error : ndarray (c,)
        Standard error of psi [-].
    ci_low, ci_high : ndarray (c,)
        Normal-approximation confidence interval of psi at ``level``.
    level : float
        Confidence level of the interval, e.g. 0.95.
    method : str
        The estimator, in words.
    """

    psi: np.ndarray
    mean: np.ndarray
    innovation_variance: np.ndarray
    stationary_variance: np.ndarray
    sample_variance: np.ndarray
    n_pairs: np.ndarray
    n_valid: np.ndarray
    std_error: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    level: float
    method: str = "least squares on the demeaned series, consecutive valid pairs only"

    @property
    def n_channels(self) -> int:
        return int(self.psi.size)

    @property
    def asymptotic_std_error(self) -> np.ndarray:
        """``sqrt((1 - psi^2) / n_pairs)`` (NaN where ``|psi| >= 1``), (c,)."""
        with np.errstate(invalid="ignore"):
            return np.sqrt((1.0 - self.psi ** 2) / self.n_pairs)

    def as_dict(self) -> dict:
        """Plain lists, for JSON."""
        out = {k: np.asarray(getattr(self, k)).tolist() for k in (
            "psi", "mean", "innovation_variance", "stationary_variance", "sample_variance", "n_pairs",
            "n_valid", "std_error", "ci_low", "ci_high")}
        out["level"] = self.level
        out["method"] = self.method
        return out


def _name(j: int, names) -> str:
    return f"channel {j}" + (f" ({names[j]!r})" if names is not None else "")


def valid_mask(x, mask=None, names=None) -> tuple[np.ndarray, np.ndarray]:
    """Checked ``(x, valid)`` as float (n, c) and bool (n, c) arrays.

    Parameters
    ----------
    x : array_like (n,) or (n, c)
        The series; a 1-D input is one channel.
    mask : array_like of bool, same shape as x, optional
        True where a sample is missing. Without it, NaN marks missing samples.
    names : sequence of str (c,), optional
        Channel names for error messages.

    Raises
    ------
    ValueError
        Wrong shapes, or a non-finite value that is not marked missing (an
        infinity, or NaN when a mask is given), naming the channel and index.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise ValueError(f"expected a series (n,) or (n, c), got shape {x.shape}")
    if names is not None and len(names) != x.shape[1]:
        raise ValueError(f"{len(names)} channel names for {x.shape[1]} channels")
    finite = np.isfinite(x)
    if mask is None:
        bad = np.isinf(x)
        valid = finite
        why = "is infinite (NaN marks a missing sample; infinity is an error)"
    else:
        m = np.asarray(mask)
        if m.dtype != bool:
            raise ValueError(f"mask must be boolean (True = missing), got dtype {m.dtype}")
        if m.ndim == 1 and x.shape[1] == 1:
            m = m[:, None]
        if m.shape != x.shape:
            raise ValueError(f"mask has shape {m.shape}, the series {x.shape}")
        valid = ~m
        bad = valid & ~finite
        why = "is not finite and not masked as missing"
    if bad.any():
        k, j = np.argwhere(bad)[0]
        raise ValueError(f"{_name(int(j), names)}, sample {int(k)}: value {float(x[k, j])} {why}; "
                         f"{int(bad.sum())} such value(s)")
    return x, valid


def fit_ar1(x, mask=None, *, level: float = 0.95, min_pairs: int = MIN_PAIRS, demean: bool = True,
            names=None) -> Ar1Fit:
    """Fit ``d_k = psi d_{k-1} + w_k`` per channel by least squares (see the module docstring).

    Parameters
    ----------
    x : array_like (n, c) or (n,)
        Residual series [any unit], one column per channel, samples in time
        order (one row per epoch).
    mask : array_like of bool (n, c), optional
        True where a sample is missing; without it NaN marks missing samples.
    level : float, default 0.95
        Confidence level of ``ci_low, ci_high``, in (0, 1).
    min_pairs : int, default 10
        Fewest consecutive valid pairs a channel needs (>= 3).
    demean : bool, default True
        Subtract the mean of the valid samples first; False fits the raw
        series (``mean`` is then reported as 0 and sigma_w^2 divides by m - 1).
    names : sequence of str (c,), optional
        Channel names for error messages.

    Returns
    -------
    Ar1Fit

    Raises
    ------
    ValueError
        Bad shapes or arguments; a non-finite value not marked missing; a
        channel with fewer than ``min_pairs`` consecutive valid pairs; a
        constant channel (no variation in its lagged values). The message
        names the channel.
    """
    if not (isinstance(level, numbers.Real) and 0.0 < float(level) < 1.0):
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    if isinstance(min_pairs, bool) or not isinstance(min_pairs, numbers.Integral) or min_pairs < 3:
        raise ValueError(f"min_pairs must be an integer >= 3, got {min_pairs!r}")
    x, valid = valid_mask(x, mask, names)
    n, c = x.shape
    xv = np.where(valid, x, 0.0)
    n_valid = valid.sum(axis=0)
    pair = valid[1:] & valid[:-1]                                 # (n-1, c): (x_{k-1}, x_k) both valid
    n_pairs = pair.sum(axis=0)
    for j in range(c):
        if n_pairs[j] < min_pairs:
            raise ValueError(f"{_name(j, names)}: {int(n_pairs[j])} consecutive valid pair(s), "
                             f"at least {min_pairs} are needed to fit an AR(1)")
    if demean:
        mean = xv.sum(axis=0) / n_valid
    else:
        mean = np.zeros(c)
    d = np.where(valid, x - mean, 0.0)
    for j in range(c):
        if np.ptp(x[valid[:, j], j]) == 0:
            raise ValueError(f"{_name(j, names)} is constant ({x[valid[:, j], j][0]!r} at every valid "
                             "sample): an AR(1) coefficient is undefined")
    prev, cur = np.where(pair, d[:-1], 0.0), np.where(pair, d[1:], 0.0)
    sxx = np.sum(prev * prev, axis=0)
    sxy = np.sum(prev * cur, axis=0)
    for j in range(c):
        if not sxx[j] > 0:
            raise ValueError(f"{_name(j, names)}: every lagged value equals the mean, so psi is undefined "
                             "(constant pieces)")
    psi = sxy / sxx
    e = np.where(pair, cur - psi * prev, 0.0)
    dof = n_pairs - (2 if demean else 1)
    sigma2 = np.sum(e * e, axis=0) / dof
    se = np.sqrt(sigma2 / sxx)
    z = float(stats.norm.ppf(0.5 + 0.5 * float(level)))
    with np.errstate(divide="ignore", invalid="ignore"):
        stat_var = np.where(np.abs(psi) < 1.0, sigma2 / (1.0 - psi ** 2), np.inf)
    samp_var = np.array([np.var(x[valid[:, j], j], ddof=1) if n_valid[j] > 1 else np.nan for j in range(c)])
    return Ar1Fit(psi=psi, mean=mean, innovation_variance=sigma2, stationary_variance=stat_var,
                  sample_variance=samp_var, n_pairs=n_pairs.astype(int), n_valid=n_valid.astype(int),
                  std_error=se, ci_low=psi - z * se, ci_high=psi + z * se, level=float(level),
                  method=("least squares on the demeaned series, consecutive valid pairs only" if demean
                          else "least squares on the raw (not demeaned) series, consecutive valid pairs only"))


def whiten_ar1(x, psi, mask=None, *, names=None) -> np.ndarray:
    """AR(1) innovations ``x_k - psi x_{k-1}`` per channel (P2 eq. 15).

    Parameters
    ----------
    x : array_like (n, c) or (n,)
        Series [unit]; subtract a mean first if the model has one
        (``x - fit.mean``).
    psi : float or array_like (c,)
        AR(1) coefficient per channel (finite).
    mask : array_like of bool (n, c), optional
        True where a sample is missing; without it NaN marks missing samples.
    names : sequence of str (c,), optional
        Channel names for error messages.

    Returns
    -------
    ndarray (n, c) (or (n,) for a 1-D input)
        Row 0 and every row whose sample or predecessor is missing are NaN.

    Raises
    ------
    ValueError
        Bad shapes, non-finite psi, or a non-finite value not marked missing.
    """
    one_d = np.ndim(x) == 1
    x, valid = valid_mask(x, mask, names)
    c = x.shape[1]
    p = np.asarray(psi, dtype=float)
    if p.ndim == 0:
        p = np.full(c, float(p))
    if p.shape != (c,):
        raise ValueError(f"psi must be a scalar or one value per channel ({c},), got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"psi must be finite, got {p}")
    out = np.full(x.shape, np.nan)
    pair = valid[1:] & valid[:-1]
    w = x[1:] - p * x[:-1]
    out[1:] = np.where(pair, w, np.nan)
    return out[:, 0] if one_d else out


def autocorrelation(x, max_lag: int, mask=None, *, names=None) -> tuple[np.ndarray, np.ndarray]:
    """Gap-aware sample autocorrelation per channel, lags 0..max_lag.

    ``r_L = (sum_{P_L} d_k d_{k-L} / |P_L|) / (sum_valid d_k^2 / n_valid)`` with
    ``d`` the channel demeaned over its valid samples and ``P_L`` the pairs
    at lag L whose two samples are both valid (NaN when there is none). For a
    gap-free series this is the biased estimator times ``n / (n - L)``.

    Parameters
    ----------
    x : array_like (n, c) or (n,)
    max_lag : int
        >= 1.
    mask : array_like of bool, optional
        True = missing; without it NaN marks missing samples.

    Returns
    -------
    r : ndarray (max_lag + 1, c)
        ``r[0] == 1``.
    n_pairs : ndarray of int (max_lag + 1, c)
        ``|P_L|`` (``n_valid`` at lag 0).
    """
    if isinstance(max_lag, bool) or not isinstance(max_lag, numbers.Integral) or max_lag < 1:
        raise ValueError(f"max_lag must be a positive integer, got {max_lag!r}")
    x, valid = valid_mask(x, mask, names)
    n, c = x.shape
    nv = valid.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(valid, x, 0.0).sum(axis=0) / nv
        d = np.where(valid, x - mean, 0.0)
        var = np.sum(d * d, axis=0) / nv
        r = np.full((max_lag + 1, c), np.nan)
        counts = np.zeros((max_lag + 1, c), dtype=int)
        counts[0] = nv
        r[0] = 1.0
        for lag in range(1, min(max_lag, n - 1) + 1):
            both = valid[lag:] & valid[:-lag]
            m = both.sum(axis=0)
            counts[lag] = m
            s = np.sum(np.where(both, d[lag:] * d[:-lag], 0.0), axis=0)
            r[lag] = np.where(m > 0, s / np.maximum(m, 1) / var, np.nan)
    return r, counts

