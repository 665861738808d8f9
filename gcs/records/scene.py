"""The ``/scene`` messages of a record (foxglove.SceneUpdate): the vehicles (spheres of the
collision radius, locked to their ``vehicle_<id>`` frames, with their id as a label), the
obstacles and the geofence of the scenario's world (once, at the first step), and the
bearings each follower senses as lines between the true positions (every
:data:`BEARING_PERIOD_S`). Units m, frame ``world`` (ENU)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from gcs.records.topics import WORLD_FRAME, vehicle_frame

BEARING_PERIOD_S = 0.1  # s: the bearing lines are drawn at 10 Hz (the 3-D view's need)
LEADER = Color(r=0.9, g=0.3, b=0.2, a=0.9)
FOLLOWER = Color(r=0.2, g=0.5, b=0.95, a=0.9)
BEARING = Color(r=0.95, g=0.85, b=0.2, a=0.8)
OBSTACLE = Color(r=0.5, g=0.5, b=0.5, a=0.6)
FENCE = Color(r=0.1, g=0.8, b=0.3, a=0.9)
IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)


def stamp(ns: int) -> Timestamp:
    """A foxglove Timestamp of ``ns`` nanoseconds of simulation time."""
    return Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _pose(x: float, y: float, z: float, yaw_rad: float = 0.0) -> Pose:
    q = Quaternion(x=0.0, y=0.0, z=math.sin(yaw_rad / 2), w=math.cos(yaw_rad / 2))
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=q)


def vehicle_entities(ns: int, ids: Sequence[int], leaders: Sequence[int],
                     radius_m: float) -> list[SceneEntity]:
    """One frame-locked entity per vehicle (a sphere of diameter 2 ``radius_m`` and its id)."""
    out = []
    d = max(2 * radius_m, 0.05)
    for i in ids:
        col = LEADER if i in leaders else FOLLOWER
        out.append(SceneEntity(
            timestamp=stamp(ns), frame_id=vehicle_frame(i), id=f"vehicle/{i}",
            frame_locked=True,
            spheres=[SpherePrimitive(pose=_pose(0, 0, 0), size=Vector3(x=d, y=d, z=d),
                                     color=col)],
            texts=[TextPrimitive(pose=_pose(0, 0, d), billboard=True, font_size=14.0,
                                 scale_invariant=True, color=col, text=str(i))]))
    return out


def world_entities(ns: int, world: Any) -> list[SceneEntity]:
    """The obstacles (grey) and the geofence (green lines) of ``world``
    (:class:`swarm_common.world.config.World`); none without either."""
    out = []
    spheres, cyls, cubes = [], [], []
    for ob in world.obstacles:
        c = ob.centre_m
        kind = str(ob.kind)
        if kind == "sphere":
            d = 2 * ob.radius_m
            spheres.append(SpherePrimitive(pose=_pose(*c), size=Vector3(x=d, y=d, z=d),
                                           color=OBSTACLE))
        elif kind == "cylinder":
            d, hgt = 2 * ob.radius_m, ob.z_range_m[1] - ob.z_range_m[0]
            zc = 0.5 * (ob.z_range_m[0] + ob.z_range_m[1])
            cyls.append(CylinderPrimitive(pose=_pose(c[0], c[1], zc),
                                          size=Vector3(x=d, y=d, z=hgt), bottom_scale=1.0,
                                          top_scale=1.0, color=OBSTACLE))
        else:
            sx, sy, sz = ob.size_m
            cubes.append(CubePrimitive(pose=_pose(c[0], c[1], c[2], math.radians(ob.yaw_deg)),
                                       size=Vector3(x=sx, y=sy, z=sz), color=OBSTACLE))
    if spheres or cyls or cubes:
        out.append(SceneEntity(timestamp=stamp(ns), frame_id=WORLD_FRAME, id="obstacles",
                               spheres=spheres, cylinders=cyls, cubes=cubes))
    fence = world.geofence
    if fence is not None:
        lo, hi = fence.min_m, fence.max_m
        ring = list(fence.polygon_m) or [(lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]),
                                         (lo[0], hi[1])]
        pts = []
        for a in range(len(ring)):
            (x0, y0), (x1, y1) = ring[a], ring[(a + 1) % len(ring)]
            for z in (lo[2], hi[2]):  # bottom and top edges
                pts += [Point3(x=x0, y=y0, z=z), Point3(x=x1, y=y1, z=z)]
            pts += [Point3(x=x0, y=y0, z=lo[2]), Point3(x=x0, y=y0, z=hi[2])]  # upright
        out.append(SceneEntity(
            timestamp=stamp(ns), frame_id=WORLD_FRAME, id="geofence",
            lines=[LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose(0, 0, 0),
                                 thickness=2.0, scale_invariant=True, points=pts,
                                 color=FENCE)]))
    return out


def sensed_pairs(sensed: Sequence[Sequence[int]], follower_idx: Sequence[int]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) column indices: follower a senses the bearing to b."""
    a = [f for f in follower_idx for _ in sensed[f]]
    b = [j for f in follower_idx for j in sensed[f]]
    return np.asarray(a, np.int64), np.asarray(b, np.int64)


def bearing_update(ns: int, p_k: np.ndarray, a: np.ndarray, b: np.ndarray) -> SceneUpdate:
    """The ``bearings`` entity at one step: a line from each follower to what it senses,
    ``p_k`` (N, 3) the true positions (m)."""
    seg = np.empty((2 * len(a), 3))
    seg[0::2], seg[1::2] = p_k[a], p_k[b]
    pts = [Point3(x=x, y=y, z=z) for x, y, z in seg.tolist()]
    ent = SceneEntity(timestamp=stamp(ns), frame_id=WORLD_FRAME, id="bearings",
                      lines=[LinePrimitive(type=LinePrimitiveLineType.LineList,
                                           pose=_pose(0, 0, 0), thickness=1.5,
                                           scale_invariant=True, points=pts, color=BEARING)])
    return SceneUpdate(entities=[ent])
