"""Mission items as the vehicle stores them: validation, frames, and the wire messages.

An item is kept exactly as MISSION_ITEM_INT carries it (:class:`Item`), so a download
returns what was uploaded bit for bit; :func:`item_position_enu` turns its position into
the simulator's ENU frame (metres, z up, origin = the shared geodetic origin, ground at
``home_alt``) through :mod:`vehicle_sim.physics.geo` and :func:`swarm_common.frames.ned_to_enu`.

Frames accepted (the others are MAV_MISSION_UNSUPPORTED_FRAME):

* ``MAV_FRAME_GLOBAL(_INT)``: latitude/longitude degE7, altitude AMSL (m);
* ``MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT)``: altitude above home (MAVSDK uses this);
* ``MAV_FRAME_LOCAL_NED``: x north, y east (m × 1e4 in the INT message), z down (m);
* ``MAV_FRAME_MISSION``: items without a position (DO_*, RETURN_TO_LAUNCH).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames
from vehicle_sim.physics import geo

MISSION = M.MAV_MISSION_TYPE_MISSION
FENCE = M.MAV_MISSION_TYPE_FENCE
RALLY = M.MAV_MISSION_TYPE_RALLY
MISSION_TYPES = (MISSION, FENCE, RALLY)
# Storage caps per mission type (items); a larger MISSION_COUNT is MAV_MISSION_NO_SPACE.
CAPACITY = {MISSION: 500, FENCE: 256, RALLY: 32}
MAX_DISTANCE_M = 10_000.0  # a positional item farther than this from the origin: INVALID
LOCAL_SCALE = 1e4  # MISSION_ITEM_INT x/y in a local frame: metres * 1e4
DEG_E7 = 1e7

GLOBAL_FRAMES = frozenset({
    M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT,
    M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
})  # fmt: skip
RELATIVE_FRAMES = frozenset({M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
FLOAT_FRAME = {
    M.MAV_FRAME_GLOBAL_INT: M.MAV_FRAME_GLOBAL,
    M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
}
POSITION_FRAMES = GLOBAL_FRAMES | {M.MAV_FRAME_LOCAL_NED}
ALL_FRAMES = POSITION_FRAMES | {M.MAV_FRAME_MISSION}

# NAV commands AUTO.MISSION flies; position optional (x = y = 0: "where the vehicle is")
NAV_FLOWN = frozenset({
    M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LOITER_TIME,
    M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH,
})  # fmt: skip
POSITIONLESS_OK = frozenset({
    M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LAND,
    M.MAV_CMD_NAV_RETURN_TO_LAUNCH,
})  # fmt: skip
FENCE_POLYGON = frozenset({
    M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
})  # fmt: skip
FENCE_CIRCLE = frozenset({
    M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
})  # fmt: skip
FENCE_COMMANDS = FENCE_POLYGON | FENCE_CIRCLE | {M.MAV_CMD_NAV_FENCE_RETURN_POINT}
RALLY_COMMANDS = frozenset({M.MAV_CMD_NAV_RALLY_POINT})
DO_FIRST, DO_LAST = 176, 252  # MAV_CMD_DO_* range: accepted in a mission, skipped in flight


@dataclass(frozen=True)
class Item:
    """One stored item, the fields of MISSION_ITEM_INT (x, y: degE7 or local m × 1e4)."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int

    @property
    def has_position(self) -> bool:
        """False for frame MISSION and for lat = lon = 0 in a global frame ("here")."""
        if self.frame == M.MAV_FRAME_MISSION:
            return False
        return self.frame == M.MAV_FRAME_LOCAL_NED or not (self.x == 0 and self.y == 0)


def item_from_int(m: Any) -> Item:
    """An :class:`Item` of a received MISSION_ITEM_INT."""
    return Item(
        int(m.seq), int(m.frame), int(m.command), int(m.current), int(m.autocontinue),
        float(m.param1), float(m.param2), float(m.param3), float(m.param4),
        int(m.x), int(m.y), float(m.z), int(getattr(m, "mission_type", MISSION)),
    )  # fmt: skip


def item_from_float(m: Any) -> Item | None:
    """An :class:`Item` of a received (deprecated) MISSION_ITEM (x/y in degrees or metres);
    None when x/y are not finite or do not fit the INT32 fields."""
    scale = LOCAL_SCALE if m.frame == M.MAV_FRAME_LOCAL_NED else DEG_E7
    try:
        x, y = int(round(float(m.x) * scale)), int(round(float(m.y) * scale))
    except (OverflowError, ValueError):
        return None
    if not all(-(2**31) <= v < 2**31 for v in (x, y)):
        return None
    return Item(
        int(m.seq), int(m.frame), int(m.command), int(m.current), int(m.autocontinue),
        float(m.param1), float(m.param2), float(m.param3), float(m.param4),
        x, y, float(m.z), int(getattr(m, "mission_type", MISSION)),
    )  # fmt: skip


def to_int_message(it: Item, target: tuple[int, int]) -> M.MAVLink_mission_item_int_message:
    """MISSION_ITEM_INT of a stored item, addressed to ``target`` = (sysid, compid)."""
    return M.MAVLink_mission_item_int_message(
        target[0], target[1], it.seq, it.frame, it.command, it.current, it.autocontinue,
        it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, it.mission_type,
    )  # fmt: skip


def to_float_message(it: Item, target: tuple[int, int]) -> M.MAVLink_mission_item_message:
    """MISSION_ITEM (float x/y) of a stored item, for a client that asks with MISSION_REQUEST;
    a ``*_INT`` frame is named by its float twin there, as PX4 does."""
    scale = LOCAL_SCALE if it.frame == M.MAV_FRAME_LOCAL_NED else DEG_E7
    frame = FLOAT_FRAME.get(it.frame, it.frame)
    return M.MAVLink_mission_item_message(
        target[0], target[1], it.seq, frame, it.command, it.current, it.autocontinue,
        it.param1, it.param2, it.param3, it.param4, it.x / scale, it.y / scale, it.z,
        it.mission_type,
    )  # fmt: skip


# ---------------------------------------------------------------------------------------
# positions
def item_position_enu(cfg: Any, it: Item) -> np.ndarray | None:
    """ENU position (m) of an item; None for a positionless one (frame MISSION, or
    lat = lon = 0 in a global frame: "where the vehicle is"). Altitude: relative frames above
    home (ground = 0), global frames AMSL minus ``cfg.home_alt``, LOCAL_NED z down."""
    if not it.has_position:
        return None
    if it.frame == M.MAV_FRAME_LOCAL_NED:
        ned = np.array([it.x / LOCAL_SCALE, it.y / LOCAL_SCALE, it.z])
        return frames.ned_to_enu(ned)
    north, east = geo.ned_from_latlon(cfg, it.x / DEG_E7, it.y / DEG_E7)
    down = -it.z if it.frame in RELATIVE_FRAMES else geo.down_from_amsl(cfg, it.z)
    return frames.ned_to_enu(np.array([north, east, down]))


def altitude_enu(cfg: Any, it: Item) -> float:
    """ENU height (m above the ground) an item asks for, whatever its x/y."""
    if it.frame == M.MAV_FRAME_LOCAL_NED:
        return -it.z
    return it.z if it.frame in RELATIVE_FRAMES else -geo.down_from_amsl(cfg, it.z)


def yaw_enu(heading_deg: float) -> float | None:
    """ENU yaw (rad) of a MAVLink heading (degrees from north, clockwise); None if NaN."""
    if not math.isfinite(heading_deg):
        return None
    r_ned = frames.rotm_from_euler(0.0, 0.0, math.radians(heading_deg))
    return frames.euler_enu_from_quat_ned(frames.quat_from_rotm(r_ned))[2]


# ---------------------------------------------------------------------------------------
# validation (the MAV_MISSION_RESULT of one item, then of a whole list)
def check_item(cfg: Any, it: Item, mission_type: int) -> int:
    """MAV_MISSION_ACCEPTED or the error for one item of ``mission_type``."""
    if it.mission_type != mission_type:
        return M.MAV_MISSION_ERROR
    if it.frame not in ALL_FRAMES:
        return M.MAV_MISSION_UNSUPPORTED_FRAME
    if not all(math.isfinite(v) or math.isnan(v) for v in _params(it)):
        return M.MAV_MISSION_INVALID  # +-inf
    if mission_type == MISSION:
        res = _check_mission_command(it)
    elif mission_type == FENCE:
        res = _check_fence_command(it)
    else:
        res = M.MAV_MISSION_ACCEPTED if it.command in RALLY_COMMANDS else M.MAV_MISSION_UNSUPPORTED
    if res != M.MAV_MISSION_ACCEPTED:
        return res
    return _check_position(cfg, it)


def _params(it: Item) -> tuple[float, ...]:
    return (it.param1, it.param2, it.param3, it.param4, it.z)


def _check_mission_command(it: Item) -> int:
    c = it.command
    if DO_FIRST <= c <= DO_LAST:
        return M.MAV_MISSION_ACCEPTED
    if c not in NAV_FLOWN:
        return M.MAV_MISSION_UNSUPPORTED
    if c in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME) and it.param1 < 0:
        return M.MAV_MISSION_INVALID_PARAM1  # hold / loiter time, s
    if c == M.MAV_CMD_NAV_WAYPOINT and it.param2 < 0:
        return M.MAV_MISSION_INVALID_PARAM2  # acceptance radius, m
    if c != M.MAV_CMD_NAV_RETURN_TO_LAUNCH and it.frame == M.MAV_FRAME_MISSION:
        return M.MAV_MISSION_UNSUPPORTED_FRAME
    if c not in POSITIONLESS_OK and not it.has_position:
        return M.MAV_MISSION_INVALID_PARAM5_X
    if c != M.MAV_CMD_NAV_RETURN_TO_LAUNCH and not math.isfinite(it.z):
        return M.MAV_MISSION_INVALID_PARAM7
    return M.MAV_MISSION_ACCEPTED


def _check_fence_command(it: Item) -> int:
    if it.command not in FENCE_COMMANDS:
        return M.MAV_MISSION_UNSUPPORTED
    if it.frame not in POSITION_FRAMES:
        return M.MAV_MISSION_UNSUPPORTED_FRAME
    if it.command in FENCE_POLYGON and not (math.isfinite(it.param1) and it.param1 >= 3):
        return M.MAV_MISSION_INVALID_PARAM1  # vertex count
    if it.command in FENCE_CIRCLE and not (math.isfinite(it.param1) and it.param1 > 0):
        return M.MAV_MISSION_INVALID_PARAM1  # radius, m
    return M.MAV_MISSION_ACCEPTED


def _check_position(cfg: Any, it: Item) -> int:
    if it.frame in GLOBAL_FRAMES and it.has_position:
        if not -90 * DEG_E7 <= it.x <= 90 * DEG_E7:
            return M.MAV_MISSION_INVALID_PARAM5_X
        if not -180 * DEG_E7 <= it.y <= 180 * DEG_E7:
            return M.MAV_MISSION_INVALID_PARAM6_Y
    p = item_position_enu(cfg, it)
    if p is not None and float(np.hypot(p[0], p[1])) > MAX_DISTANCE_M:
        return M.MAV_MISSION_INVALID_PARAM5_X
    return M.MAV_MISSION_ACCEPTED


def check_list(items: list[Item], mission_type: int) -> int:
    """Whole-list rules: a fence polygon is ``param1`` consecutive vertices of one kind."""
    if mission_type != FENCE:
        return M.MAV_MISSION_ACCEPTED
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in FENCE_POLYGON:
            n = int(it.param1)
            group = items[i : i + n]
            if len(group) < n or any(g.command != it.command or g.param1 != n for g in group):
                return M.MAV_MISSION_INVALID_PARAM1
            i += n
        else:
            i += 1
    return M.MAV_MISSION_ACCEPTED
