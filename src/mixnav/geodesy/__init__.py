"""Earth model and coordinate frames (WGS-84).

``earth``  : ellipsoid constants, radii of curvature, normal gravity, Earth
             rate and transport rate in the local NED frame.
``frames`` : geodetic (lat, lon, h) <-> ECEF <-> local NED conversions.
"""

from .earth import (
    A_WGS84,
    E2_WGS84,
    F_WGS84,
    OMEGA_EARTH,
    earth_rate_ned,
    gravity_ned,
    normal_gravity,
    radii,
    transport_rate_ned,
)
from .frames import (
    dcm_ecef_to_ned,
    ecef_to_lla,
    lla_to_ecef,
    lla_to_ned,
    ned_to_lla,
)

__all__ = [
    "A_WGS84", "E2_WGS84", "F_WGS84", "OMEGA_EARTH", "earth_rate_ned", "gravity_ned",
    "normal_gravity", "radii", "transport_rate_ned", "dcm_ecef_to_ned", "ecef_to_lla",
    "lla_to_ecef", "lla_to_ned", "ned_to_lla",
]
