"""``[[obstacle]]`` and ``[geofence]``: validation, typed view and the way back to TOML.

An obstacle is a ``sphere`` (``centre_m``, ``radius_m``), a vertical ``cylinder``
(``centre_m`` = [x, y], ``radius_m``, ``z_range_m`` = [bottom, top]) or a ``box``
(``centre_m``, ``size_m``, ``yaw_deg`` about +z). Each has a ``clearance_m``: how far (m)
every vehicle's centre keeps from its surface (default: the controller's ``d_safe_m``).
The geofence is a box, ``min_m`` to ``max_m`` (ENU corners, m), that every vehicle's
centre stays ``margin_m`` inside (default ``d_safe_m``). Every refusal is one
:class:`WorldError` line naming the key.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from swarm_common.table_check import Range, check_keys, number, show, vector

MAX_OBSTACLES = 1000
_POS: Range = (-1e4, 1e4, False, False)
_LEN: Range = (0.0, 1000.0, True, False)
_CLEAR: Range = (0.0, 100.0, False, False)
_YAW: Range = (-720.0, 720.0, False, False)
TABLE_COLUMNS = 11  # kind, centre (3), radius, z range (2), size (3), yaw (rad)


class WorldError(ValueError):
    """An ``[[obstacle]]`` or ``[geofence]`` table that cannot be used; one line."""


class ObstacleKind(StrEnum):
    SPHERE = "sphere"
    CYLINDER = "cylinder"
    BOX = "box"


KIND_CODE = {ObstacleKind.SPHERE: 0.0, ObstacleKind.CYLINDER: 1.0, ObstacleKind.BOX: 2.0}


@dataclass(frozen=True)
class Obstacle:
    """One static obstacle (module docstring). Unused fields of a kind are 0."""

    kind: ObstacleKind
    centre_m: tuple[float, float, float]  # a cylinder's z is the middle of its range
    clearance_m: float
    radius_m: float = 0.0
    z_range_m: tuple[float, float] = (0.0, 0.0)
    size_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_deg: float = 0.0

    def row(self) -> np.ndarray:
        """The obstacle as one row of the compiled geometry's table (TABLE_COLUMNS)."""
        return np.array([KIND_CODE[self.kind], *self.centre_m, self.radius_m, *self.z_range_m,
                         *self.size_m, np.deg2rad(self.yaw_deg)])


@dataclass(frozen=True)
class Geofence:
    """The box every vehicle's centre stays ``margin_m`` inside (ENU corners, m)."""

    min_m: tuple[float, float, float]
    max_m: tuple[float, float, float]
    margin_m: float


@dataclass(frozen=True)
class World:
    """The scenario's obstacles and geofence (both optional)."""

    obstacles: tuple[Obstacle, ...] = ()
    geofence: Geofence | None = None
    _table: np.ndarray = field(default_factory=lambda: np.zeros((0, TABLE_COLUMNS)),
                               compare=False, repr=False)

    @property
    def empty(self) -> bool:
        return not self.obstacles and self.geofence is None

    @property
    def table(self) -> np.ndarray:
        """(K, TABLE_COLUMNS) the obstacles for :mod:`swarm_common.world.geometry`."""
        return self._table

    @property
    def clearances(self) -> np.ndarray:
        """(K,) each obstacle's clearance (m)."""
        return np.array([o.clearance_m for o in self.obstacles], dtype=float)

    def fence_arrays(self) -> tuple[bool, np.ndarray, float]:
        """(on, (2,3) [min; max] (m), margin (m)) for the compiled geometry."""
        f = self.geofence
        if f is None:
            return False, np.zeros((2, 3)), 0.0
        return True, np.array([f.min_m, f.max_m], dtype=float), f.margin_m


def make_world(obstacles: tuple[Obstacle, ...], geofence: Geofence | None) -> World:
    table = (np.array([o.row() for o in obstacles]) if obstacles
             else np.zeros((0, TABLE_COLUMNS)))
    table.setflags(write=False)
    return World(obstacles, geofence, table)


_OBSTACLE_KEYS = {
    ObstacleKind.SPHERE: ("kind", "centre_m", "radius_m", "clearance_m"),
    ObstacleKind.CYLINDER: ("kind", "centre_m", "radius_m", "z_range_m", "clearance_m"),
    ObstacleKind.BOX: ("kind", "centre_m", "size_m", "yaw_deg", "clearance_m"),
}


def _require(raw: dict[str, Any], where: str, key: str, rule: str) -> Any:
    if key not in raw:
        raise WorldError(f"missing key {where}.{key} ({rule})")
    return raw[key]


def _obstacle(raw: object, k: int, d_safe: float) -> Obstacle:
    where = f"obstacle[{k}]"
    if not isinstance(raw, dict):
        raise WorldError(f"{where} = {show(raw)}: must be a table")
    kinds = ", ".join(ObstacleKind)
    kind_raw = _require(raw, where, "kind", kinds)
    if kind_raw not in tuple(ObstacleKind):
        raise WorldError(f"{where}.kind = {show(kind_raw)}: must be one of {kinds}")
    kind = ObstacleKind(kind_raw)
    check_keys(raw, where, _OBSTACLE_KEYS[kind], WorldError)
    clear = (number(raw["clearance_m"], f"{where}.clearance_m", _CLEAR, WorldError)
             if "clearance_m" in raw else d_safe)
    if kind is ObstacleKind.SPHERE:
        c = vector(_require(raw, where, "centre_m", "3 numbers, m"), f"{where}.centre_m", 3,
                   _POS, WorldError)
        r = number(_require(raw, where, "radius_m", "m"), f"{where}.radius_m", _LEN, WorldError)
        return Obstacle(kind, (c[0], c[1], c[2]), clear, radius_m=r)
    if kind is ObstacleKind.CYLINDER:
        c = vector(_require(raw, where, "centre_m", "2 numbers [x, y], m"), f"{where}.centre_m",
                   2, _POS, WorldError)
        r = number(_require(raw, where, "radius_m", "m"), f"{where}.radius_m", _LEN, WorldError)
        zr = vector(_require(raw, where, "z_range_m", "[bottom, top], m"), f"{where}.z_range_m",
                    2, _POS, WorldError)
        if not zr[0] < zr[1]:
            raise WorldError(f"{where}.z_range_m = {show(raw['z_range_m'])}: bottom must be "
                             "below top")
        return Obstacle(kind, (c[0], c[1], 0.5 * (zr[0] + zr[1])), clear, radius_m=r,
                        z_range_m=(zr[0], zr[1]))
    c = vector(_require(raw, where, "centre_m", "3 numbers, m"), f"{where}.centre_m", 3, _POS,
               WorldError)
    s = vector(_require(raw, where, "size_m", "3 numbers, m"), f"{where}.size_m", 3, _LEN,
               WorldError)
    yaw = number(raw["yaw_deg"], f"{where}.yaw_deg", _YAW, WorldError) if "yaw_deg" in raw else 0.0
    return Obstacle(kind, (c[0], c[1], c[2]), clear, size_m=(s[0], s[1], s[2]), yaw_deg=yaw)


def _geofence(raw: object, d_safe: float) -> Geofence:
    if not isinstance(raw, dict):
        raise WorldError(f"[geofence] = {show(raw)}: must be a table")
    check_keys(raw, "geofence", ("min_m", "max_m", "margin_m"), WorldError)
    lo = vector(_require(raw, "geofence", "min_m", "3 numbers, m"), "geofence.min_m", 3, _POS,
                WorldError)
    hi = vector(_require(raw, "geofence", "max_m", "3 numbers, m"), "geofence.max_m", 3, _POS,
                WorldError)
    margin = (number(raw["margin_m"], "geofence.margin_m", _CLEAR, WorldError)
              if "margin_m" in raw else d_safe)
    for a, name in enumerate("xyz"):
        if not hi[a] - lo[a] > 2.0 * margin:
            raise WorldError(f"geofence: max_m.{name} − min_m.{name} = {hi[a] - lo[a]:g} m: must "
                             f"exceed twice margin_m ({2 * margin:g} m)")
    return Geofence((lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2]), margin)


def parse_world(data: dict[str, Any], d_safe: float) -> World:
    """The world of a decoded scenario document (its ``obstacle`` list and ``geofence``
    table, both optional); ``d_safe`` (m) the default clearance and margin."""
    raw = data.get("obstacle", [])
    if not isinstance(raw, list):
        raise WorldError(f"obstacle = {show(raw)}: must be a list of [[obstacle]] tables")
    if len(raw) > MAX_OBSTACLES:
        raise WorldError(f"obstacle: {len(raw)} obstacles; at most {MAX_OBSTACLES} allowed")
    obstacles = tuple(_obstacle(o, k, d_safe) for k, o in enumerate(raw))
    fence = _geofence(data["geofence"], d_safe) if "geofence" in data else None
    return make_world(obstacles, fence)


def world_toml(world: World) -> dict[str, Any]:
    """``world`` as TOML-ready top-level entries (``parse_world`` gives it back)."""
    out: dict[str, Any] = {}
    if world.obstacles:
        rows = []
        for o in world.obstacles:
            row: dict[str, Any] = {"kind": str(o.kind), "clearance_m": o.clearance_m}
            if o.kind is ObstacleKind.SPHERE:
                row |= {"centre_m": list(o.centre_m), "radius_m": o.radius_m}
            elif o.kind is ObstacleKind.CYLINDER:
                row |= {"centre_m": list(o.centre_m[:2]), "radius_m": o.radius_m,
                        "z_range_m": list(o.z_range_m)}
            else:
                row |= {"centre_m": list(o.centre_m), "size_m": list(o.size_m),
                        "yaw_deg": o.yaw_deg}
            rows.append(row)
        out["obstacle"] = rows
    if world.geofence is not None:
        f = world.geofence
        out["geofence"] = {"min_m": list(f.min_m), "max_m": list(f.max_m),
                           "margin_m": f.margin_m}
    return out
