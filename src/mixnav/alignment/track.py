"""Dead-reckoning alignment from pseudoranges: the initial position and heading of a
vehicle that is already moving, from the first seconds of data only.

1. Every epoch up to ``t_align`` is solved alone for position, receiver clock and
   inter-system offsets by iteratively reweighted least squares with Huber
   weights (k = 1.5 sigma, scale from the median absolute residual): the
   non-line-of-sight delays of urban canyons are large and positive, so an
   unweighted fix is pulled by tens of metres.
2. The odometry is dead-reckoned over the same time with heading 0 from the
   origin (:func:`dead_reckon`).
3. The fixes are fitted by ``p(t) = p0 + R(psi0) d(t)`` (2-D rotation and
   translation, Huber-weighted again): the heading ``psi0`` that turns the
   odometry track onto the GNSS track, and the start ``p0``.
4. ``refine = True``: every pseudorange of the window is fitted at once to the
   dead-reckoned track, ``r(t) = r_ref + p0 + R(psi0) d(t)``, with a clock
   ``b0 + d1 t`` and the inter-system offsets (7 unknowns for hundreds of
   rows), by expectation-maximisation under a two-component noise: line of
   sight ``N(0, var_j)`` and non-line-of-sight ``N(mu, s^2)``, with ``w``, ``mu``,
   ``s`` re-estimated from the responsibilities. Each epoch's fix is pulled by
   its delayed rows; the whole window shares one track, so the rows that agree
   with it are found. EM is local: it starts from the Huber fit with the clock
   moved by each of ``clock_starts`` metres (delays pull a fix's clock up) and
   keeps the start of largest likelihood. The mixture it learns (a LOS weight per
   C/N0 band, ``mu``, ``s``) is reported, for a filter that starts here to go on
   from (``los_weight_bands``, ``nlos_mean_m``, ``nlos_sd_m``), with the correlation
   time of the line-of-sight residuals (:func:`los_correlation_time`, each epoch's common
   part removed: the fit's track and clock errors are the filter's states, not a
   satellite's own correlated error).

Uses data up to ``t_align`` only: a filter started at ``t_align`` from the
returned state is causal.
"""

from __future__ import annotations

import math

import numpy as np

from ..data import InitialState
from ..errors import ArgumentError
from ..geodesy.frames import ecef_to_lla, lla_to_ned, ned_to_lla
from ..gnss.geometry import C_LIGHT, earth_rotation_correction
from ..measurements.kinds import CHANNEL_SYSTEM


def _huber_weights(v: np.ndarray, k: float = 1.5) -> np.ndarray:
    s = 1.4826 * np.median(np.abs(v)) + 1e-6
    a = np.abs(v) / (k * s)
    return np.where(a <= 1.0, 1.0, 1.0 / np.maximum(a, 1e-12))


def robust_fix(sat_ecef, pseudorange, variance, system_index, n_systems, x0=None, iterations=10):
    """One epoch's position [m] (ECEF) and clocks (reference clock [m], offsets [m]) by
    Huber-reweighted least squares; None when it does not converge or has too few rows."""
    m = len(pseudorange)
    n_par = 3 + n_systems
    if m < n_par + 1:
        return None
    x = np.zeros(3) if x0 is None else np.array(x0, dtype=float)
    clk = np.zeros(n_systems)
    w = 1.0 / np.asarray(variance, dtype=float)
    hub = np.ones(m)
    for it in range(iterations + 10):
        tau = np.linalg.norm(sat_ecef - x, axis=1) / C_LIGHT
        d = earth_rotation_correction(sat_ecef, tau) - x
        rng = np.linalg.norm(d, axis=1)
        v = pseudorange - rng - clk[system_index]
        A = np.zeros((m, n_par))
        A[:, :3] = -d / rng[:, None]
        A[np.arange(m), 3 + system_index] = 1.0
        if it >= 10:   # first converge from the Earth's centre unweighted, then reweight
            hub = _huber_weights(v * np.sqrt(w))
        ww = w * hub
        N = A.T @ (A * ww[:, None])
        try:
            dp = np.linalg.solve(N, A.T @ (ww * v))
        except np.linalg.LinAlgError:
            return None
        x += dp[:3]
        clk += dp[3:]
        if it >= 10 and np.linalg.norm(dp) < 1e-3:
            break
    r = np.linalg.norm(x)
    if not (6.2e6 < r < 6.5e6):
        return None
    return x, clk


def dead_reckon(inc, speed_scale: float = 0.0):
    """Positions N, E [m] and heading [rad] at the end of each increment of
    :class:`~mixnav.data.OdometryIncrements`, starting at the origin with heading 0."""
    dpsi = inc.dtheta[:, 2]
    psi = np.cumsum(dpsi)
    mid = psi - 0.5 * dpsi
    ds = (1.0 + speed_scale) * inc.dvel[:, 0]
    return np.cumsum(ds * np.cos(mid)), np.cumsum(ds * np.sin(mid)), psi


def _window_rows(epochs, t0, t_align, sysmap):
    """Flat rows of the window: times, satellites, pseudoranges, variances, system index, C/N0,
    and a key per satellite (system and number)."""
    keep = []
    for e in range(len(epochs)):
        if t0 < epochs.time[e] <= t_align:
            sl = epochs.rows_of(e)
            keep.append(np.arange(sl.start, sl.stop))
    idx = np.concatenate(keep) if keep else np.zeros(0, dtype=int)
    sidx = np.array([sysmap.get(int(s), -1) for s in epochs.system[idx]], dtype=int)
    idx, sidx = idx[sidx >= 0], sidx[sidx >= 0]
    t = np.repeat(epochs.time, np.diff(epochs.start))[idx]
    key = epochs.system[idx].astype(np.int64) * CHANNEL_SYSTEM + epochs.sat_id[idx].astype(np.int64)   # a satellite
    return t, epochs.sat_ecef[idx], epochs.pseudorange[idx], epochs.variance[idx], sidx, epochs.cn0[idx], key


def los_correlation_time(t, key, e, var, g, max_time: float = 30.0, common: bool = False) -> float:
    """Correlation time [s] of the line-of-sight errors: the lag-one correlation ``rho`` of
    the standardised residuals ``e / sqrt(var)`` of rows likelier LOS than not (``g > 0.5``),
    paired satellite by satellite across consecutive epochs, turned into ``-dt / ln rho``
    (``dt`` the median epoch interval). Multipath and near-LOS diffraction keep a
    satellite's error for seconds, so a filter that takes each epoch's rows as
    independent is overconfident (:class:`~mixnav.filters.epoch_mixture.EpochMixtureEstimator`,
    ``correlation_time``). 0 when uncorrelated (or too few pairs); at most ``max_time``.

    ``common = True``: each epoch's mean standardised residual over its LOS rows is removed
    first. What all satellites of an epoch share (a track or clock error of the fit, which a
    filter's states take up) is then not counted as a satellite's own correlation."""
    ut, inv = np.unique(t, return_inverse=True)
    if len(ut) < 3:
        return 0.0
    dt = float(np.median(np.diff(ut)))
    los = g > 0.5
    zs = e / np.sqrt(var)
    if common:
        n_los = np.bincount(inv, weights=los.astype(float), minlength=len(ut))
        zs = zs - (np.bincount(inv, weights=np.where(los, zs, 0.0), minlength=len(ut)) / np.maximum(n_los, 1.0))[inv]
    o = np.lexsort((t, key))
    k, tt, z, ok = key[o], t[o], zs[o], los[o]
    pair = (k[1:] == k[:-1]) & (np.abs(tt[1:] - tt[:-1] - dt) < 0.5 * dt) & ok[1:] & ok[:-1]
    if pair.sum() < 20:
        return 0.0
    a, b = z[:-1][pair], z[1:][pair]
    rho = float((a * b).sum() / math.sqrt((a * a).sum() * (b * b).sum()))
    if rho <= 0.0:
        return 0.0
    return float(min(-dt / math.log(min(rho, 1.0 - 1e-12)), max_time))


def _refine(theta0, lla_ref, tq, sat, rho, var, sidx, n_sys, track, iterations=30, band=None,
            prior=None, record=None):
    """EM fit of the window's pseudoranges to the dead-reckoned track (module docstring, step 4).

    ``theta = [p0_n, p0_e, p0_d, psi0, b0, d1, offsets...]``; ``track(t)`` gives the
    dead-reckoned north, east [m] at times ``t``. Returns ``(theta, log-likelihood, w, mu, s)``
    with ``w`` the LOS weight of each band present (``band.max() + 1`` of them), then the last
    iteration's residuals and LOS responsibilities.

    ``prior``: ``{index: (value, sigma)}``, components of ``theta`` started at ``value`` and
    held near it by a Gaussian prior of ``sigma`` (diagnostics: the fit held at a reference;
    none in the pipeline). ``record``: called once at the end with the fit's final state
    (``theta, ll, e, g, A, u, var, sd``)."""
    from ..geodesy.frames import dcm_ecef_to_ned
    C_en = dcm_ecef_to_ned(lla_ref[0], lla_ref[1]).T
    r_ref = lla_to_ecef_point(lla_ref)
    dn, de = track(tq)
    t_ref = tq[0]
    theta = np.array(theta0, dtype=float)
    prior = prior or {}
    for k, (v, _) in prior.items():
        theta[k] = v
    band = np.zeros(len(rho), dtype=np.int64) if band is None else band
    nb = int(band.max()) + 1
    w_b = np.full(nb, 0.5)
    mu, s = 20.0, 30.0
    ll = -np.inf
    for it in range(iterations):
        c, sn = math.cos(theta[3]), math.sin(theta[3])
        pn = theta[0] + c * dn - sn * de
        pe = theta[1] + sn * dn + c * de
        r = r_ref + np.stack([pn, pe, np.full_like(pn, theta[2])], axis=1) @ C_en.T
        tau = np.linalg.norm(sat - r, axis=1) / C_LIGHT
        d = earth_rotation_correction(sat, tau) - r
        rng = np.linalg.norm(d, axis=1)
        off = np.concatenate([[0.0], theta[6:]])
        e = rho - (rng + theta[4] + theta[5] * (tq - t_ref) + off[sidx])
        # E-step
        w = w_b[band]
        a = np.log(w) - 0.5 * e * e / var - 0.5 * np.log(2 * np.pi * var)
        b = np.log(1 - w) - 0.5 * (e - mu) ** 2 / s ** 2 - 0.5 * np.log(2 * np.pi * s * s)
        mx = np.maximum(a, b)
        lse = mx + np.log(np.exp(a - mx) + np.exp(b - mx))
        ll_new = float(lse.sum())
        g = np.exp(a - lse)
        # M-step: mixture parameters, then one weighted Gauss-Newton step of theta
        w_b = np.clip(np.bincount(band, weights=g, minlength=nb) / np.maximum(np.bincount(band, minlength=nb), 1),
                      0.05, 0.95)
        mu = float(((1 - g) * e).sum() / (1 - g).sum())
        s = float(max(math.sqrt(((1 - g) * (e - mu) ** 2).sum() / (1 - g).sum()), 5.0))
        u_n = (d / rng[:, None]) @ C_en        # line of sight in NED
        A = np.zeros((len(e), len(theta)))
        # d(range)/d(p) = -u; p depends on p0 and on psi0 through the rotated track
        A[:, 0], A[:, 1], A[:, 2] = u_n[:, 0], u_n[:, 1], u_n[:, 2]
        dpn, dpe = -sn * dn - c * de, c * dn - sn * de
        A[:, 3] = u_n[:, 0] * dpn + u_n[:, 1] * dpe
        A[:, 4] = -1.0
        A[:, 5] = -(tq - t_ref)
        for k in range(1, n_sys):
            A[sidx == k, 5 + k] = -1.0
        # residual e = rho - h; h grows along -u for p: de/dp = u; e target: minimise the
        # weighted squares of (e - (1 - g) mu) with weights g / var + (1 - g) / s^2
        wt = g / var + (1 - g) / s ** 2
        tgt = (g * e / var + (1 - g) * (e - mu) / s ** 2) / wt
        N = A.T @ (A * wt[:, None])
        rhs = A.T @ (wt * tgt)
        for k, (v, sg) in prior.items():
            N[k, k] += 1.0 / sg ** 2
            rhs[k] += (theta[k] - v) / sg ** 2
        try:
            step = np.linalg.solve(N + 1e-9 * np.eye(len(theta)), rhs)
        except np.linalg.LinAlgError:
            break
        theta = theta - step
        if abs(ll_new - ll) < 1e-3 and np.abs(step).max() < 1e-3:
            ll = ll_new
            break
        ll = ll_new
    if record is not None:
        record({"theta": theta.copy(), "ll": ll, "e": e, "g": g, "A": A, "u": u_n, "var": var, "sd": s})
    return theta, ll, w_b, mu, s, e, g


def lla_to_ecef_point(lla):
    from ..geodesy.frames import lla_to_ecef
    return lla_to_ecef(np.asarray(lla, dtype=float))


def align_track(epochs, inc, t_align: float, systems=(1, 4), refine: bool = True,
                clock_starts=(0.0, -10.0, -20.0, -30.0, -40.0, -60.0), cn0_edges=()) -> tuple[InitialState, dict]:
    """The initial state at ``t_align`` [s] (module docstring) and a report (fix count, fit
    residual RMS ``fit_rms_m`` [m], heading [deg] ...).

    ``fit_rms_m`` is measured on the fit's residuals: with ``refine``, the RMS of the
    pseudorange residuals of the final EM fit weighted by each row's LOS responsibility
    (and ``los_scale``, their mean square on the given variances); without, the RMS of the
    2-D fixes about the fitted track. It is the returned state's position sigma (north,
    east; twice that down) and, over the track's span, its heading sigma (1-30 deg).

    Parameters
    ----------
    epochs : PseudorangeEpochs
    inc : OdometryIncrements
    t_align : float
        End of the alignment window [s] (after the first increment).
    systems : sequence of int
        System codes, the clock's reference first.
    """
    t0 = float(inc.time[0] - inc.dt[0])
    if not (t0 < t_align <= inc.time[-1]):
        raise ArgumentError(f"must be inside the odometry's span ({t0:g}, {inc.time[-1]:g}] s, got {t_align}",
                            argument="t_align")
    sysmap = {int(s): k for k, s in enumerate(systems)}
    times, fixes, x = [], [], None
    for e in range(len(epochs)):
        t = epochs.time[e]
        if t < t0 or t > t_align:
            continue
        sl = epochs.rows_of(e)
        sidx = np.array([sysmap.get(int(s), -1) for s in epochs.system[sl]])
        use = sidx >= 0
        present = sorted(set(sidx[use]))
        remap = {k: i for i, k in enumerate(present)}
        sol = robust_fix(epochs.sat_ecef[sl][use], epochs.pseudorange[sl][use], epochs.variance[sl][use],
                         np.array([remap[k] for k in sidx[use]], dtype=int), len(present), x0=x)
        if sol is None:
            continue
        x = sol[0]
        times.append(t)
        fixes.append(x.copy())
    if len(fixes) < 5:
        raise ArgumentError(f"only {len(fixes)} epochs could be solved before t_align = {t_align:g} s",
                            argument="t_align")
    fixes = np.array(fixes)
    times = np.array(times)
    lla_ref = ecef_to_lla(np.median(fixes, axis=0))
    p = lla_to_ned(ecef_to_lla(fixes), lla_ref)[:, :2]
    dn, de, psi = dead_reckon(inc)
    tt = np.concatenate([[t0], inc.time])
    dn, de, psi = (np.concatenate([[0.0], a]) for a in (dn, de, psi))
    d = np.stack([np.interp(times, tt, dn), np.interp(times, tt, de)], axis=1)
    w = np.ones(len(times))
    for _ in range(20):    # weighted 2-D Procrustes, Huber reweighting
        mp = (w[:, None] * p).sum(0) / w.sum()
        md = (w[:, None] * d).sum(0) / w.sum()
        A = ((w[:, None] * (d - md)).T @ (p - mp))
        ang = math.atan2(A[0, 1] - A[1, 0], A[0, 0] + A[1, 1])
        R = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
        p0 = mp - R @ md
        res = p - (p0 + d @ R.T)
        w = _huber_weights(np.linalg.norm(res, axis=1))
    ka = int(np.searchsorted(tt, t_align - 1e-9))
    report = {"fixes": len(fixes)}
    if refine:
        tq, sat, rho, var, sidx, cn0, sat_key = _window_rows(epochs, t0, t_align, sysmap)
        edges = np.asarray(cn0_edges, dtype=float)
        band = np.where(np.isfinite(cn0), np.searchsorted(edges, np.nan_to_num(cn0), side="right"), len(edges) + 1) \
            if edges.size else np.zeros(len(rho), dtype=np.int64)
        present = sorted(set(sidx.tolist()))
        remap = np.zeros(max(present) + 1, dtype=int)
        remap[present] = np.arange(len(present))
        remap_back = {int(k): i for i, k in enumerate(present)}     # system index -> parameter slot
        sidx = remap[sidx]
        n_sys = len(present)
        track = lambda tq_: (np.interp(tq_, tt, dn), np.interp(tq_, tt, de))  # noqa: E731
        # clock of the Huber fixes at the window's start, a straight line through them
        r_fix = fixes
        clk0 = []
        for t_e, x_e in zip(times, r_fix):
            sel = (tq == t_e) & (sidx == 0)
            if sel.any():
                tau = np.linalg.norm(sat[sel] - x_e, axis=1) / C_LIGHT
                rr = np.linalg.norm(earth_rotation_correction(sat[sel], tau) - x_e, axis=1)
                clk0.append((t_e, float(np.median(rho[sel] - rr))))
        ct = np.array(clk0)
        d1, b0 = np.polyfit(ct[:, 0] - tq[0], ct[:, 1], 1) if len(ct) > 1 else (0.0, ct[0, 1])
        h_ref = float(np.median(ecef_to_lla(fixes)[:, 2]))
        best = None
        for dc in clock_starts:
            th0 = np.concatenate([[p0[0], p0[1], 0.0, ang, b0 + dc, d1], np.zeros(n_sys - 1)])
            lla_ref2 = np.array([lla_ref[0], lla_ref[1], h_ref])
            th, ll, w_b, mu, s_n, e_fit, g_fit = _refine(th0, lla_ref2, tq, sat, rho, var, sidx, n_sys, track,
                                                         band=band)
            if best is None or ll > best[1]:
                best = (th, ll, w_b, mu, s_n, dc, e_fit, g_fit)
        th, ll, w_b, mu, s_n, dc, e_fit, g_fit = best
        w_los = float(np.mean(w_b[band]))
        # the learned mixture, handed to a filter that starts here: one LOS weight per C/N0 band
        # and the band-free one last (bands without rows in the window take the overall share)
        n_bands = len(edges) + 2
        w_bands = np.full(n_bands, w_los)
        if edges.size:
            seen = np.bincount(band, minlength=n_bands)[:n_bands] > 0
            w_bands[:len(w_b)][seen[:len(w_b)]] = w_b[seen[:len(w_b)]]
            w_bands[-1] = w_los
        c, sn = math.cos(th[3]), math.sin(th[3])
        pa = np.array([th[0] + c * dn[ka] - sn * de[ka], th[1] + sn * dn[ka] + c * de[ka]])
        ang = th[3]
        lla = ned_to_lla(np.array([[pa[0], pa[1], th[2]]]), np.array([lla_ref[0], lla_ref[1], h_ref]))[0]
        report.update(los_share=w_los, nlos_mean_m=mu, nlos_sd_m=s_n, clock_start_m=dc, log_likelihood=ll,
                      los_weight_bands=[float(v) for v in w_bands],
                      los_correlation_time_s=los_correlation_time(tq, sat_key, e_fit, var, g_fit, common=True))
        # measured: the RMS of the fit's residuals over the rows likelier LOS (weighted by the
        # LOS responsibility; the delayed rows are far by construction), and the LOS rows' scale
        # on the given variances (mean g e^2 / var over mean g), both of the final fit
        g_sum = max(float(g_fit.sum()), 1e-9)
        rms = float(math.sqrt((g_fit * e_fit * e_fit).sum() / g_sum))
        report["los_scale"] = float((g_fit * e_fit * e_fit / var).sum() / g_sum)
        # the clock line and the offsets at t_align, in the systems' order (absent systems: 0)
        clock0 = np.array([th[4] + th[5] * (tt[ka] - tq[0]), th[5]])
        offsets = np.zeros(len(systems) - 1)
        for k_sys, i_present in remap_back.items():
            if k_sys > 0 and i_present > 0:
                offsets[k_sys - 1] = th[5 + i_present]
    else:
        clock0, offsets = None, None
        pa = p0 + R @ np.array([dn[ka], de[ka]])
        h = float(np.median(ecef_to_lla(fixes)[:, 2]))
        lla = ned_to_lla(np.array([[pa[0], pa[1], 0.0]]), lla_ref)[0]
        lla[2] = h
        rms = float(np.sqrt(np.mean(np.sum(res ** 2, axis=1))))
    heading = ang + psi[ka]
    nav = np.zeros(10)
    nav[0], nav[3] = math.cos(0.5 * heading), math.sin(0.5 * heading)
    nav[7:10] = lla
    span = float(np.linalg.norm(d[-1] - d[0])) + 1.0
    sig_psi = min(max(rms / span, math.radians(1.0)), math.radians(30.0))
    init = InitialState(time=float(tt[ka]), nav=nav, sigma_att=np.array([0.0, 0.0, sig_psi]),
                        sigma_vel=np.ones(3), sigma_pos=np.array([rms, rms, 2 * rms]),
                        sigma_clock=np.array([1e4, 200.0]) if clock0 is None else np.array([30.0, 2.0]),
                        clock0=clock0, aux0=None if offsets is None or not len(offsets) else
                        {"system_offset": offsets})
    report.update(fit_rms_m=rms, heading_deg=math.degrees(heading) % 360.0, heading_sigma_deg=math.degrees(sig_psi))
    return init, report
