"""The geofence the simulator enforces (pure: ENU geometry, no I/O).

Built from the stored FENCE items (:func:`fence_from_items`): polygons
(``MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION/EXCLUSION``, ``param1`` consecutive vertices)
and circles (``MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION/EXCLUSION``, ``param1`` = radius, m),
plus the two PX4 limits ``GF_MAX_HOR_DIST`` (horizontal distance from home, m) and
``GF_MAX_VER_DIST`` (height above home, m); 0 turns a limit off.

Semantics: with at least one inclusion zone, the vehicle must be inside at least one of
them (the inclusion zones form one union: MAVLink's inclusion *groups*, ``param2``, are not
distinguished); it must be outside every exclusion zone. Zones are 2-D (no altitude).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import astuple, dataclass, field
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames
from vehicle_sim.physics.geo import latlon_e7
from vehicle_sim.services.mission_items import FENCE_CIRCLE, FENCE_POLYGON, Item, item_position_enu


@dataclass(frozen=True)
class Polygon:
    """Vertices (N, 2) ENU x/y (m), in order; ``inclusion``: inside is allowed."""

    xy: np.ndarray
    inclusion: bool

    def contains(self, x: float, y: float) -> bool:
        """Even-odd ray casting (a point on an edge may fall either way)."""
        inside = False
        n = len(self.xy)
        for i in range(n):
            x1, y1 = self.xy[i]
            x2, y2 = self.xy[(i + 1) % n]
            if (y1 > y) != (y2 > y):
                x_cross = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
                if x < x_cross:
                    inside = not inside
        return inside


@dataclass(frozen=True)
class Circle:
    """Centre ENU x/y (m) and radius (m); ``inclusion``: inside is allowed."""

    cx: float
    cy: float
    radius: float
    inclusion: bool

    def contains(self, x: float, y: float) -> bool:
        return math.hypot(x - self.cx, y - self.cy) <= self.radius


@dataclass
class Geofence:
    """Zones plus the distance limits; :meth:`breach` names the first violation."""

    zones: list[Polygon | Circle] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.zones)

    def outline(self) -> np.ndarray:
        """The ENU vertices (x0, y0, x1, y1, ...; m) of a fence that is one inclusion
        polygon; empty for any other (none, circles, exclusions, several zones): what the
        truth reports of a changed fence (``wire.Truth.fences``, the verdict's fence)."""
        if len(self.zones) == 1:
            zone = self.zones[0]
            if isinstance(zone, Polygon) and zone.inclusion:
                return np.ravel(zone.xy).astype(float)
        return np.zeros(0)

    def breach(
        self, p_enu: np.ndarray, home_enu: np.ndarray, max_hor_m: float = 0.0,
        max_ver_m: float = 0.0,
    ) -> str | None:  # fmt: skip
        """None inside the fence, else a short reason (for STATUSTEXT)."""
        x, y, z = (float(c) for c in p_enu[:3])
        if max_hor_m > 0 and math.hypot(x - home_enu[0], y - home_enu[1]) > max_hor_m:
            return f"more than {max_hor_m:g} m from home"
        if max_ver_m > 0 and z - float(home_enu[2]) > max_ver_m:
            return f"more than {max_ver_m:g} m above home"
        inclusions = [zn for zn in self.zones if zn.inclusion]
        if inclusions and not any(zn.contains(x, y) for zn in inclusions):
            return "outside the inclusion zone"
        for zn in self.zones:
            if not zn.inclusion and zn.contains(x, y):
                return "inside an exclusion zone"
        return None


def scenario_fence_items(cfg: Any, fence: Any) -> list[Item]:
    """The FENCE items of a scenario's ``[geofence]`` (:class:`swarm_common.world.config.
    Geofence`): one inclusion polygon, the box's x-y rectangle or the polygon's vertices,
    global frame (lat/lon degE7 about ``cfg``'s origin). Its altitude limits have no zone
    item (PX4's zones are 2-D): the offboard filter keeps them (docs/world.md)."""
    if fence.polygon_m:
        xy = [(float(x), float(y)) for x, y in fence.polygon_m]
    else:
        (x0, y0, _), (x1, y1, _) = fence.min_m, fence.max_m
        xy = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    items = []
    for k, (x, y) in enumerate(xy):
        lat, lon = latlon_e7(cfg, frames.enu_to_ned(np.array([x, y, 0.0])))
        items.append(Item(k, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                          0, 1, float(len(xy)), 0.0, 0.0, 0.0, lat, lon, 0.0,
                          M.MAV_MISSION_TYPE_FENCE))
    return items


def fence_from_items(cfg: Any, items: Sequence[Item]) -> Geofence:
    """The :class:`Geofence` of a validated FENCE item list (return points are ignored)."""
    zones: list[Polygon | Circle] = []
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in FENCE_POLYGON:
            n = int(it.param1)
            pts = [item_position_enu(cfg, v) for v in items[i : i + n]]
            xy = np.array([[0.0, 0.0] if q is None else [q[0], q[1]] for q in pts])
            inc = it.command == M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
            zones.append(Polygon(xy, inc))
            i += n
            continue
        if it.command in FENCE_CIRCLE:
            q = item_position_enu(cfg, it)
            cx, cy = (0.0, 0.0) if q is None else (float(q[0]), float(q[1]))
            inc = it.command == M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
            zones.append(Circle(cx, cy, float(it.param1), inc))
        i += 1
    return Geofence(zones)


def plan_id(items: Sequence[Item]) -> int:
    """MISSION_CURRENT's id of a stored plan (``fence_id`` for the fence): a CRC-32 of its
    items, as PX4 sends one, so that a client learns of any change without downloading;
    0 for an empty store (never 0 otherwise)."""
    if not items:
        return 0
    return zlib.crc32(repr([astuple(it) for it in items]).encode()) or 1
