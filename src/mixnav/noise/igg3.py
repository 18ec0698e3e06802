"""Robust weight functions shared by the robust filter (:mod:`mixnav.filters.robust_adaptive`, M2)
and the robust single-point solution (:mod:`mixnav.gnss.spp`)."""

from __future__ import annotations

import numpy as np


def igg3_factors(t: np.ndarray, k0: float, k1: float) -> np.ndarray:
    """IGG-III weight factors of standardised residuals ``t`` (Yang 1994)::

        gamma = 1                                   |t| <= k0   (keep)
        gamma = (k0 / |t|) ((k1 - |t|) / (k1 - k0))^2   k0 < |t| <= k1   (down-weight)
        gamma = 0                                   |t| > k1    (reject)

    A row's variance becomes ``variance / gamma``.
    """
    t = np.abs(np.asarray(t, dtype=float))
    g = np.ones_like(t)
    mid = (t > k0) & (t <= k1)
    g[mid] = (k0 / t[mid]) * ((k1 - t[mid]) / (k1 - k0)) ** 2
    g[t > k1] = 0.0
    return g
