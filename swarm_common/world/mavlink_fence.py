"""A fence as a vehicle stores it (MAVLink FENCE items) read back into the filter's world.

The simulator starts each vehicle with the scenario's ``[geofence]`` as one inclusion
polygon (:func:`vehicle_sim.services.geofence.scenario_fence_items`: ENU vertices to
latitude/longitude in degE7 about the shared origin, :mod:`swarm_common.world.geodesy`), and a
ground station may upload another. The offboard daemon downloads it and this module turns
it back into a :class:`~swarm_common.world.config.Geofence` the dcbf filter keeps
(docs/world.md, "A fence uploaded over MAVLink"). Everything here comes from a socket, so
:func:`read_fence` checks every field before using it, and says what it found:

* ``polygon``: exactly one inclusion polygon (return points ignored): its ENU vertices.
  :func:`filter_fence` then makes the prism, with the altitude band of the fence the
  filter keeps (MAVLink's zones are 2-D), through the scenario loader's own checks
  (convex, simple, wide enough for the margin);
* ``none``: no zone at all (an empty store, or return points only);
* ``unsupported``: valid MAVLink the filter cannot represent: an exclusion zone, a circle,
  several inclusion polygons (their union), more than
  :data:`~swarm_common.world.config.MAX_FENCE_VERTICES` vertices;
* ``bad``: not a valid fence at all (a sequence gap, a NaN or non-integer vertex count, a
  latitude out of range, a vertex beyond :data:`MAX_RANGE_M`, an unknown command or
  frame); the caller counts and drops it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from swarm_common.world import geodesy
from swarm_common.world.config import MAX_FENCE_VERTICES, Geofence, WorldError, parse_world

# MAVLink numbers (common.xml), here so that this module needs no pymavlink
FRAME_GLOBAL, FRAME_LOCAL_NED, FRAME_GLOBAL_RELATIVE_ALT = 0, 1, 3
FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT_INT = 5, 6
GLOBAL_FRAMES = frozenset({FRAME_GLOBAL, FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_INT,
                           FRAME_GLOBAL_RELATIVE_ALT_INT})
RETURN_POINT, POLY_IN, POLY_OUT, CIRCLE_IN, CIRCLE_OUT = 5000, 5001, 5002, 5003, 5004
LOCAL_SCALE = 1e4  # MISSION_ITEM_INT x/y in a local frame: metres * 1e4
MAX_ITEMS = 256  # the simulator's fence capacity (vehicle_sim.services.mission_items)
MAX_RANGE_M = 10_000.0  # a vertex farther than this from the origin: bad
MATCH_TOL_M = 0.05  # vertices this close are the same (the degE7 round trip: about 1 cm)
# the altitude band of a fence uploaded without one in the scenario: wide enough that no
# floor or ceiling plane ever comes within sensing range (m)
OPEN_BAND_M = (-1000.0, 1000.0)

Kind = Literal["polygon", "none", "unsupported", "bad"]


@dataclass(frozen=True)
class FenceItem:
    """The fields of one MISSION_ITEM_INT that a fence uses (x, y: degE7, or m × 1e4 in
    MAV_FRAME_LOCAL_NED)."""

    seq: int
    frame: int
    command: int
    param1: float
    x: int
    y: int


@dataclass(frozen=True)
class FenceRead:
    """What :func:`read_fence` found: its ``kind`` (module docstring), the inclusion
    polygon's ENU vertices (m) for ``polygon``, and a one-line ``reason`` otherwise."""

    kind: Kind
    xy: tuple[tuple[float, float], ...] = ()
    reason: str = ""


def _enu_xy(it: FenceItem, origin: geodesy.Origin) -> tuple[float, float] | str:
    """The item's ENU (x, y) (m) about ``origin``, or why it has none."""
    if it.frame == FRAME_LOCAL_NED:
        x, y = it.y / LOCAL_SCALE, it.x / LOCAL_SCALE
    elif it.frame in GLOBAL_FRAMES:
        if not (abs(it.x) <= 90 * geodesy.DEG_E7 and abs(it.y) <= 180 * geodesy.DEG_E7):
            return f"item {it.seq}: latitude/longitude {it.x}, {it.y} (degE7) out of range"
        x, y = geodesy.enu_xy_of_e7(it.x, it.y, *origin)
    else:
        return f"item {it.seq}: frame {it.frame} is not a position frame"
    if not math.hypot(x, y) <= MAX_RANGE_M:
        return f"item {it.seq}: {math.hypot(x, y):.0f} m from the origin (> {MAX_RANGE_M:g} m)"
    return x, y


def _polygon_count(it: FenceItem) -> int | str:
    """A polygon vertex's ``param1``, the polygon's vertex count, or why it is bad."""
    n = it.param1
    if not (math.isfinite(n) and n == int(n) and 3 <= n <= MAX_ITEMS):
        return f"item {it.seq}: polygon vertex count param1 = {n!r}"
    return int(n)


def read_fence(items: Sequence[FenceItem],
               origin: geodesy.Origin = geodesy.DEFAULT_ORIGIN) -> FenceRead:
    """The fence of a downloaded FENCE list (module docstring), its latitudes and longitudes
    read about ``origin``: the vehicle's GPS_GLOBAL_ORIGIN, the origin of the local frame
    its odometry is in."""
    if len(items) > MAX_ITEMS:
        return FenceRead("bad", reason=f"{len(items)} items (> {MAX_ITEMS})")
    polygons: list[tuple[int, tuple[tuple[float, float], ...]]] = []
    other: list[str] = []
    i = 0
    while i < len(items):
        it = items[i]
        if it.seq != i:
            return FenceRead("bad", reason=f"item {i} has seq {it.seq}")
        if it.command in (POLY_IN, POLY_OUT):
            n = _polygon_count(it)
            if isinstance(n, str):
                return FenceRead("bad", reason=n)
            group = items[i : i + n]
            if len(group) < n:
                return FenceRead("bad", reason=f"item {i}: a {n}-vertex polygon, "
                                 f"{len(group)} items left")
            xy: list[tuple[float, float]] = []
            for j, v in enumerate(group):
                if v.seq != i + j or v.command != it.command or v.param1 != it.param1:
                    return FenceRead("bad", reason=f"item {i + j}: not vertex {j} of the "
                                     f"polygon at item {i}")
                p = _enu_xy(v, origin)
                if isinstance(p, str):
                    return FenceRead("bad", reason=p)
                xy.append(p)
            polygons.append((it.command, tuple(xy)))
            i += n
            continue
        if it.command in (CIRCLE_IN, CIRCLE_OUT):
            if not (math.isfinite(it.param1) and 0.0 < it.param1 <= MAX_RANGE_M):
                return FenceRead("bad", reason=f"item {i}: circle radius {it.param1!r}")
            p = _enu_xy(it, origin)
            if isinstance(p, str):
                return FenceRead("bad", reason=p)
            other.append("inclusion circle" if it.command == CIRCLE_IN else "exclusion circle")
        elif it.command == RETURN_POINT:
            p = _enu_xy(it, origin)
            if isinstance(p, str):
                return FenceRead("bad", reason=p)
        else:
            return FenceRead("bad", reason=f"item {i}: command {it.command} is not a fence item")
        i += 1
    other += ["exclusion polygon" for c, _ in polygons if c == POLY_OUT]
    inclusion = [xy for c, xy in polygons if c == POLY_IN]
    if len(inclusion) > 1:
        other.append(f"{len(inclusion)} inclusion polygons")
    if other:
        return FenceRead("unsupported", reason=", ".join(sorted(set(other))))
    if not inclusion:
        return FenceRead("none", reason="no inclusion zone")
    if len(inclusion[0]) > MAX_FENCE_VERTICES:
        return FenceRead("unsupported", reason=f"a polygon of {len(inclusion[0])} vertices "
                         f"(the filter takes at most {MAX_FENCE_VERTICES})")
    return FenceRead("polygon", xy=inclusion[0])


def horizontal_vertices(fence: Geofence) -> tuple[tuple[float, float], ...]:
    """The fence's x-y outline as the simulator stores it: a polygon's vertices, or a
    box's rectangle from its low corner counter-clockwise (scenario_fence_items)."""
    if fence.polygon_m:
        return tuple((float(x), float(y)) for x, y in fence.polygon_m)
    (x0, y0, _), (x1, y1, _) = fence.min_m, fence.max_m
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))


def same_outline(xy: Sequence[tuple[float, float]], fence: Geofence | None,
                 tol: float = MATCH_TOL_M) -> bool:
    """True when ``xy`` (m) is ``fence``'s outline to ``tol`` (m), whatever the first
    vertex and the winding: the vehicle stores the fence the filter already keeps, which
    then stays as it is, bit for bit."""
    if fence is None:
        return False
    ref = np.array(horizontal_vertices(fence), dtype=float)
    got = np.array(xy, dtype=float)
    if got.shape != ref.shape:
        return False
    for cand in (got, got[::-1]):
        for shift in range(len(cand)):
            if np.all(np.hypot(*(np.roll(cand, shift, axis=0) - ref).T) <= tol):
                return True
    return False


def filter_fence(xy: Sequence[tuple[float, float]], keep: Geofence | None,
                 d_safe: float) -> Geofence | str:
    """The prism over ``xy`` (m) for the filter, with the altitude band and margin of
    ``keep`` (the fence it keeps now; without one :data:`OPEN_BAND_M` and ``d_safe``), or
    why the filter cannot take it (the scenario loader's checks: convex, simple, wider
    than twice the margin)."""
    band = OPEN_BAND_M if keep is None else keep.z_range_m
    margin = d_safe if keep is None else keep.margin_m
    table = {"polygon_m": [[x, y] for x, y in xy], "z_range_m": list(band),
             "margin_m": margin}
    try:
        fence = parse_world({"geofence": table}, d_safe).geofence
    except WorldError as exc:
        return str(exc)
    assert fence is not None
    return fence
