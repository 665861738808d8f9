"""The truth of a run against its world (docs/world.md, docs/metrics.md "World"):
obstacles and the geofence, scored from the simulator's positions and velocities.

* ``obstacle_min_distance_m``: the smallest signed distance (m) from a vehicle's centre to
  an obstacle's surface over every step (< 0: inside);
* ``obstacle_h_min_m``: the smallest obstacle barrier h = d − D + τ ḋ (m; d that distance,
  D the obstacle's ``clearance_m``, τ the pair barrier's ``tau_safe_s``), what the dcbf
  filter's world rows keep ≥ 0;
* ``fence_min_margin_m`` and ``fence_h_min_m``: the same for the geofence, with d the
  distance inside the fence (box or polygon prism) and D its ``margin_m``.

The fence is the scenario's, and for a vehicle whose stored fence a ground station
changed in a distributed run, from the step the simulator reports it (``wire.Truth.fences``)
the one it stores, made into the filter's prism (the scenario fence's altitude band and
margin; docs/world.md): the fence the simulator enforces. A stored fence that is not one
convex inclusion polygon is not scored for that vehicle from then (its daemon raises
FENCE_MISMATCH instead).

Each is None without obstacles (or without a fence). A barrier below 0 is a truth event
of the verdict (:data:`~swarm_common.enums.SafetyAlarmKind.OBSTACLE`,
:data:`~swarm_common.enums.SafetyAlarmKind.GEOFENCE`): the run is unsafe.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm_common.world.config import Geofence, World
from swarm_common.world.geometry import fence_distances, obstacle_distances
from swarm_common.world.mavlink_fence import filter_fence

# a vehicle's stored fence changed at time t (s): (t, the vehicle's column, its outline's
# ENU vertices x0, y0, x1, y1, ... in m; empty: not one inclusion polygon)
FenceChange = tuple[float, int, tuple[float, ...]]

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


def _fence_truth(f: Geofence, p: np.ndarray, v: np.ndarray,
                 tau_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Margins and barriers (…) of positions and velocities (…,3) inside ``f``."""
    planes = f.planes()
    dist_f = fence_distances(planes, p)
    margin = np.min(dist_f, axis=-1)
    # the rate of the nearest face's margin: the velocity along its inward normal
    face = np.argmin(dist_f, axis=-1)
    rate_f = np.sum(planes[face, :3] * v, axis=-1)
    return margin, margin - f.margin_m + tau_s * rate_f


def world_truth(world: World, p: np.ndarray, v: np.ndarray, tau_s: float,
                t: np.ndarray | None = None, changes: tuple[FenceChange, ...] = (),
                d_safe: float = 0.0) -> WorldTruth:
    """The truth of positions ``p`` and velocities ``v`` (K,N,3) against ``world``, and
    against the stored fences of ``changes`` (at times ``t`` (K,) s; ``d_safe`` the margin
    of an uploaded fence where the scenario has none); NaN where a vehicle has no fence."""
    dist = h_obs = margin = h_fence = None
    if world.obstacles and p.size:
        dist = np.empty((*p.shape[:2], len(world.obstacles)))
        rate = np.empty_like(dist)
        obstacle_distances(world.table, np.ascontiguousarray(p, dtype=float),
                           np.ascontiguousarray(v, dtype=float), dist, rate)
        h_obs = dist - world.clearances + tau_s * rate
    if world.geofence is not None and p.size:
        margin, h_fence = _fence_truth(world.geofence, p, v, tau_s)
    if changes and t is not None and p.size:
        if margin is None or h_fence is None:
            margin, h_fence = np.full(p.shape[:2], np.nan), np.full(p.shape[:2], np.nan)
        for when, col, xy in sorted(changes, key=lambda c: c[0]):
            rows = t >= when - 1e-9
            pts = tuple(zip(xy[0::2], xy[1::2], strict=True))
            f = filter_fence(pts, world.geofence, d_safe) if pts else "no polygon"
            if isinstance(f, str):
                margin[rows, col] = h_fence[rows, col] = np.nan
            else:
                margin[rows, col], h_fence[rows, col] = _fence_truth(
                    f, p[rows, col], v[rows, col], tau_s)
    return WorldTruth(dist, h_obs, margin, h_fence)


def world_metric_values(truth: WorldTruth) -> dict[str, Any]:
    """The :data:`WORLD_KEYS` of ``truth`` (module docstring)."""

    def mn(a: np.ndarray | None) -> float | None:
        if a is None or not a.size or np.all(np.isnan(a)):
            return None
        return float(np.nanmin(a))

    return {"obstacle_min_distance_m": mn(truth.dist), "obstacle_h_min_m": mn(truth.h_obs),
            "fence_min_margin_m": mn(truth.margin), "fence_h_min_m": mn(truth.h_fence)}
