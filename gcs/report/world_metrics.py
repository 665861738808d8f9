"""The truth of a run against its world (docs/world.md, docs/metrics.md "World"):
obstacles and the geofence, scored from the simulator's positions and velocities.

* ``obstacle_min_distance_m``: the smallest signed distance (m) from a vehicle's centre to
  an obstacle's surface over every step (< 0: inside);
* ``obstacle_h_min_m``: the smallest obstacle barrier h = d − D + τ ḋ (m; d that distance,
  D the obstacle's ``clearance_m``, τ the pair barrier's ``tau_safe_s``), what the dcbf
  filter's world rows keep ≥ 0;
* ``fence_min_margin_m`` and ``fence_h_min_m``: the same for the geofence, with d the
  distance inside the fence (box or polygon prism) and D its ``margin_m``.

Each is None without obstacles (or without a fence). A barrier below 0 is a truth event
of the verdict (:data:`~swarm_common.enums.SafetyAlarmKind.OBSTACLE`,
:data:`~swarm_common.enums.SafetyAlarmKind.GEOFENCE`): the run is unsafe.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm_common.world.config import World
from swarm_common.world.geometry import fence_distances, obstacle_distances

WORLD_KEYS = ("obstacle_min_distance_m", "obstacle_h_min_m", "fence_min_margin_m",
              "fence_h_min_m")


@dataclass(frozen=True)
class WorldTruth:
    """Per step and agent: obstacle distances and barriers (K,N,O), fence margins and
    barriers (K,N); None where the world has none."""

    dist: np.ndarray | None
    h_obs: np.ndarray | None
    margin: np.ndarray | None
    h_fence: np.ndarray | None


def world_truth(world: World, p: np.ndarray, v: np.ndarray, tau_s: float) -> WorldTruth:
    """The truth of positions ``p`` and velocities ``v`` (K,N,3) against ``world``."""
    dist = h_obs = margin = h_fence = None
    if world.obstacles and p.size:
        dist = np.empty((*p.shape[:2], len(world.obstacles)))
        rate = np.empty_like(dist)
        obstacle_distances(world.table, np.ascontiguousarray(p, dtype=float),
                           np.ascontiguousarray(v, dtype=float), dist, rate)
        h_obs = dist - world.clearances + tau_s * rate
    if world.geofence is not None and p.size:
        f = world.geofence
        planes = f.planes()
        dist_f = fence_distances(planes, p)
        margin = np.min(dist_f, axis=-1)
        # the rate of the nearest face's margin: the velocity along its inward normal
        face = np.argmin(dist_f, axis=-1)
        rate_f = np.sum(planes[face, :3] * v, axis=-1)
        h_fence = margin - f.margin_m + tau_s * rate_f
    return WorldTruth(dist, h_obs, margin, h_fence)


def world_metric_values(truth: WorldTruth) -> dict[str, Any]:
    """The :data:`WORLD_KEYS` of ``truth`` (module docstring)."""

    def mn(a: np.ndarray | None) -> float | None:
        return float(np.min(a)) if a is not None and a.size else None

    return {"obstacle_min_distance_m": mn(truth.dist), "obstacle_h_min_m": mn(truth.h_obs),
            "fence_min_margin_m": mn(truth.margin), "fence_h_min_m": mn(truth.h_fence)}
