"""Geodetic <-> local conversion around the simulator's geodetic origin (flat earth).

The world origin (ENU 0, 0, 0) is at ``(home_lat, home_lon, home_alt)`` of the
autopilot's configuration (:class:`~vehicle_sim.autopilot.config.AutopilotConfig`) for
every vehicle, so all vehicles share one map. Local offsets here are NED (north, east,
down, metres), the MAVLink side; turn them into our ENU maths frame with
:func:`swarm_common.frames.ned_to_enu`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarm_common.world.geodesy import EARTH_R, north_east_of

__all__ = ["EARTH_R", "down_from_amsl", "latlon_e7", "ned_from_latlon"]


def latlon_e7(cfg: Any, ned: np.ndarray) -> tuple[int, int]:
    """(lat, lon) in degE7 of a NED offset (m) from the geodetic origin."""
    lat = cfg.home_lat + math.degrees(float(ned[0]) / EARTH_R)
    lon = cfg.home_lon + math.degrees(
        float(ned[1]) / (EARTH_R * math.cos(math.radians(cfg.home_lat)))
    )
    return int(round(lat * 1e7)), int(round(lon * 1e7))


def ned_from_latlon(cfg: Any, lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """(north, east) in metres of a latitude/longitude (degrees) from ``cfg``'s origin
    (:func:`swarm_common.world.geodesy.north_east_of`, the daemons' reading too)."""
    return north_east_of(lat_deg, lon_deg, cfg.home_lat, cfg.home_lon)


def down_from_amsl(cfg: Any, alt_amsl_m: float) -> float:
    """NED down (m) of an altitude above mean sea level (the ground is at ``home_alt``)."""
    return float(cfg.home_alt - alt_amsl_m)
