"""Simulated GNSS observables per satellite and epoch, and the container filters read.

Per epoch ``k`` and visible satellite ``j`` (antenna at ``r``, receiver clock
bias ``b`` [m] and drift ``d`` [m/s], satellite clock ``dt_s`` [s])::

    pseudorange  rho = |R(tau) r_s(t - tau) - r| + b - c dt_s + e_rho
    range rate   rr  = d|...|/dt + d - c ddt_s + e_rr,  d|...|/dt = u . (v_s (1 - tau') - v_r)
    carrier      phi = |...| + b - c dt_s + lambda N_j + e_phi      [m]

Several systems (``satellites`` a :class:`mixnav.gnss.constellation.MultiConstellation`):
the pseudorange and carrier of a satellite of system ``g`` also carry the receiver's
inter-system offset ``o_g`` [m] (``system_offsets``, zero for the others; one receiver
clock), the ambiguity is in cycles of the system's first-frequency wavelength (GLONASS by
the satellite's channel), and the observations say each slot's system.

``R(tau)`` is the Earth rotation during the travel time ``tau`` (Sagnac);
``u`` the unit line of sight receiver -> satellite; the receiver velocity
``v_r`` includes the lever-arm term ``C_nb (w x l)``. No ionosphere or
troposphere: a simulation adds what it wants through the noise processes
(``pseudorange_noise``, ...). The ambiguity ``N_j`` is constant per
satellite (an integer number of L1 cycles drawn once per run), so the
time-differenced carrier phase (TDCP) cancels it.

Epochs store a padded block of ``K`` satellite slots (the most visible at
any epoch): arrays ``(m, K)`` with ``valid`` marking the used slots, so a
filter reads one epoch as contiguous rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..attitude import quat_to_dcm
from ..data import Trajectory
from ..geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from .clock import simulate_clock
from .geometry import C_LIGHT, LAMBDA_L1, earth_rotation_correction, elevation_azimuth

__all__ = ["GnssObservations", "SatelliteOutage", "simulate_observables"]


@dataclass(frozen=True)
class SatelliteOutage:
    """Satellites lost in ``[start, end)`` [s]: the listed ``prns``, or all but
    the ``keep`` highest (``keep = 0``: every satellite); with ``fraction``
    only at ``round(fraction * n)`` of the window's ``n`` epochs, drawn at
    random (after the clock walk, so runs without a fraction keep their draws)."""

    start: float
    end: float
    prns: tuple = ()
    keep: int | None = None
    fraction: float | None = None


@dataclass(frozen=True)
class GnssObservations:
    """Observables of ``m`` epochs in ``K`` satellite slots.

    Attributes
    ----------
    time : ndarray (m,)
        Receive times [s] (the IMU time scale).
    valid : ndarray of bool (m, K)
    prn : ndarray of int (m, K)
        -1 in unused slots.
    sat_pos, sat_vel : ndarray (m, K, 3)
        ECEF at transmit time, already rotated into the receive-time ECEF
        frame [m], [m/s].
    pseudorange, range_rate, carrier : ndarray (m, K)
        [m], [m/s], [m] (NaN in unused slots). Satellite clocks are already
        removed (as a receiver does with the broadcast clock).
    elevation : ndarray (m, K)
        [rad].
    sigma_pr, sigma_rr, sigma_cp : float
        1-sigma the filters are told [m], [m/s], [m].
    clock : ndarray (m, 2)
        True receiver clock bias [m] and drift [m/s] (for scoring).
    pr_variance : ndarray (m, K) or None
        Per-slot pseudorange variance [m^2] the filters are told instead of ``sigma_pr^2``
        (e.g. elevation-dependent, for recorded data); None: ``sigma_pr^2`` everywhere.
    system : ndarray of int (m, K) or None
        System code of each slot (:data:`mixnav.gnss.pseudoranges.SYSTEM_LETTERS`: 1 GPS,
        4 GLONASS, 8 Galileo, 16 QZSS, 32 BeiDou; 0 in unused slots); ``prn`` then numbers
        the satellite within its system. None: every satellite is GPS.
    carrier_continuous : ndarray of bool (m, K) or None
        True where the slot's carrier continues its satellite's carrier of the previous epoch
        without a cycle slip (:mod:`mixnav.gnss.cycle_slips`: recorded carriers); a TDCP is
        formed only there. None: every carrier is one arc per satellite (the simulator's).
    """

    time: np.ndarray
    valid: np.ndarray
    prn: np.ndarray
    sat_pos: np.ndarray
    sat_vel: np.ndarray
    pseudorange: np.ndarray
    range_rate: np.ndarray
    carrier: np.ndarray
    elevation: np.ndarray
    sigma_pr: float
    sigma_rr: float
    sigma_cp: float
    clock: np.ndarray
    pr_variance: np.ndarray | None = None
    system: np.ndarray | None = None
    carrier_continuous: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.time)

    @property
    def n_visible(self) -> np.ndarray:
        return self.valid.sum(axis=1)


def _antenna_state(truth: Trajectory, k: int, lever: np.ndarray):
    """Antenna ECEF position and velocity at truth sample ``k``."""
    C_nb = quat_to_dcm(truth.q_nb[k])
    lat, lon = truth.lla[k, 0], truth.lla[k, 1]
    C_ne = dcm_ecef_to_ned(lat, lon)
    r = lla_to_ecef(truth.lla[k]) + C_ne.T @ (C_nb @ lever)
    w_b = truth.extra.get("w_ib_b")
    w = w_b[k] if w_b is not None else np.zeros(3)
    v_n = truth.v_n[k] + C_nb @ np.cross(w, lever)
    return r, C_ne.T @ v_n


def simulate_observables(truth: Trajectory, satellites, rate: float, lever_arm, mask_angle: float,
                         sigma_pr: float, sigma_rr: float, sigma_cp: float,
                         clock_q: tuple[float, float], clock0: tuple[float, float],
                         rng: np.random.Generator, *, outages=(), satellite_outages=(),
                         pseudorange_noise=None, range_rate_noise=None, carrier_noise=None,
                         time_offset: float = 0.0, system_offsets=None) -> GnssObservations:
    """Observables of the antenna every ``1 / rate`` s on the truth's time grid.

    Parameters
    ----------
    truth : Trajectory
        At the IMU rate; epochs fall on its samples.
    satellites : object with ``states(t) -> SatelliteStates``
        E.g. :class:`mixnav.gnss.constellation.NominalConstellation`; called
        with one transmit time per satellite, ``time_offset + t - tau`` (n,).
    rate : float
        [Hz].
    lever_arm : ndarray (3,)
        Antenna in the body frame [m].
    mask_angle : float
        [rad].
    sigma_pr, sigma_rr, sigma_cp : float
        Gaussian noise 1-sigma of pseudorange [m], range rate [m/s], carrier
        [m]; also what the filters are told. A noise process given for an
        observable replaces its Gaussian noise (sampled per satellite of the
        source, one channel each, then placed in the slots).
    clock_q : (q_bias [m^2/s], q_drift [m^2/s^3])
    clock0 : (bias [m], drift [m/s]) at the first epoch.
    rng : numpy.random.Generator
        The run's ``gnss`` stream.
    outages : sequence of (start, end)
        No observation at all in these windows.
    satellite_outages : sequence of SatelliteOutage
    system_offsets : dict of int -> float, optional
        Several systems: the receiver's inter-system offset [m] of a system code (the
        pseudoranges and carriers of its satellites carry it); absent codes: zero.
    """
    lever = np.asarray(lever_arm, dtype=float)
    step = int(round(1.0 / (rate * np.median(np.diff(truth.time)))))
    idx = np.arange(step, len(truth.time), step)
    t = truth.time[idx]
    keep = np.ones(len(t), bool)
    for a, b in outages:
        keep &= ~((t >= a) & (t < b))
    idx, t = idx[keep], t[keep]
    m = len(t)
    clock = simulate_clock(t, clock_q[0], clock_q[1], clock0[0], clock0[1], rng)
    active = []  # per outage: bool (m,) of the epochs where it applies
    for o in satellite_outages:
        inside = (t >= o.start) & (t < o.end)
        if o.fraction is not None:
            idx_in = np.nonzero(inside)[0]
            pick = rng.choice(idx_in, size=int(round(o.fraction * len(idx_in))), replace=False)
            inside = np.zeros(m, bool)
            inside[pick] = True
        active.append(inside)

    n_sat = len(satellites.states(time_offset).prn)
    per_epoch = []
    for j, k in enumerate(idx):
        r, v = _antenna_state(truth, k, lever)
        # transmit time by fixed-point passes on the travel time (3 passes: < 1e-12 s);
        # states() takes one time per satellite
        tau = np.full(n_sat, 0.075)
        for _ in range(3):
            s = satellites.states(time_offset + t[j] - tau)
            p = earth_rotation_correction(s.pos_ecef, tau)
            tau = np.linalg.norm(p - r, axis=1) / C_LIGHT
        vs = earth_rotation_correction(s.vel_ecef, tau)
        el, _ = elevation_azimuth(r, p)
        vis = el >= mask_angle
        for o, on in zip(satellite_outages, active):
            if on[j]:
                if o.keep is not None:
                    order = np.argsort(-np.where(vis, el, -np.inf))
                    lost = np.ones(len(el), bool)
                    lost[order[:o.keep]] = False
                    vis &= ~lost
                else:
                    vis &= ~np.isin(s.prn, o.prns)
        per_epoch.append((r, v, s.select(vis), p[vis], vs[vis], el[vis], tau[vis]))
    K = max([len(e[3]) for e in per_epoch], default=0)
    valid = np.zeros((m, K), bool)
    prn = np.full((m, K), -1, dtype=int)
    sat_pos = np.zeros((m, K, 3))
    sat_vel = np.zeros((m, K, 3))
    geo = np.full((m, K), np.nan)
    rr = np.full((m, K), np.nan)
    elev = np.full((m, K), np.nan)
    for j, (r, v, s, p, vs, el, tau) in enumerate(per_epoch):
        n = len(p)
        valid[j, :n] = True
        prn[j, :n] = s.prn
        sat_pos[j, :n], sat_vel[j, :n], elev[j, :n] = p, vs, el
        d = p - r
        rng_geo = np.linalg.norm(d, axis=1)
        geo[j, :n] = rng_geo
        # rate of the travelled distance: the transmit time moves with the receive
        # time as 1 - d(tau)/dt, so u.v_s counts (1 - rr/c): solve for rr (a 1e-6
        # relative, mm/s, term that tight filters leave out)
        u = d / rng_geo[:, None]
        us = np.einsum("ij,ij->i", u, vs)
        rr[j, :n] = (us - u @ v) / (1.0 + us / C_LIGHT)

    # Noise is drawn per satellite (one channel per satellite of the source, over all
    # epochs) and then gathered into the slots, so a coloured process (AR(1), bias
    # segments) follows its satellite even when the slot it occupies changes as
    # satellites rise and set; process ``channels`` are satellite indices of the source.
    all_sat = np.asarray(satellites.states(time_offset).prn)
    order = np.argsort(all_sat)
    col = order[np.searchsorted(all_sat[order], np.where(valid, prn, all_sat[order[0]]))]
    rows = np.arange(m)[:, None]

    def noise(process, sigma):
        if process is not None:
            e = process.sample(t, n_sat, rng)
        else:
            e = rng.standard_normal((m, n_sat)) * sigma
        return np.where(valid, e[rows, col], np.nan)

    pr = geo + clock[:, :1] + noise(pseudorange_noise, sigma_pr)
    rrate = rr + clock[:, 1:] + noise(range_rate_noise, sigma_rr)
    # one integer ambiguity per satellite for the whole run
    all_prn = np.unique(prn[valid])
    amb = dict(zip(all_prn.tolist(), rng.integers(-10 ** 6, 10 ** 6, len(all_prn))))
    N = np.where(valid, np.vectorize(lambda q: amb.get(q, 0))(prn), 0) if K else np.zeros((m, 0))
    system, wavelength = None, LAMBDA_L1
    if hasattr(satellites, "split_ids"):     # several systems: the ids into systems and numbers
        system, prn = satellites.split_ids(prn)
        system = np.where(valid, system, 0)
        prn = np.where(valid, prn, -1)
        wavelength = _wavelengths(system, prn, getattr(satellites, "glonass_channels", {}))
        off = np.zeros((m, K))
        for code, v in (system_offsets or {}).items():
            off[system == int(code)] = float(v)
        pr = pr + off
        geo = geo + off
    cp = geo + clock[:, :1] + wavelength * N + noise(carrier_noise, sigma_cp)
    return GnssObservations(time=t, valid=valid, prn=prn, sat_pos=sat_pos, sat_vel=sat_vel,
                            pseudorange=pr, range_rate=rrate, carrier=cp, elevation=elev,
                            sigma_pr=float(sigma_pr), sigma_rr=float(sigma_rr),
                            sigma_cp=float(sigma_cp), clock=clock, system=system)


def _wavelengths(system: np.ndarray, prn: np.ndarray, glonass_channels: dict) -> np.ndarray:
    """First-frequency carrier wavelength [m] of each slot (:func:`mixnav.gnss.spp.first_frequency`;
    NaN in unused slots)."""
    from .pseudoranges import SYSTEM_LETTERS
    from .spp import first_frequency
    letters = np.array([SYSTEM_LETTERS.get(int(c), "G") for c in system.ravel()])
    chan = np.array([glonass_channels.get(int(p), 99) for p in prn.ravel()])
    f = first_frequency(letters, chan).reshape(system.shape)
    return np.where(system > 0, C_LIGHT / f, np.nan)

