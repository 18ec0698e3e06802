"""Compiled recording of one output epoch (one dispatch instead of a dozen small numpy calls)."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True)
def record_epoch(io, P, nav, sensor, clock, prev, dt_last, rec_nav, rec_sigma, rec_sensor, rec_clock, rec_pv,
                 rec_w, i_vel=3, i_pos=6):
    """Write row ``io`` of the record arrays; return whether ``nav`` is finite.

    ``rec_sigma[io] = sqrt(diag(P))``, ``rec_pv[io]`` the covariance of the velocity
    (states ``i_vel..i_vel+2``) and position (``i_pos..i_pos+2``) errors, NaN for a
    block the layout does not have (offset -1: a dead-reckoning model estimates no
    velocity), ``rec_w[io] = prev[0:3] / dt_last`` (the compensated body rate of
    the last increment; zeros when ``dt_last`` is not positive).
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
        oi = (i_vel + i) if i < 3 else (i_pos + i - 3)
        for j in range(6):
            oj = (i_vel + j) if j < 3 else (i_pos + j - 3)
            if (i < 3 and i_vel < 0) or (j < 3 and i_vel < 0):
                rec_pv[io, i, j] = math.nan
            else:
                rec_pv[io, i, j] = P[oi, oj]
    for i in range(3):
        rec_w[io, i] = prev[i] / dt_last if dt_last > 0.0 else 0.0
    return finite
