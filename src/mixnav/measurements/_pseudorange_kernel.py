"""Compiled batch prediction of the multi-system pseudorange model (the maths: :mod:`.pseudorange`).

Only :meth:`PseudorangeGnss.predict_batch` uses it (the ensemble filters' ``h``); the rows
of the error-state filters stay in numpy, so their numbers do not depend on it.
"""

from __future__ import annotations

import math

from numba import njit

from ..geodesy.earth import A_WGS84, E2_WGS84
from ..gnss.geometry import C_LIGHT, OMEGA_E_GPS


@njit(cache=True)
def pseudorange_predict_batch(lla, sat, bias, offsets, sys_col, Y):
    """``Y[j, k]``: the pseudorange of satellite ``k`` predicted at member ``j``.

    ``lla`` (N, 3) the members' positions [rad, rad, m]; ``sat`` (m, 3) the satellites at
    the transmit time in that time's ECEF frame [m]; ``bias`` (N,) receiver clock bias [m];
    ``offsets`` (N, S) each member's clock offset per system column (column 0 zero: the
    reference system); ``sys_col`` (m,) each satellite's column. One fixed-point step of
    the travel time, then the Earth's rotation over it (Sagnac), as the rows do.
    """
    N = lla.shape[0]
    m = sat.shape[0]
    for j in range(N):
        lat, lon, h = lla[j, 0], lla[j, 1], lla[j, 2]
        sl = math.sin(lat)
        cl = math.cos(lat)
        rn = A_WGS84 / math.sqrt(1.0 - E2_WGS84 * sl * sl)
        x = (rn + h) * cl * math.cos(lon)
        y = (rn + h) * cl * math.sin(lon)
        z = (rn * (1.0 - E2_WGS84) + h) * sl
        for k in range(m):
            sx, sy, sz = sat[k, 0], sat[k, 1], sat[k, 2]
            tau = math.sqrt((sx - x) ** 2 + (sy - y) ** 2 + (sz - z) ** 2) / C_LIGHT
            a = OMEGA_E_GPS * tau
            ca, sa = math.cos(a), math.sin(a)
            dx = ca * sx + sa * sy - x
            dy = -sa * sx + ca * sy - y
            dz = sz - z
            Y[j, k] = math.sqrt(dx * dx + dy * dy + dz * dz) + bias[j] + offsets[j, sys_col[k]]
