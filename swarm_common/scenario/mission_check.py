"""A scenario's formation mission: its timed plan, and the load-time check that the vehicles
can fly it (docs/missions.md).

The plan (:func:`plan_for`) is built from the scenario alone, so every process (the
in-process runner, each daemon, the report) computes the same one. The shape it flies is
the desired formation at the start: the leaders' ``position`` and the followers where the
bearings put them (:func:`~swarm_common.scenario.feasibility.desired_origins`).

Limits (:func:`mission_limits`): every agent's speed, acceleration and jerk as the
``[mission]`` table sets them; the floor is the dcbf ground clearance plus the collision
radius; no two agents closer than ``controller.d_safe_m`` at any waypoint. The table's
acceleration and jerk must leave the feedback its share of the input set: with the attitude
lag τ the needed command is about a + τ j, which must stay within (1 − FEEDBACK_RESERVE) of
min(u_max, g tan(tilt_max)).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.memo import IdentityMemo
from swarm_common.mission.config import MissionConfig, MissionError
from swarm_common.mission.plan import Limits, MissionPlan, build_plan
from swarm_common.mission.timeline import MissionTimeline
from swarm_common.scenario.feasibility import FEEDBACK_RESERVE, desired_origins
from swarm_common.scenario.spec import Scenario

_PLANS: IdentityMemo[MissionPlan] = IdentityMemo()
MIN_YAW_OFFSET_M = 1e-3  # m: leaders closer horizontally cannot carry the yaw


def mission_limits(sc: Scenario) -> Limits:
    """The :class:`~swarm_common.mission.plan.Limits` of ``sc``'s mission (module docstring)."""
    m = sc.mission
    assert m is not None
    ctl, veh = sc.controller, sc.vehicle
    return Limits(
        max_speed_mps=m.max_speed_mps, max_accel_mps2=m.max_accel_mps2,
        max_jerk_mps3=m.max_jerk_mps3,
        floor_m=ctl.dcbf_ground_clearance_m + veh.collision_radius_m,
        min_separation_m=ctl.d_safe_m,
    )


def available_accel(sc: Scenario) -> float:
    """What a mission may use of the input set (m/s²): (1 − FEEDBACK_RESERVE) ×
    min(u_max, g tan(tilt_max))."""
    veh = sc.vehicle
    a = min(sc.controller.u_max_mps2,
            veh.gravity_mps2 * math.tan(math.radians(veh.tilt_max_deg)))
    return (1.0 - FEEDBACK_RESERVE) * a


def mission_shape(sc: Scenario) -> np.ndarray:
    """(N, 3) the formation the mission moves: every agent's desired start position (m)."""
    shape = desired_origins(sc)
    if shape is None:
        raise MissionError("mission: the formation does not fix every follower "
                           "(formation.graph), so it cannot be moved as one")
    return shape


def plan_for(sc: Scenario) -> MissionPlan:
    """The timed plan of ``sc``'s mission (built once per scenario object in a process)."""
    if sc.mission is None:
        raise ValueError(f"{sc.path}: the scenario has no [mission]")
    mission = sc.mission
    return _PLANS.get(sc, (), lambda: build_plan(mission, mission_shape(sc), mission_limits(sc)))


def mission_problem(sc: Scenario) -> str | None:
    """One line naming the key when ``sc``'s mission cannot be flown, else None (no mission:
    None)."""
    m = sc.mission
    if m is None:
        return None
    need = m.max_accel_mps2 + sc.vehicle.tau_rollpitch_s * m.max_jerk_mps3
    avail = available_accel(sc)
    if need > avail:
        return (f"mission.max_accel_mps2 = {m.max_accel_mps2:g} with max_jerk_mps3 = "
                f"{m.max_jerk_mps3:g} needs {need:.2f} m/s² (a + τ j, τ = "
                f"vehicle.tau_rollpitch_s), above the {avail:.2f} m/s² the vehicle leaves "
                f"after the feedback reserve")
    problem = turn_problem(sc, m)
    if problem is not None:
        return problem
    try:
        plan_for(sc)
    except MissionError as exc:
        return str(exc)
    return None


def yaw_leaders(sc: Scenario) -> tuple[int, int, np.ndarray]:
    """(a, b, offset): the scenario indices of the first two leaders, whose horizontal
    offset carries the formation's yaw, and their offset p_b − p_a (m) in the mission's
    shape (yaw 0)."""
    shape = mission_shape(sc)
    a, b = (sc.index_of(i) for i in sc.formation.leaders[:2])
    return a, b, shape[b] - shape[a]


def leaders_carry_yaw(sc: Scenario) -> bool:
    """True when the first two leaders are apart horizontally in the mission's shape, so
    their offset carries the formation's yaw (docs/missions.md)."""
    return float(np.hypot(*yaw_leaders(sc)[2][:2])) >= MIN_YAW_OFFSET_M


def timeline_for(sc: Scenario) -> MissionTimeline:
    """A fresh timeline of ``sc``'s mission: its plan, then what commands change."""
    return MissionTimeline(plan_for(sc), mission_shape(sc), mission_limits(sc))


def yaws(sc: Scenario) -> bool:
    """True when ``sc``'s formation may turn: it has a mission (a ground station may turn it
    in flight) and its leaders carry the yaw. Its followers then run their desired-state
    observer in the formation's frame."""
    return sc.mission is not None and leaders_carry_yaw(sc)


def turn_problem(sc: Scenario, cfg: MissionConfig) -> str | None:
    """One line when mission ``cfg`` turns a formation whose leaders cannot carry the yaw."""
    if any(w.yaw_deg != 0.0 for w in cfg.waypoints) and not leaders_carry_yaw(sc):
        return ("mission: a waypoint turns the formation (yaw_deg), but the first two "
                "leaders are stacked vertically: their offset cannot carry the yaw")
    return None
