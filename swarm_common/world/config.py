"""``[[obstacle]]`` and ``[geofence]``: validation, typed view and the way back to TOML.

An obstacle is a ``sphere`` (``centre_m``, ``radius_m``), a vertical ``cylinder``
(``centre_m`` = [x, y], ``radius_m``, ``z_range_m`` = [bottom, top]) or a ``box``
(``centre_m``, ``size_m``, ``yaw_deg`` about +z). Each has a ``clearance_m``: how far (m)
every vehicle's centre keeps from its surface (default: the controller's ``d_safe_m``).
The geofence is a box, ``min_m`` to ``max_m`` (ENU corners, m), or a vertical prism: a
convex ``polygon_m`` ([[x, y], ...], m, either winding) from ``z_range_m`` = [bottom, top].
Every vehicle's centre stays ``margin_m`` inside it (default ``d_safe_m``). Either way the
fence is a convex set of inward half-spaces nᵀx ≥ c (:meth:`Geofence.planes`), the rows
the filter keeps. Every refusal is one :class:`WorldError` line naming the key.
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
MAX_FENCE_VERTICES = 64
_TURN_TOL = 1e-9  # |e_i × e_i+1| below this times |e_i||e_i+1|: collinear (sin of the turn)
_VERTEX_TOL = 1e-6  # m: an edge shorter than this repeats a vertex


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
    """The fence every vehicle's centre stays ``margin_m`` inside: the box ``min_m`` to
    ``max_m`` (ENU corners, m), or, with ``polygon_m`` (x, y vertices, m, as written, convex)
    set, the prism over it from ``min_m[2]`` to ``max_m[2]``; then ``min_m`` and ``max_m``
    are its bounding box (:func:`polygon_fence`)."""

    min_m: tuple[float, float, float]
    max_m: tuple[float, float, float]
    margin_m: float
    polygon_m: tuple[tuple[float, float], ...] = ()

    @property
    def z_range_m(self) -> tuple[float, float]:
        """(bottom, top) (m)."""
        return self.min_m[2], self.max_m[2]

    def planes(self) -> np.ndarray:
        """(F, 4) the inward half-spaces nᵀx ≥ c (unit n) as rows [n, c]: a box's 6 faces
        (axes x, y, z; the low face n = e_a, c = min_m[a], then the high face n = −e_a,
        c = −max_m[a]); a polygon's one vertical plane per edge (counter-clockwise from
        its first vertex), then the floor (n = e_z, c = bottom) and ceiling (n = −e_z,
        c = −top). A point's distance inside is the smallest nᵀx − c."""
        if not self.polygon_m:
            out = np.zeros((6, 4))
            for a in range(3):
                out[2 * a, a], out[2 * a, 3] = 1.0, self.min_m[a]
                out[2 * a + 1, a], out[2 * a + 1, 3] = -1.0, -self.max_m[a]
            return out
        v = np.array(self.polygon_m, dtype=float)
        if _signed_area(v) < 0.0:
            v = np.concatenate([v[:1], v[:0:-1]])  # the same vertices, counter-clockwise
        e = np.roll(v, -1, axis=0) - v
        n = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.hypot(e[:, 0], e[:, 1])[:, None]
        out = np.zeros((len(v) + 2, 4))
        out[:-2, :2] = n
        out[:-2, 3] = np.sum(n * v, axis=1)
        out[-2, 2], out[-2, 3] = 1.0, self.min_m[2]
        out[-1, 2], out[-1, 3] = -1.0, -self.max_m[2]
        return out

    def face_names(self) -> tuple[str, ...]:
        """A name per row of :meth:`planes`, in its order, for one-line messages: a box's
        ``min_m.x`` … ``max_m.z``; a polygon's ``side polygon_m[i]–[j]`` (the vertices as
        written), ``floor`` and ``ceiling``."""
        if not self.polygon_m:
            return tuple(f"{end}_m.{a}" for a in "xyz" for end in ("min", "max"))
        n = len(self.polygon_m)
        ccw = _signed_area(np.array(self.polygon_m, dtype=float)) > 0.0
        order = list(range(n)) if ccw else [0, *range(n - 1, 0, -1)]
        sides = (f"side polygon_m[{order[j]}]–[{order[(j + 1) % n]}]" for j in range(n))
        return (*sides, "floor", "ceiling")


def _signed_area(v: np.ndarray) -> float:
    """The shoelace area (m²) of the polygon ``v`` (V, 2): > 0 counter-clockwise."""
    w = np.roll(v, -1, axis=0)
    return 0.5 * float(np.sum(v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]))


def polygon_fence(vertices: tuple[tuple[float, float], ...], z_range: tuple[float, float],
                  margin: float) -> Geofence:
    """The prism fence over ``vertices`` (m) from ``z_range`` (m), its bounding box set."""
    v = np.array(vertices, dtype=float)
    lo, hi = v.min(axis=0), v.max(axis=0)
    return Geofence((float(lo[0]), float(lo[1]), z_range[0]),
                    (float(hi[0]), float(hi[1]), z_range[1]), margin, tuple(vertices))


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

    def fence_arrays(self) -> tuple[np.ndarray, float]:
        """((F, 4) the fence's half-spaces [n, c] (:meth:`Geofence.planes`; F = 0 without
        a fence), margin (m)) for the compiled geometry."""
        f = self.geofence
        if f is None:
            return np.zeros((0, 4)), 0.0
        return f.planes(), f.margin_m


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
    poly = "polygon_m" in raw or "z_range_m" in raw
    if poly:
        for key in ("min_m", "max_m"):
            if key in raw:
                raise WorldError(f"geofence.{key}: a box key beside polygon_m/z_range_m; give "
                                 "either min_m and max_m or polygon_m and z_range_m")
        check_keys(raw, "geofence", ("polygon_m", "z_range_m", "margin_m"), WorldError)
    else:
        check_keys(raw, "geofence", ("min_m", "max_m", "margin_m"), WorldError)
    margin = (number(raw["margin_m"], "geofence.margin_m", _CLEAR, WorldError)
              if "margin_m" in raw else d_safe)
    if poly:
        return _polygon(raw, margin)
    lo = vector(_require(raw, "geofence", "min_m", "3 numbers, m"), "geofence.min_m", 3, _POS,
                WorldError)
    hi = vector(_require(raw, "geofence", "max_m", "3 numbers, m"), "geofence.max_m", 3, _POS,
                WorldError)
    for a, name in enumerate("xyz"):
        if not hi[a] - lo[a] > 2.0 * margin:
            raise WorldError(f"geofence: max_m.{name} − min_m.{name} = {hi[a] - lo[a]:g} m: must "
                             f"exceed twice margin_m ({2 * margin:g} m)")
    return Geofence((lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2]), margin)


def _polygon(raw: dict[str, Any], margin: float) -> Geofence:
    """A polygon fence's keys (module docstring): convex, simple, not degenerate."""
    key = "geofence.polygon_m"
    pts = _require(raw, "geofence", "polygon_m", "[[x, y], ...], m")
    if not isinstance(pts, list) or not 3 <= len(pts) <= MAX_FENCE_VERTICES:
        raise WorldError(f"{key} = {show(pts)}: must be a list of 3 to {MAX_FENCE_VERTICES} "
                         "[x, y] vertices (m)")
    xy = [vector(p, f"{key}[{i}]", 2, _POS, WorldError) for i, p in enumerate(pts)]
    verts = tuple((p[0], p[1]) for p in xy)
    zr = vector(_require(raw, "geofence", "z_range_m", "[bottom, top], m"), "geofence.z_range_m",
                2, _POS, WorldError)
    if not zr[0] < zr[1]:
        raise WorldError(f"geofence.z_range_m = {show(raw['z_range_m'])}: bottom must be below "
                         "top")
    if not zr[1] - zr[0] > 2.0 * margin:
        raise WorldError(f"geofence.z_range_m: top − bottom = {zr[1] - zr[0]:g} m: must exceed "
                         f"twice margin_m ({2 * margin:g} m)")
    v = np.array(verts, dtype=float)
    e = np.roll(v, -1, axis=0) - v
    length = np.hypot(e[:, 0], e[:, 1])
    short = np.flatnonzero(length < _VERTEX_TOL)
    if short.size:
        i = int(short[0])
        raise WorldError(f"{key}: vertices {i} and {(i + 1) % len(v)} repeat: a polygon needs "
                         "distinct consecutive vertices")
    f = np.roll(e, -1, axis=0)
    cross = (e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]) / (length * np.roll(length, -1))
    flat = np.flatnonzero(np.abs(cross) < _TURN_TOL)
    if flat.size:
        i = int(flat[0])
        raise WorldError(f"{key}: vertex {(i + 1) % len(v)} is collinear with its neighbours: "
                         "drop it")
    if not (np.all(cross > 0.0) or np.all(cross < 0.0)):
        raise WorldError(f"{key}: the polygon is not convex (it turns both ways)")
    turn = float(np.sum(np.arctan2(cross, np.sum(e * f, axis=1) / (length * np.roll(length, -1)))))
    if abs(abs(turn) - 2.0 * np.pi) > 1e-6:
        raise WorldError(f"{key}: the polygon crosses itself (it winds {turn / (2 * np.pi):.0f} "
                         "times)")
    if not abs(_signed_area(v)) > 0.0:
        raise WorldError(f"{key}: the polygon has zero area")
    fence = polygon_fence(verts, (zr[0], zr[1]), margin)
    planes = fence.planes()[:-2]
    width = min(float(np.max(v @ pl[:2] - pl[3])) for pl in planes)  # narrowest, m
    if not width > 2.0 * margin:
        raise WorldError(f"{key}: the polygon is {width:g} m across at its narrowest: must "
                         f"exceed twice margin_m ({2 * margin:g} m)")
    return fence


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
        out["geofence"] = ({"min_m": list(f.min_m), "max_m": list(f.max_m)} if not f.polygon_m
                           else {"polygon_m": [list(p) for p in f.polygon_m],
                                 "z_range_m": list(f.z_range_m)}) | {"margin_m": f.margin_m}
    return out
