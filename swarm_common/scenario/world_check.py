"""Load-time checks of a scenario's world (docs/world.md, "Checked at load"), part of the
load-time safety checks (:func:`swarm_common.scenario.safety_check.safety_problems`):

* every agent starts outside every obstacle by its ``clearance_m`` and inside the
  geofence by its ``margin_m``;
* the leaders, which fly their reference with no filter, keep that clearance along it:
  the ``[leader_trajectory]`` sinusoid p_L(t) = p_L(0) + A (1 − cos ωt) is sampled over
  one period (:data:`SAMPLES` points), a ``[mission]``'s timed plan every
  :data:`MISSION_STEP_S` (at most :data:`MISSION_SAMPLES` points) to its end. Between
  samples a leader moves at most its speed limit times the step (a few centimetres).

Each problem is one line naming the agent and the obstacle or the fence's nearest face
(a box's ``max_m.x``, a polygon's ``side polygon_m[2]–[3]``, ``floor`` or ``ceiling``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from swarm_common.mission.plan import MissionPlan
from swarm_common.mission.timeline import Plan
from swarm_common.scenario.mission_check import plan_for
from swarm_common.world.geometry import fence_distances, fence_margins, obstacle_distances

if TYPE_CHECKING:
    from swarm_common.scenario.spec import Scenario

SAMPLES = 64  # points per period of the leaders' sinusoid
MISSION_STEP_S = 0.05  # s between samples of a mission's plan
MISSION_SAMPLES = 20_000  # ... and at most this many


def _worst(sc: Scenario, p: np.ndarray, ids: list[int], what: str) -> str | None:
    """The first broken clearance of the points ``p`` (K,N,3) of agents ``ids``."""
    w = sc.world
    if w.obstacles:
        d = np.empty((*p.shape[:2], len(w.obstacles)))
        obstacle_distances(w.table, np.ascontiguousarray(p), np.zeros_like(p), d,
                           np.empty_like(d))
        gap = d - w.clearances
        k, i, o = np.unravel_index(int(np.argmin(gap)), gap.shape)
        if gap[k, i, o] < 0.0:
            ob = w.obstacles[o]
            return (f"obstacle[{o}] ({ob.kind}): agent {ids[i]} {what} {d[k, i, o]:.2f} m from "
                    f"its surface, inside its clearance_m = {ob.clearance_m:g}")
    if w.geofence is not None:
        f = w.geofence
        planes = f.planes()
        m = fence_margins(planes, p)
        k, i = np.unravel_index(int(np.argmin(m)), m.shape)
        if m[k, i] < f.margin_m:
            face = f.face_names()[int(np.argmin(fence_distances(planes, p[k, i])))]
            where = (f"{m[k, i]:.2f} m inside it" if m[k, i] >= 0.0
                     else f"{-m[k, i]:.2f} m outside it")
            return (f"geofence: agent {ids[i]} {what} {where} (nearest face: {face}), less "
                    f"than geofence.margin_m = {f.margin_m:g}")
    return None


def plan_world_problem(sc: Scenario, plan: Plan, t0: float) -> str | None:
    """The first clearance that the leaders break flying ``plan`` from ``t0`` (s) to its
    end, sampled every :data:`MISSION_STEP_S` (at most :data:`MISSION_SAMPLES` points):
    the load-time check of a ``[mission]``, and of every plan a ground station sends in
    flight (:func:`swarm_common.scenario.flight_check.checked_timeline`)."""
    if sc.world.empty:
        return None
    lead = [k for k, a in enumerate(sc.agents) if a.is_leader]
    # a hold is a plan without legs (no end_s): its one pose
    end = t0 if isinstance(plan, MissionPlan) and not plan.legs else max(float(plan.end_s), t0)
    n = int(min(MISSION_SAMPLES, math.ceil((end - t0) / MISSION_STEP_S) + 1))
    times = np.linspace(t0, end, max(n, 2))
    path = np.array([[plan.agent_xi(t, k)[0:3] for k in lead] for t in times])
    return _worst(sc, path, [sc.agents[k].id for k in lead], "flies its mission")


def world_problem(sc: Scenario) -> str | None:
    """The first broken world assumption of ``sc`` (module docstring), else None."""
    if sc.world.empty:
        return None
    start = sc.initial_positions()[None]
    problem = _worst(sc, start, list(sc.ids), "starts")
    if problem is not None:
        return problem
    lead = [k for k, a in enumerate(sc.agents) if a.is_leader]
    lead_ids = [sc.agents[k].id for k in lead]
    if sc.mission is not None:
        return plan_world_problem(sc, plan_for(sc), 0.0)
    lt = sc.leader_trajectory
    if lt.frequency_hz <= 0.0 or not any(lt.amplitude_m):
        return None
    t = np.linspace(0.0, 1.0 / lt.frequency_hz, SAMPLES)
    wave = 1.0 - np.cos(2.0 * math.pi * lt.frequency_hz * t)
    path = sc.initial_positions()[lead][None] + wave[:, None, None] * np.asarray(
        lt.amplitude_m, float)
    return _worst(sc, path, lead_ids, "flies its sinusoid")
