"""Nominal GPS, Galileo, BeiDou (MEO) and GLONASS constellations from Keplerian elements,
for simulation.

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

The other systems (:meth:`NominalConstellation.galileo`, :meth:`~NominalConstellation.beidou`,
:meth:`~NominalConstellation.glonass`) are Walker 24/3/1 constellations (3 planes 120 deg
apart, 8 slots 45 deg apart in a plane, each plane's slots 15 deg on from the previous
one's) with each system's nominal orbit and its own ``GM`` and Earth rotation rate (those
its broadcast orbits are evaluated with, :mod:`mixnav.gnss.orbits`):

======== ================== =========== ==========================================
system   semi-major axis    inclination source
======== ================== =========== ==========================================
Galileo  29 600 318 m       56 deg      Galileo OS SIS ICD 2.0 (nominal orbit)
BeiDou   27 906 100 m       55 deg      BDS-SIS-ICD-OS 3.0: MEO at 21 528 km altitude
GLONASS  25 508 000 m       64.8 deg    GLONASS ICD 5.1: period 11 h 15 min 44 s, 64.8 deg
======== ================== =========== ==========================================

(GLONASS's axis is Kepler's third law of the ICD's period with PZ-90's GM; BeiDou's is the
altitude plus the WGS-84 equatorial radius. BeiDou's GEO and IGSO satellites are not
simulated.) GLONASS satellites fly as a receiver
computes them from the broadcast records (:class:`GlonassBroadcastOrbits`): a state vector
every 30 min taken from the nominal orbit, integrated (:func:`mixnav.gnss.orbits.glonass_states`,
J2, RK4) from the nearest one, so RINEX navigation records written from those states give
back the simulated satellites. :class:`MultiConstellation`
puts several together: one satellite id per satellite, the GPS PRN for GPS and
``1000 * system code + number`` for the others, so GPS PRNs keep their meaning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import GM_GPS, OMEGA_E_GPS, SatelliteStates

__all__ = ["NominalConstellation", "MultiConstellation", "GlonassBroadcastOrbits", "SEMI_MAJOR_AXIS", "INCLINATION", "GLONASS_CHANNELS"]

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
    gm, omega_e : float
        Gravitational constant [m^3/s^2] and Earth rotation rate [rad/s] of the system
        (GPS's by default).
    """

    raan: np.ndarray
    arg_lat: np.ndarray
    prn: np.ndarray
    semi_major_axis: float = SEMI_MAJOR_AXIS
    inclination: float = INCLINATION
    gm: float = GM_GPS
    omega_e: float = OMEGA_E_GPS

    @classmethod
    def walker(cls, semi_major_axis: float, inclination: float, gm: float, omega_e: float, planes: int = 3,
               per_plane: int = 8, phasing: int = 1, raan_offset: float = 0.0,
               phase_offset: float = 0.0) -> "NominalConstellation":
        """A Walker ``planes * per_plane / planes / phasing`` constellation: planes
        ``360 / planes`` deg apart, slots ``360 / per_plane`` deg apart, plane ``p``'s
        slots shifted by ``p * phasing * 360 / (planes * per_plane)`` deg; numbers 1, 2, ...
        plane by plane (GLONASS's slot numbering)."""
        plane = np.repeat(np.arange(planes), per_plane)
        slot = np.tile(np.arange(per_plane), planes)
        raan = 2 * np.pi * plane / planes + raan_offset
        arg_lat = 2 * np.pi * slot / per_plane + 2 * np.pi * phasing * plane / (planes * per_plane) + phase_offset
        return cls(raan=raan, arg_lat=arg_lat, prn=np.arange(1, planes * per_plane + 1),
                   semi_major_axis=float(semi_major_axis), inclination=float(inclination), gm=float(gm),
                   omega_e=float(omega_e))

    @classmethod
    def galileo(cls, raan_offset: float = np.radians(20.0), phase_offset: float = 0.0) -> "NominalConstellation":
        """Galileo's 24 nominal slots (module docstring; Galileo ``GM``, ``Omega_e``).
        ``raan_offset`` turns its planes away from GPS's (20 deg by default)."""
        from .orbits import GALILEO
        return cls.walker(29_600_318.0, np.radians(56.0), GALILEO.gm, GALILEO.omega_e,
                          raan_offset=raan_offset, phase_offset=phase_offset)

    @classmethod
    def beidou(cls, raan_offset: float = np.radians(40.0), phase_offset: float = 0.0) -> "NominalConstellation":
        """BeiDou's 24 MEO slots (module docstring; CGCS2000 ``GM``, ``Omega_e``), numbered
        with BDS-3's MEO PRNs (:data:`BEIDOU_MEO_PRNS`: never a GEO number, which the
        broadcast orbits would turn by the GEO rotation)."""
        from .orbits import BEIDOU
        c = cls.walker(27_906_100.0, np.radians(55.0), BEIDOU.gm, BEIDOU.omega_e,
                       raan_offset=raan_offset, phase_offset=phase_offset)
        return cls(c.raan, c.arg_lat, np.array(BEIDOU_MEO_PRNS), c.semi_major_axis, c.inclination, c.gm, c.omega_e)

    @classmethod
    def glonass(cls, raan_offset: float = np.radians(10.0), phase_offset: float = 0.0) -> "NominalConstellation":
        """GLONASS's 24 slots (module docstring; PZ-90 ``GM``, ``Omega_e``), numbered as
        the ICD's slots 1-24 (frequency channels: :data:`GLONASS_CHANNELS`)."""
        from .orbits import GLONASS
        return cls.walker(25_508_000.0, np.radians(64.8), GLONASS.gm, GLONASS.omega_e,
                          raan_offset=raan_offset, phase_offset=phase_offset)

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
        return float(np.sqrt(self.gm / self.semi_major_axis ** 3))

    def states(self, t: float) -> SatelliteStates:
        """Positions and velocities (ECEF) of all satellites at time ``t`` [s] after t = 0."""
        n, a, i = self.mean_motion, self.semi_major_axis, self.inclination
        u = self.arg_lat + n * t
        cu, su = np.cos(u), np.sin(u)
        # node longitude in the rotating frame decreases with Earth rotation
        w_e = self.omega_e
        om = self.raan - w_e * t
        co, so = np.cos(om), np.sin(om)
        ci, si = np.cos(i), np.sin(i)
        x = a * (cu * co - su * ci * so)
        y = a * (cu * so + su * ci * co)
        z = a * su * si
        # d/dt with du/dt = n and d(om)/dt = -w_e
        dx = a * n * (-su * co - cu * ci * so) + w_e * y
        dy = a * n * (-su * so + cu * ci * co) - w_e * x
        dz = a * n * cu * si
        m = len(self.prn)
        return SatelliteStates(prn=self.prn.copy(), pos_ecef=np.stack([x, y, z], axis=-1),
                               vel_ecef=np.stack([dx, dy, dz], axis=-1),
                               clock_bias=np.zeros(m), clock_drift=np.zeros(m))

    def broadcast_records(self, gps_t0: float, toe, time_system: str = "G") -> dict:
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

        A BeiDou record (``time_system = "C"``) gives its week, ``t_oe`` and ``t_oc`` in BDT
        (``GPST - 14 s``, weeks from 2006-01-01), and ``OMEGA0`` counts from the start of that
        BDT week; Galileo's (``"E"``) are in GST, which RINEX writes on GPS's weeks.

        Parameters
        ----------
        gps_t0 : float
            GPS time of this constellation's ``t = 0``, seconds since 1980-01-06 00:00 [s].
        toe : array_like (r,)
            Reference times of the records, GPS seconds since 1980-01-06 [s]; one record
            per satellite and time.
        time_system : "G", "E" or "C"

        Returns
        -------
        dict of str -> ndarray (r * n,)
            ``prn``, ``week``, ``toe``, ``toc_week``, ``toc`` and the Keplerian and clock
            parameters (rad, rad/s, m^(1/2), s), records grouped by time.
        """
        toe = np.atleast_1d(np.asarray(toe, dtype=float))
        n_sat = len(self.prn)
        t_abs = np.repeat(toe, n_sat)
        t_sim = t_abs - gps_t0
        if time_system == "C":   # BDT: GPST - 14 s, weeks counted from 2006-01-01 (GPS week 1356)
            from .gnss_time import BDT_OFFSET_S, BDT_WEEK_OFFSET
            t_own = t_abs - BDT_OFFSET_S - BDT_WEEK_OFFSET * 604800.0
            week = np.floor(t_own / 604800.0)
            tow = t_own - week * 604800.0
            week_start_gps = (week + BDT_WEEK_OFFSET) * 604800.0 + BDT_OFFSET_S
        else:
            week = np.floor(t_abs / 604800.0)
            tow = t_abs - week * 604800.0
            week_start_gps = week * 604800.0
        wrap = lambda a: np.mod(a + np.pi, 2 * np.pi) - np.pi  # noqa: E731
        raan = np.tile(self.raan, len(toe))
        zeros = np.zeros(len(t_abs))
        rec = {k: zeros.copy() for k in ("af0", "af1", "af2", "crs", "delta_n", "cuc", "e", "cus", "cic", "cis",
                                         "crc", "omega", "omega_dot", "idot", "health", "tgd")}
        rec.update(prn=np.tile(self.prn, len(toe)).astype(np.int64), week=week, toe=tow, toc_week=week.copy(),
                   toc=tow.copy(), sqrt_a=np.full(len(t_abs), np.sqrt(self.semi_major_axis)),
                   i0=np.full(len(t_abs), self.inclination),
                   m0=wrap(np.tile(self.arg_lat, len(toe)) + self.mean_motion * t_sim),
                   omega0=wrap(raan + self.omega_e * (gps_t0 - week_start_gps)))
        return rec


#: GLONASS frequency channel of each orbital slot 1-24 (antipodal slots of a plane share
#: one), the plan the GLONASS operator (IAC, glonass-iac.ru) publishes.
GLONASS_CHANNELS = {1: 1, 2: -4, 3: 5, 4: 6, 5: 1, 6: -4, 7: 5, 8: 6, 9: -2, 10: -7, 11: 0, 12: -1, 13: -2,
                    14: -7, 15: 0, 16: -1, 17: 4, 18: -3, 19: 3, 20: 2, 21: 4, 22: -3, 23: 3, 24: 2}

#: BDS-3 MEO PRNs (C19-C30, C32-C37, C41-C46), the BeiDou nominal constellation's numbers
BEIDOU_MEO_PRNS = tuple(range(19, 31)) + tuple(range(32, 38)) + tuple(range(41, 47))

#: RINEX letter -> system code (:data:`mixnav.gnss.pseudoranges.SYSTEM_LETTERS`)
_CODES = {"G": 1, "R": 4, "E": 8, "J": 16, "C": 32}
#: the satellite id of a non-GPS satellite: ``ID_SYSTEM * code + number``
ID_SYSTEM = 1000


@dataclass(frozen=True)
class GlonassBroadcastOrbits:
    """GLONASS satellites integrated from broadcast-style state vectors (module docstring).

    Parameters
    ----------
    nominal : NominalConstellation
        The orbits the state vectors are taken from (:meth:`NominalConstellation.glonass`).
    interval : float
        Time between records [s] (GLONASS's ``t_b`` every 30 min); the records are at
        whole multiples of it in the simulation's time, and a query at ``t`` integrates from
        the nearest, ``round(t / interval)``: what the navigation reader picks from records
        written on the same grid.
    """

    nominal: NominalConstellation
    interval: float = 1800.0

    @property
    def prn(self) -> np.ndarray:
        return self.nominal.prn

    def records(self, t_b) -> dict:
        """The state vectors at reference times ``t_b`` (r,) [s of simulation time], one per
        satellite and time, grouped by time: ``prn``, ``tb``, ``pos``, ``vel`` (ECEF, [m],
        [m/s]), ``acc`` (zero: no luni-solar term), ``minus_tau_n``, ``gamma_n`` (zero: the
        simulated satellite clocks are perfect)."""
        t_b = np.atleast_1d(np.asarray(t_b, float))
        n = len(self.nominal.prn)
        tb = np.repeat(t_b, n)
        st = [self.nominal.states(t) for t in t_b]
        zeros = np.zeros(len(tb))
        return {"prn": np.tile(self.nominal.prn, len(t_b)), "tb": tb,
                "pos": np.vstack([x.pos_ecef for x in st]), "vel": np.vstack([x.vel_ecef for x in st]),
                "acc": np.zeros((len(tb), 3)), "minus_tau_n": zeros, "gamma_n": zeros.copy()}

    def states(self, t) -> SatelliteStates:
        """Every satellite at time(s) ``t`` [s] (scalar or one per satellite), integrated from
        its record nearest ``t``."""
        from .orbits import glonass_states
        n = len(self.nominal.prn)
        t = np.broadcast_to(np.asarray(t, float), (n,)).copy()
        tb = np.floor(t / self.interval + 0.5) * self.interval
        start = self.nominal.states(tb)
        r = {"tb": tb, "pos": start.pos_ecef, "vel": start.vel_ecef, "acc": np.zeros((n, 3)),
             "minus_tau_n": np.zeros(n), "gamma_n": np.zeros(n)}
        pos, vel, clk, drift = glonass_states(r, t)
        return SatelliteStates(prn=self.nominal.prn.copy(), pos_ecef=pos, vel_ecef=vel, clock_bias=clk,
                               clock_drift=drift)


@dataclass(frozen=True)
class MultiConstellation:
    """Several systems' nominal constellations as one source of satellite states.

    Parameters
    ----------
    parts : tuple of (str, NominalConstellation)
        RINEX system letter and constellation, e.g. ``(("G", gps), ("E", galileo))``.

    :meth:`states` numbers the satellites by one id each (module docstring);
    :meth:`split_ids` turns ids into (system code, number within the system).
    """

    parts: tuple

    def __post_init__(self):
        letters = [p[0] for p in self.parts]
        if not letters or len(set(letters)) != len(letters) or not set(letters) <= set(_CODES):
            raise ValueError(f"give distinct systems among {', '.join(_CODES)}, got {letters}")

    @classmethod
    def of(cls, systems, gps: NominalConstellation | None = None) -> "MultiConstellation":
        """The nominal constellations of ``systems`` (letters G, R, E, C), GPS's being ``gps``
        (default :meth:`NominalConstellation.gps` with 5 slots per plane)."""
        make = {"G": lambda: gps if gps is not None else NominalConstellation.gps(5),
                "E": NominalConstellation.galileo, "C": NominalConstellation.beidou,
                "R": lambda: GlonassBroadcastOrbits(NominalConstellation.glonass())}
        bad = [s for s in systems if s not in make]
        if bad:
            raise ValueError(f"no nominal constellation for {bad} (these have one: {', '.join(make)})")
        return cls(tuple((s, make[s]()) for s in systems))

    @property
    def ids(self) -> np.ndarray:
        """The satellite id of every satellite, in :meth:`states` order."""
        return np.concatenate([c.prn if s == "G" else ID_SYSTEM * _CODES[s] + c.prn for s, c in self.parts])

    @staticmethod
    def split_ids(ids):
        """``(system code, number within the system)`` of satellite ids (arrays of int)."""
        ids = np.asarray(ids)
        system = np.where(ids < ID_SYSTEM, 1, ids // ID_SYSTEM)
        return system, np.where(ids < ID_SYSTEM, ids, ids % ID_SYSTEM)

    def part(self, letter: str):
        """One system's constellation."""
        for s, c in self.parts:
            if s == letter:
                return c
        raise KeyError(letter)

    @property
    def glonass_channels(self) -> dict:
        """GLONASS slot -> frequency channel (:data:`GLONASS_CHANNELS`), empty without GLONASS."""
        if not any(s == "R" for s, _ in self.parts):
            return {}
        return {int(p): GLONASS_CHANNELS[int(p)] for p in self.part("R").prn}

    def states(self, t) -> SatelliteStates:
        """Every satellite's state at time(s) ``t`` [s] (a scalar, or one time per
        satellite in :attr:`ids` order); ``prn`` holds the ids."""
        t = np.asarray(t, dtype=float)
        out, k = [], 0
        for _, c in self.parts:
            n = len(c.prn)
            out.append(c.states(t if t.ndim == 0 else t[k:k + n]))
            k += n
        return SatelliteStates(prn=self.ids, pos_ecef=np.vstack([o.pos_ecef for o in out]),
                               vel_ecef=np.vstack([o.vel_ecef for o in out]),
                               clock_bias=np.concatenate([o.clock_bias for o in out]),
                               clock_drift=np.concatenate([o.clock_drift for o in out]))
