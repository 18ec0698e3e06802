"""Satellites and GNSS observables.

geometry.py      constants of the GPS signal and Earth model used by GNSS code,
                 line-of-sight geometry (elevation, azimuth, Earth rotation
                 during signal travel), the :class:`SatelliteStates` type every
                 satellite source returns
constellation.py nominal GPS constellation (6 planes, circular Kepler orbits) for simulation
signals.py       the systems read (G R E C J), their RINEX pseudorange codes, the default signal per system
clock.py         two-state receiver clock (the filters' ClockModel), sampled exactly
observables.py   simulated pseudorange, range rate, carrier per satellite and epoch
ephemeris.py     GPS broadcast ephemeris from RINEX navigation files (georinex),
                 orbit, velocity and clock per IS-GPS-200
orbits.py        broadcast orbit and clock kernels of every system (Keplerian with
                 per-system constants and the BeiDou GEO case; GLONASS RK4)
gnss_time.py     GPST, BDT, GLONASST and UTC conversions, leap seconds
multi_ephemeris.py  MultiEphemeris: RINEX 2/3 navigation files of any systems, one
                 ephemeris per system letter (G, R, E, C, J)
spp.py           single-point positioning by iterated weighted least squares
"""
