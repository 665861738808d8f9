"""MAVLink mission items and commands as formation missions (pure: no sockets).

What a ground station sends the formation's vehicle becomes a ``[mission]`` table that the
leaders fly (docs/missions.md, "The formation as one vehicle"):

* ``MAV_CMD_NAV_WAYPOINT`` (and ``NAV_LOITER_TIME``) with a position: a formation waypoint
  whose centroid is the item's position (ENU around the simulator's geodetic origin),
  ``hold_s`` = param1, and, when param4 is a number, the formation turned by −param4 degrees
  from its scenario shape (MAVLink headings turn clockwise, our yaw counter-clockwise);
* ``MAV_CMD_DO_CHANGE_SPEED``: the cruise speed (param2, m/s) of the legs after it;
* the formation's scale: the ``FORM_SCALE`` parameter at the time of the command.

Anything else in a mission (take-off, land, return) is refused: the formation flies
waypoints. Every refusal is a :class:`~swarm_common.mission.config.MissionError` line.
"""

from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import common as M

from swarm_common.mission.config import MissionConfig, MissionError, parse_mission
from vehicle_sim.services import mission_items as mi
from vehicle_sim.services.mission_items import Item

WAYPOINT_COMMANDS = frozenset({M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME})


def mission_table(
    waypoints: list[dict[str, Any]], speed_mps: float, base: MissionConfig,
) -> dict[str, Any]:
    """A ``[mission]`` table of ``waypoints`` at ``speed_mps``, with ``base``'s limits."""
    return {
        "speed_mps": speed_mps, "max_speed_mps": base.max_speed_mps,
        "max_accel_mps2": base.max_accel_mps2, "max_jerk_mps3": base.max_jerk_mps3,
        "arrive_radius_m": base.arrive_radius_m, "waypoint": waypoints,
    }


def yaw_of_heading(param4: float, current_deg: float) -> float:
    """The formation's yaw (deg, counter-clockwise) of a MAVLink heading param (deg,
    clockwise); NaN keeps ``current_deg``."""
    return current_deg if math.isnan(param4) else -float(param4)


def items_to_table(
    cfg: Any, items: list[Item], speed_mps: float, scale: float, yaw_deg: float,
    base: MissionConfig,
) -> dict[str, Any]:
    """The ``[mission]`` table of a MISSION store (``cfg``: the geodetic origin)."""
    wps: list[dict[str, Any]] = []
    speed = speed_mps
    for it in items:
        if it.command == M.MAV_CMD_DO_CHANGE_SPEED:
            if not (math.isfinite(it.param2) and it.param2 > 0.0):
                raise MissionError(f"mission item {it.seq}: DO_CHANGE_SPEED speed "
                                   f"{it.param2!r} must be a number > 0")
            speed = float(it.param2)
            continue
        if it.command not in WAYPOINT_COMMANDS:
            raise MissionError(f"mission item {it.seq}: command {it.command} is not a "
                               "formation waypoint (NAV_WAYPOINT, NAV_LOITER_TIME, "
                               "DO_CHANGE_SPEED)")
        p = mi.item_position_enu(cfg, it)
        if p is None:
            raise MissionError(f"mission item {it.seq}: a formation waypoint needs a position")
        yaw_deg = yaw_of_heading(it.param4, yaw_deg)
        hold = 0.0 if math.isnan(it.param1) else float(it.param1)
        wps.append({"centroid": [float(x) for x in p], "scale": scale, "yaw_deg": yaw_deg,
                    "hold_s": hold, "speed_mps": speed})
    if not wps:
        raise MissionError("mission: no formation waypoint")
    return mission_table(wps, speed, base)


def checked(table: dict[str, Any]) -> MissionConfig:
    """``table`` validated as a ``[mission]`` (MissionError: one line)."""
    return parse_mission(table)
