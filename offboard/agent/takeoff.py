"""Coordinated take-off from pads (``[lifecycle] start = "ground"``, docs/lifecycle.md).

Plan (:func:`takeoff_plan`), deterministic from the scenario only (no communication):
every agent's ``position`` is its pad (z = 0; pads ≥ 2·D_safe apart, checked at load).
Agent i climbs vertically above its pad to its staging altitude

    z_i = takeoff_altitude_m + s·(v_i,z − min_j v_j,z)

(s = the leaders' scale, pad separation over vertex separation, Departure 1; v the vertex),
i.e. each vertex layer climbs to its own layer's altitude, so no vehicle ever enters
another's climb column (the columns are the pads, ≥ 2·D_safe apart) and the layers are
already vertically separated when they move sideways into the formation. All agents start
at the plan's start time ``t0`` at ``climb_rate_mps`` with smoothstep speed ramps of
``TAU_R`` s; the climb of ``z_i`` m ends at ``t0 + z_i / v_c + TAU_R`` s; ``t_climb`` is the
latest end. ``t0`` = 0 for a lockstep or in-process run; a real-time swarm started by the
operator (``--manual-start``) holds on its pads until the ground station's take-off command
gives a common ``t0`` (docs/lifecycle.md).

Hand-over: followers track the climb reference until ``t_climb``, then blend into the
desired-state observer's ξ̂ over ``BLEND_S`` s (min-jerk weight σ, derivatives by the
product rule); leaders hold their staging point (the base p_L(0) of their trajectory)
until ``t_traj``, the first whole trajectory period at or after ``t_climb + BLEND_S``, and
then fly it. The safety filter stays active throughout. ENU, z up (m, s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarm_common.enums import StartMode
from swarm_common.scenario.model import Scenario

TAU_R = 1.0  # s, speed ramp time of every climb and descent (offboard.agent.landing too)
BLEND_S = 3.0  # s, followers' blend from the climb reference into ξ̂


@dataclass(frozen=True)
class TakeoffPlan:
    """Common plan: pads (N,3) (m), staging altitudes (N,) (m), climb rate (m/s), the end of
    the climbs ``t_climb`` (s), of the followers' blend ``t_blend`` (s) and the start of the
    leaders' trajectory ``t_traj`` (s), all mission times; the climbs start at ``t0`` (s)."""

    pads: np.ndarray
    z_stage: np.ndarray
    climb_rate: float
    t_climb: float
    t_blend: float
    t_traj: float
    t0: float = 0.0

    def staging(self, index: int) -> np.ndarray:
        """(3,) staging point of agent ``index`` (above its pad)."""
        return np.array([self.pads[index, 0], self.pads[index, 1], self.z_stage[index]])


def is_ground_start(sc: Scenario) -> bool:
    return sc.lifecycle.start is StartMode.GROUND


def takeoff_plan(sc: Scenario, t0: float = 0.0) -> TakeoffPlan:
    """The common take-off plan of a ground-start scenario, climbs starting at mission time
    ``t0`` ≥ 0 s (module docstring); ValueError for a negative or non-finite ``t0``."""
    if not (math.isfinite(t0) and t0 >= 0.0):
        raise ValueError(f"take-off start time {t0!r} s: must be finite and >= 0")
    pads = sc.initial_positions()
    verts = sc.vertices()
    k1, k2 = (sc.index_of(i) for i in sc.formation.leaders[:2])
    scale = float(np.linalg.norm(pads[k1] - pads[k2]) / np.linalg.norm(verts[k1] - verts[k2]))
    lc = sc.lifecycle
    z = lc.takeoff_altitude_m + scale * (verts[:, 2] - verts[:, 2].min())
    t_climb = t0 + float(z.max()) / lc.climb_rate_mps + TAU_R
    t_blend = t_climb + BLEND_S
    period = 1.0 / sc.leader_trajectory.frequency_hz if sc.leader_trajectory.frequency_hz else 0.0
    t_traj = math.ceil(t_blend / period - 1e-9) * period if period > 0.0 else t_blend
    return TakeoffPlan(pads, z, lc.climb_rate_mps, t_climb, t_blend, t_traj, float(t0))


def ramped_travel(s: float, dz: float, v: float) -> tuple[float, float, float, float]:
    """Distance travelled, speed, acceleration, jerk at s ≥ 0 s into a straight move of dz m
    (speed v m/s with smoothstep ramps of TAU_R s; at rest after dz/v + TAU_R s): the
    take-off climb here and the landing descent (offboard.agent.landing)."""
    if s <= 0.0 or dz <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    tau = TAU_R
    t_end = dz / v + tau
    if s >= t_end:
        return dz, 0.0, 0.0, 0.0
    if s < tau:
        x = s / tau
        return (v * tau * (x**3 - 0.5 * x**4), v * (3 * x * x - 2 * x**3),
                v * (6 * x - 6 * x * x) / tau, v * (6 - 12 * x) / tau**2)
    if s <= t_end - tau:
        return v * (s - 0.5 * tau), v, 0.0, 0.0
    x = (t_end - s) / tau
    return (dz - v * tau * (x**3 - 0.5 * x**4), v * (3 * x * x - 2 * x**3),
            -v * (6 * x - 6 * x * x) / tau, v * (6 - 12 * x) / tau**2)


def climb_xi(plan: TakeoffPlan, index: int, t: float) -> np.ndarray:
    """ξ = [p*, v*, a*, j*] (12,) of agent ``index``'s vertical climb at mission time t (at
    rest on its pad until ``plan.t0``)."""
    out = np.zeros(12)
    out[0:2] = plan.pads[index, :2]
    d, v, a, j = ramped_travel(t - plan.t0, float(plan.z_stage[index]), plan.climb_rate)
    out[2] = plan.pads[index, 2] + d
    out[5], out[8], out[11] = v, a, j
    return out


def _min_jerk(x: float) -> tuple[float, float, float, float]:
    """σ, σ', σ'', σ''' of 10x³ − 15x⁴ + 6x⁵ on x ∈ [0, 1] (clamped outside)."""
    if x <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    if x >= 1.0:
        return 1.0, 0.0, 0.0, 0.0
    return (x**3 * (10.0 - 15.0 * x + 6.0 * x * x), 30.0 * x * x * (1.0 - x) ** 2,
            60.0 * x * (1.0 - 3.0 * x + 2.0 * x * x), 60.0 * (1.0 - 6.0 * x + 6.0 * x * x))


def follower_xi(plan: TakeoffPlan, index: int, t: float, xi_hat: np.ndarray) -> np.ndarray:
    """A follower's reference at t: the climb, blended into ``xi_hat`` (ξ̂) from t_climb to
    t_blend with weight σ(x), x = (t − t_climb)/BLEND_S: ξ = ξ_c + σ d with d = ξ̂ − ξ_c,
    derivatives by the product rule (ṗ = v_c + σ' d_p + σ ḋ_p, ...)."""
    if t >= plan.t_blend:
        return np.array(xi_hat, dtype=float)
    c = climb_xi(plan, index, t)
    x = (t - plan.t_climb) / BLEND_S
    if x <= 0.0:
        return c
    s0, s1, s2, s3 = _min_jerk(x)
    s1, s2, s3 = s1 / BLEND_S, s2 / BLEND_S**2, s3 / BLEND_S**3
    d = [np.asarray(xi_hat[3 * k:3 * k + 3], float) - c[3 * k:3 * k + 3] for k in range(4)]
    out = c.copy()
    out[0:3] += s0 * d[0]
    out[3:6] += s1 * d[0] + s0 * d[1]
    out[6:9] += s2 * d[0] + 2 * s1 * d[1] + s0 * d[2]
    out[9:12] += s3 * d[0] + 3 * s2 * d[1] + 3 * s1 * d[2] + s0 * d[3]
    return out


def leader_origin(sc: Scenario, index: int) -> np.ndarray:
    """p_L(0) of leader ``index``'s trajectory: its staging point for a ground start, else its
    scenario ``position``."""
    if is_ground_start(sc):
        return takeoff_plan(sc).staging(index)
    return np.asarray(sc.agents[index].position, dtype=float)


def min_column_separation(plan: TakeoffPlan) -> float:
    """Smallest horizontal distance (m) between two agents' climb columns."""
    xy = plan.pads[:, :2]
    n = len(xy)
    return min(float(np.linalg.norm(xy[i] - xy[j])) for i in range(n) for j in range(i + 1, n))
