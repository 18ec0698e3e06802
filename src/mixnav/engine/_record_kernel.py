"""Compiled recording of one output epoch (one dispatch instead of a dozen small numpy calls)."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True)
def record_epoch(io, P, nav, sensor, clock, prev, dt_last, rec_nav, rec_sigma, rec_sensor, rec_clock, rec_pv,
                 rec_w):
    """Write row ``io`` of the record arrays; return whether ``nav`` is finite.

    ``rec_sigma[io] = sqrt(diag(P))``, ``rec_pv[io] = P[3:9, 3:9]`` (velocity and
    position errors), ``rec_w[io] = prev[0:3] / dt_last`` (the compensated body
    rate of the last increment; zeros when ``dt_last`` is not positive).
    """
    finite = True
    for i in range(10):
        rec_nav[io, i] = nav[i]
        if not math.isfinite(nav[i]):
            finite = False
    for i in range(P.shape[0]):
        rec_sigma[io, i] = math.sqrt(P[i, i]) if P[i, i] >= 0.0 else math.nan
    for i in range(12):
        rec_sensor[io, i] = sensor[i]
    rec_clock[io, 0] = clock[0]
    rec_clock[io, 1] = clock[1]
    for i in range(6):
        for j in range(6):
            rec_pv[io, i, j] = P[3 + i, 3 + j]
    for i in range(3):
        rec_w[io, i] = prev[i] / dt_last if dt_last > 0.0 else 0.0
    return finite
