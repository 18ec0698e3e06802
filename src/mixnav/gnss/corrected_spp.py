"""Single-point positioning of corrected pseudoranges: the satellite clock and the atmosphere
already removed and the satellites' positions given per row
(:class:`mixnav.gnss.pseudoranges.PseudorangeEpochs`, e.g. a smartLoc log), so no broadcast
ephemeris and no GPS time are needed.

Each epoch is one :func:`mixnav.gnss.spp.wls_position` (iterated WLS, Earth rotation during
the travel time, the elevation mask; several systems: one receiver clock plus one offset
per other system present, as :func:`mixnav.gnss.spp.solve_epochs`) with the satellite
clocks zero and the row's own variance as its weight (``sigma_scale = sqrt(variance)`` on
``sigma_a = 1``, ``sigma_b = 0``: the caller's options say so), started from the previous
solution. The result is the same :class:`mixnav.gnss.spp.SppTrack` as the broadcast path's,
its ``week`` zero and ``tow`` the log's own times.
"""

from __future__ import annotations

import numpy as np

from .geometry import SatelliteStates
from .pseudoranges import SYSTEM_LETTERS, PseudorangeEpochs
from .spp import (STATUS_FEW, STATUS_OK, SYSTEM_ORDER, SppOptions, SppTrack, _record, _record_systems,
                  wls_position)


def solve_corrected(epochs: PseudorangeEpochs, options: SppOptions) -> SppTrack:
    """SPP of every epoch of ``epochs`` (module docstring); an epoch with fewer satellites
    than unknowns is status ``too few satellites``, one that does not converge ``not
    converged``: counted, never raised."""
    k = len(epochs)
    letters = np.array([SYSTEM_LETTERS.get(int(c), "?") for c in epochs.system])
    present = [s for s in SYSTEM_ORDER if s in set(letters.tolist())]
    multi = len(present) > 1
    out = SppTrack(week=np.zeros(k, int), tow=np.asarray(epochs.time, float).copy(),
                   pos_ecef=np.full((k, 3), np.nan), clock_bias=np.full(k, np.nan), cov=np.full((k, 4, 4), np.nan),
                   n_sat=np.zeros(k, int), pdop=np.full(k, np.nan), hdop=np.full(k, np.nan), vdop=np.full(k, np.nan),
                   rms_residual=np.full(k, np.nan), status=np.full(k, STATUS_OK, dtype=object),
                   offsets={s: np.full(k, np.nan) for s in present} if multi else {},
                   clock_system=np.full(k, "", dtype=object) if multi else None,
                   n_sat_system={s: np.zeros(k, int) for s in present} if multi else {})
    below = 0
    x0 = None
    for j in range(k):
        rows = epochs.rows_of(j)
        n = rows.stop - rows.start
        if n < 4:
            out.status[j] = STATUS_FEW
            continue
        zeros = np.zeros(n)
        sats = SatelliteStates(prn=epochs.sat_id[rows], pos_ecef=epochs.sat_ecef[rows], vel_ecef=np.zeros((n, 3)),
                               clock_bias=zeros, clock_drift=zeros)
        try:
            sol = wls_position(epochs.pseudorange[rows], sats, options, x0=x0,
                               sigma_scale=np.sqrt(epochs.variance[rows]), system=letters[rows] if multi else None)
        except ValueError:      # fewer satellites than unknowns above the mask
            out.status[j] = STATUS_FEW
            x0 = None
            continue
        below += sol.n_rejected_mask
        if not _record(out, j, sol, options):      # robust counts; False: not converged
            x0 = None
            continue
        if multi:
            _record_systems(out, j, sol, letters[rows], present)
        x0 = np.append(sol.pos_ecef, sol.clock_bias)
    out.status = out.status.astype(str)
    if multi:
        out.clock_system = out.clock_system.astype(str)
    out.skipped_satellites = {"below elevation mask": below} if below else {}
    return out
