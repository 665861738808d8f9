"""The geodetic origin every simulated vehicle shares by default, and flat-earth
conversion about an origin.

One definition for the simulator (:mod:`vehicle_sim.physics.geo`, which writes positions
as latitude/longitude) and the offboard daemon (which reads a fence uploaded to its
vehicle back into the filter's ENU frame, :mod:`swarm_common.world.mavlink_fence`): the
two must invert each other exactly, or a fence the filter takes from its vehicle would be
shifted from the one the simulator checks. The origin is PX4 SITL's default home (Zurich);
ENU (0, 0, 0) sits there, on the ground.
"""

from __future__ import annotations

import math

EARTH_R = 6378137.0  # m, WGS-84 equatorial radius
ORIGIN_LAT_DEG = 47.397742  # PX4 SITL default home
ORIGIN_LON_DEG = 8.545594
ORIGIN_ALT_M = 488.0  # AMSL of the ground at the origin
DEG_E7 = 1e7  # MAVLink's integer degrees
MAX_LAT_DEG = 85.0  # an origin nearer a pole: the flat-earth conversion does not hold
ORIGIN_SAME_M = 0.01  # two origins this close are one (the degE7 rounding is about 1 cm)

# a geodetic origin, (latitude, longitude) in degrees
Origin = tuple[float, float]
DEFAULT_ORIGIN: Origin = (ORIGIN_LAT_DEG, ORIGIN_LON_DEG)


def north_east_of(lat_deg: float, lon_deg: float, origin_lat_deg: float = ORIGIN_LAT_DEG,
                  origin_lon_deg: float = ORIGIN_LON_DEG) -> tuple[float, float]:
    """(north, east) in metres of a latitude/longitude (degrees) from the origin."""
    north = math.radians(lat_deg - origin_lat_deg) * EARTH_R
    east = (math.radians(lon_deg - origin_lon_deg) * EARTH_R
            * math.cos(math.radians(origin_lat_deg)))
    return north, east


def enu_xy_of_e7(lat_e7: int, lon_e7: int, origin_lat_deg: float = ORIGIN_LAT_DEG,
                 origin_lon_deg: float = ORIGIN_LON_DEG) -> tuple[float, float]:
    """ENU (x east, y north) in metres of a MAVLink latitude/longitude in degE7: the
    inverse, to the degE7 rounding (about 1 cm), of the simulator's
    :func:`vehicle_sim.physics.geo.latlon_e7`."""
    north, east = north_east_of(lat_e7 / DEG_E7, lon_e7 / DEG_E7, origin_lat_deg,
                                origin_lon_deg)
    return east, north


def origin_of_e7(lat_e7: int, lon_e7: int) -> Origin | str:
    """The origin of a GPS_GLOBAL_ORIGIN (degE7, from a socket), or why it is not one: a
    latitude beyond ±MAX_LAT_DEG, a longitude beyond ±180°."""
    lat, lon = lat_e7 / DEG_E7, lon_e7 / DEG_E7
    if not (abs(lat) <= MAX_LAT_DEG and abs(lon) <= 180.0):
        return f"GPS_GLOBAL_ORIGIN latitude/longitude {lat_e7}, {lon_e7} (degE7) out of range"
    return lat, lon


def origin_offset_m(a: Origin, b: Origin) -> float:
    """The distance (m) between two origins, flat-earth about ``b``."""
    north, east = north_east_of(a[0], a[1], b[0], b[1])
    return math.hypot(north, east)
