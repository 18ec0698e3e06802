"""A nominal GPS constellation from Keplerian elements, for simulation.

Six orbital planes (A-F) 60 deg apart in right ascension, inclination 55 deg,
circular orbits of semi-major axis 26 559.7 km (period half a sidereal day),
``k`` slots per plane evenly spaced in argument of latitude, each plane's
slots shifted by ``360 / (6 k)`` deg from the previous one's so the planes
interleave. With ``k = 4`` this is the shape of the 24-slot constellation of
the GPS SPS Performance Standard (whose slot table spaces slots unevenly to
soften coverage holes); it shows 6-8 satellites above 10 deg at 34 deg
latitude. Today's ~31 satellites give 8-12: ``k = 5`` (30 satellites) is
closer to that. Satellite clocks are perfect (zero offset
and drift): a simulation measures the receiver clock, not the satellite's.

Positions are exact two-body circular motion: no perturbations, which only
matters if simulated satellites are compared with real ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import GM_GPS, OMEGA_E_GPS, SatelliteStates

__all__ = ["NominalConstellation", "SEMI_MAJOR_AXIS", "INCLINATION"]

#: Nominal GPS semi-major axis [m] and inclination [rad].
SEMI_MAJOR_AXIS = 26_559_700.0
INCLINATION = np.radians(55.0)


@dataclass(frozen=True)
class NominalConstellation:
    """Circular-orbit satellites at a reference time ``t = 0``.

    Parameters
    ----------
    raan : ndarray (n,)
        Right ascension of the ascending node at ``t = 0`` [rad], counted in
        the ECEF frame of that instant (so longitude of the node at t = 0).
    arg_lat : ndarray (n,)
        Argument of latitude at ``t = 0`` [rad].
    prn : ndarray of int (n,)
    semi_major_axis : float
        [m].
    inclination : float
        [rad].
    """

    raan: np.ndarray
    arg_lat: np.ndarray
    prn: np.ndarray
    semi_major_axis: float = SEMI_MAJOR_AXIS
    inclination: float = INCLINATION

    @classmethod
    def gps(cls, slots_per_plane: int = 4, raan_offset: float = 0.0,
            phase_offset: float = 0.0) -> "NominalConstellation":
        """The 6-plane constellation of the module docstring, ``6 * slots_per_plane`` satellites.

        ``raan_offset`` and ``phase_offset`` [rad] turn the whole constellation,
        so a scenario can choose which geometry its receiver sees. PRNs are
        1, 2, ... plane by plane.
        """
        k = int(slots_per_plane)
        if k < 4:
            raise ValueError(f"slots_per_plane must be at least 4 (24 satellites), got {slots_per_plane}")
        plane = np.repeat(np.arange(6), k)
        slot = np.tile(np.arange(k), 6)
        raan = np.radians(60.0) * plane + raan_offset
        arg_lat = 2 * np.pi * slot / k + 2 * np.pi * plane / (6 * k) + phase_offset
        return cls(raan=raan, arg_lat=arg_lat, prn=np.arange(1, 6 * k + 1))

    @property
    def mean_motion(self) -> float:
        """[rad/s]."""
        return float(np.sqrt(GM_GPS / self.semi_major_axis ** 3))

    def states(self, t: float) -> SatelliteStates:
        """Positions and velocities (ECEF) of all satellites at time ``t`` [s] after t = 0."""
        n, a, i = self.mean_motion, self.semi_major_axis, self.inclination
        u = self.arg_lat + n * t
        cu, su = np.cos(u), np.sin(u)
        # node longitude in the rotating frame decreases with Earth rotation
        om = self.raan - OMEGA_E_GPS * t
        co, so = np.cos(om), np.sin(om)
        ci, si = np.cos(i), np.sin(i)
        x = a * (cu * co - su * ci * so)
        y = a * (cu * so + su * ci * co)
        z = a * su * si
        # d/dt with du/dt = n and d(om)/dt = -w_e
        dx = a * n * (-su * co - cu * ci * so) + OMEGA_E_GPS * y
        dy = a * n * (-su * so + cu * ci * co) - OMEGA_E_GPS * x
        dz = a * n * cu * si
        m = len(self.prn)
        return SatelliteStates(prn=self.prn.copy(), pos_ecef=np.stack([x, y, z], axis=-1),
                               vel_ecef=np.stack([dx, dy, dz], axis=-1),
                               clock_bias=np.zeros(m), clock_drift=np.zeros(m))

    def broadcast_records(self, gps_t0: float, toe) -> dict:
        """The constellation as GPS broadcast ephemeris records (the ``records`` of
        :class:`mixnav.gnss.ephemeris.BroadcastEphemeris`, what a RINEX navigation file holds).

        A circular two-body orbit is a broadcast orbit with ``e = 0``, argument of perigee
        0 (the mean anomaly is then the argument of latitude), ``delta_n``, ``IDOT``,
        ``OMEGA_DOT`` and the six harmonic corrections zero; clocks (``af0..af2``,
        ``T_GD``) zero, as the constellation's (and the relativistic term is zero at
        ``e = 0``). With ``t`` the time after this constellation's ``t = 0`` and
        ``t_oe`` that of the record: ``M0 = arg_lat + n t_oe`` and, since the broadcast
        node longitude is ``OMEGA0 - w_e (t_abs - week 604800)``, ``OMEGA0 = raan + w_e
        (gps_t0 - week 604800)`` (the record's week).

        Parameters
        ----------
        gps_t0 : float
            GPS time of this constellation's ``t = 0``, seconds since 1980-01-06 00:00 [s].
        toe : array_like (r,)
            Reference times of the records, GPS seconds since 1980-01-06 [s]; one record
            per satellite and time.

        Returns
        -------
        dict of str -> ndarray (r * n,)
            ``prn``, ``week``, ``toe``, ``toc_week``, ``toc`` and the Keplerian and clock
            parameters (rad, rad/s, m^(1/2), s), records grouped by time.
        """
        toe = np.atleast_1d(np.asarray(toe, dtype=float))
        n_sat = len(self.prn)
        t_abs = np.repeat(toe, n_sat)
        week = np.floor(t_abs / 604800.0)
        tow = t_abs - week * 604800.0
        t_sim = t_abs - gps_t0
        wrap = lambda a: np.mod(a + np.pi, 2 * np.pi) - np.pi  # noqa: E731
        raan = np.tile(self.raan, len(toe))
        zeros = np.zeros(len(t_abs))
        rec = {k: zeros.copy() for k in ("af0", "af1", "af2", "crs", "delta_n", "cuc", "e", "cus", "cic", "cis",
                                         "crc", "omega", "omega_dot", "idot", "health", "tgd")}
        rec.update(prn=np.tile(self.prn, len(toe)).astype(np.int64), week=week, toe=tow, toc_week=week.copy(),
                   toc=tow.copy(), sqrt_a=np.full(len(t_abs), np.sqrt(self.semi_major_axis)),
                   i0=np.full(len(t_abs), self.inclination),
                   m0=wrap(np.tile(self.arg_lat, len(toe)) + self.mean_motion * t_sim),
                   omega0=wrap(raan + OMEGA_E_GPS * (gps_t0 - week * 604800.0)))
        return rec
