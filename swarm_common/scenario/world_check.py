"""Load-time checks of a scenario's world (docs/world.md, "Checked at load"), part of the
load-time safety checks (:func:`swarm_common.scenario.safety_check.safety_problems`):

* every agent starts outside every obstacle by its ``clearance_m`` and inside the
  geofence by its ``margin_m``;
* the leaders, which fly their reference with no filter, keep that clearance along it:
  the ``[leader_trajectory]`` sinusoid p_L(t) = p_L(0) + A (1 − cos ωt) is sampled over
  one period (:data:`SAMPLES` points), a ``[mission]``'s timed plan every
  :data:`MISSION_STEP_S` (at most :data:`MISSION_SAMPLES` points) to its end. Between
  samples a leader moves at most its speed limit times the step (a few centimetres).

Each problem is one line naming the agent and the obstacle or face.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from swarm_common.scenario.mission_check import plan_for
from swarm_common.world.geometry import fence_margins, obstacle_distances

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
        fence = np.array([f.min_m, f.max_m])
        m = fence_margins(fence, p)
        k, i = np.unravel_index(int(np.argmin(m)), m.shape)
        if m[k, i] < f.margin_m:
            return (f"geofence: agent {ids[i]} {what} {m[k, i]:.2f} m inside it, less than "
                    f"geofence.margin_m = {f.margin_m:g}")
    return None


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
        plan = plan_for(sc)
        n = int(min(MISSION_SAMPLES, math.ceil(plan.end_s / MISSION_STEP_S) + 1))
        times = np.linspace(0.0, plan.end_s, max(n, 2))
        path = np.array([[plan.agent_xi(t, k)[0:3] for k in lead] for t in times])
        return _worst(sc, path, lead_ids, "flies its mission")
    lt = sc.leader_trajectory
    if lt.frequency_hz <= 0.0 or not any(lt.amplitude_m):
        return None
    t = np.linspace(0.0, 1.0 / lt.frequency_hz, SAMPLES)
    wave = 1.0 - np.cos(2.0 * math.pi * lt.frequency_hz * t)
    path = sc.initial_positions()[lead][None] + wave[:, None, None] * np.asarray(
        lt.amplitude_m, float)
    return _worst(sc, path, lead_ids, "flies its sinusoid")
