"""Corrected raw observations of a receiver as the tight INS filter's observables, and
velocities from Doppler.

:func:`tight_observations` turns :class:`~mixnav.gnss.pseudoranges.PseudorangeEpochs` (a
RINEX file's pseudoranges and Doppler with the broadcast corrections applied,
:func:`mixnav.gnss.spp.corrected_pseudoranges`) into the padded
:class:`~mixnav.gnss.observables.GnssObservations` that
:class:`mixnav.measurements.tight.TightGnss` reads: the same container the simulator fills,
so a recorded file and a simulation run through one measurement model (lever arm and
Doppler included). The satellite positions and velocities, given at the transmit time in
the ECEF frame of that time, are turned into the reception-time frame by the Earth's
rotation during the travel time ``tau = |s - r| / c`` seen from a position ``r`` near the
receiver (an SPP fix: a 1 km error moves ``tau`` by 3 us, the rotated satellite by 6 mm).

:func:`doppler_velocity` solves each epoch's receiver velocity and clock drift from the
range rates by least squares (the fixes' velocity an in-motion alignment needs).
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from .geometry import C_LIGHT, earth_rotation_correction
from .observables import GnssObservations
from .pseudoranges import PseudorangeEpochs


def tight_observations(epochs: PseudorangeEpochs, receiver_ecef, sigma_pr: float, sigma_rr: float,
                       elevation_mask: float = 0.0, time_offset: float = 0.0, weights: str = "constant"):
    """The tight filter's observables of corrected pseudorange epochs.

    Parameters
    ----------
    epochs : PseudorangeEpochs
        GPS rows; with ``range_rate`` (Doppler) or without.
    receiver_ecef : ndarray (E, 3)
        A position near the receiver at each epoch [m] (the Earth-rotation and elevation
        reference).
    sigma_pr, sigma_rr : float
        The 1-sigma the filter is told [m], [m/s].
    elevation_mask : float
        [rad]; rows below it are left out (counted).
    time_offset : float
        Added to the epoch times [s] (onto the filter's time axis).
    weights : "constant" or "elevation"
        Pseudorange variance ``sigma_pr^2`` for every row, or the epochs' own ``variance``
        (``corrected_pseudoranges``: SPP's ``sigma_a^2 + sigma_b^2 / sin^2 el``) per row as
        ``pr_variance``. Range rates keep ``sigma_rr``.

    Returns
    -------
    obs : GnssObservations
        ``range_rate`` NaN where no Doppler (everywhere without ``epochs.range_rate``);
        ``carrier`` NaN; ``clock`` NaN (no truth); ``system`` the rows' system codes when
        any is not GPS (None for GPS alone, as before systems existed).
    skipped : dict
        Rows left out per reason: ``below elevation mask``, ``no Doppler`` (a row without a
        range rate in a file that has Doppler: the filter takes both observables of a
        satellite or neither).
    """
    r = np.asarray(receiver_ecef, float)
    E = len(epochs)
    if r.shape != (E, 3) or not np.isfinite(r).all():
        raise ArgumentError(f"receiver_ecef must be ({E}, 3) and finite", argument="receiver_ecef")
    if not (sigma_pr > 0 and sigma_rr > 0):
        raise ArgumentError("sigmas must be positive", argument="sigma_pr")
    if weights not in ("constant", "elevation"):
        raise ArgumentError(f"must be 'constant' or 'elevation', got {weights!r}", argument="weights")
    has_rr = epochs.range_rate is not None
    el = epochs.elevation
    use = ~(np.isfinite(el) & (el < elevation_mask))
    skipped = {"below elevation mask": int((~use).sum())}
    if has_rr:
        no_rr = use & ~np.isfinite(epochs.range_rate)
        skipped["no Doppler"] = int(no_rr.sum())
        use &= ~no_rr
    counts = np.array([int(use[epochs.rows_of(e)].sum()) for e in range(E)], dtype=np.int64)
    K = int(counts.max()) if E else 0
    valid = np.zeros((E, K), bool)
    prn = np.full((E, K), -1, dtype=int)
    sat_pos = np.zeros((E, K, 3))
    sat_vel = np.zeros((E, K, 3))
    pr = np.full((E, K), np.nan)
    rr = np.full((E, K), np.nan)
    elev = np.full((E, K), np.nan)
    var = np.full((E, K), np.nan) if weights == "elevation" else None
    system = np.zeros((E, K), dtype=np.int64) if (np.asarray(epochs.system) != 1).any() else None
    for e in range(E):
        sl = epochs.rows_of(e)
        idx = np.arange(sl.start, sl.stop)[use[sl]]
        n = len(idx)
        if n == 0:
            continue
        s = epochs.sat_ecef[idx]
        tau = np.linalg.norm(s - r[e], axis=1) / C_LIGHT
        valid[e, :n] = True
        prn[e, :n] = epochs.sat_id[idx]
        sat_pos[e, :n] = earth_rotation_correction(s, tau)
        pr[e, :n] = epochs.pseudorange[idx]
        elev[e, :n] = el[idx]
        if var is not None:
            var[e, :n] = epochs.variance[idx]
        if system is not None:
            system[e, :n] = epochs.system[idx]
        if has_rr:
            sat_vel[e, :n] = earth_rotation_correction(epochs.sat_vel[idx], tau)
            rr[e, :n] = epochs.range_rate[idx]
    obs = GnssObservations(time=np.asarray(epochs.time, float) + time_offset, valid=valid, prn=prn,
                           sat_pos=sat_pos, sat_vel=sat_vel, pseudorange=pr, range_rate=rr,
                           carrier=np.full((E, K), np.nan), elevation=elev, sigma_pr=float(sigma_pr),
                           sigma_rr=float(sigma_rr), sigma_cp=float("nan"), clock=np.full((E, 2), np.nan),
                           pr_variance=var, system=system)
    return obs, skipped


def doppler_velocity(obs: GnssObservations, receiver_ecef):
    """Receiver velocity and clock drift of each epoch from its range rates (least squares).

    Model per satellite (``u`` unit line of sight receiver -> satellite, ECEF)::

        rr_j = u_j . (v_s_j - v_r) + d      =>      rr_j - u_j . v_s_j = [-u_j^T, 1] (v_r, d)

    Parameters
    ----------
    obs : GnssObservations
        With range rates (NaN rows are not used).
    receiver_ecef : ndarray (m, 3)
        [m].

    Returns
    -------
    vel_ecef : ndarray (m, 3)
        [m/s]; NaN where fewer than 4 range rates.
    drift : ndarray (m,)
        [m/s].
    cov : ndarray (m, 4, 4)
        ``sigma_rr^2 (H^T H)^-1`` of ``(v_r, d)`` [m^2/s^2].
    """
    r = np.asarray(receiver_ecef, float)
    m = len(obs)
    vel = np.full((m, 3), np.nan)
    drift = np.full(m, np.nan)
    cov = np.full((m, 4, 4), np.nan)
    for k in range(m):
        sel = obs.valid[k] & np.isfinite(obs.range_rate[k])
        if sel.sum() < 4:
            continue
        d = obs.sat_pos[k, sel] - r[k]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        y = obs.range_rate[k, sel] - np.einsum("ij,ij->i", u, obs.sat_vel[k, sel])
        H = np.column_stack([-u, np.ones(len(u))])
        N = H.T @ H
        try:
            L = np.linalg.cholesky(N)
        except np.linalg.LinAlgError:   # degenerate geometry: no velocity at this epoch
            continue
        x = np.linalg.solve(L.T, np.linalg.solve(L, H.T @ y))
        L_inv = np.linalg.solve(L, np.eye(4))
        vel[k], drift[k] = x[:3], x[3]
        cov[k] = obs.sigma_rr ** 2 * (L_inv.T @ L_inv)
    return vel, drift, cov
