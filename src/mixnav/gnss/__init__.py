"""Satellites and GNSS observables.

geometry.py      constants of the GPS signal and Earth model used by GNSS code,
                 line-of-sight geometry (elevation, azimuth, Earth rotation
                 during signal travel), the :class:`SatelliteStates` type every
                 satellite source returns
"""
