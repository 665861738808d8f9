"""Scenario consistency checks that need more than one key: the neighbour graph, the
start separation, the pads of a ground start, and feasibility (docs/scenarios.md).

Each returns or raises one line naming the key; :func:`swarm_common.scenario.model.parse_scenario`
runs them in this order after the schema.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from swarm_common.enums import GraphKind
from swarm_common.scenario import graphs
from swarm_common.scenario.feasibility import feasibility_problem
from swarm_common.scenario.files import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    InfeasibleScenarioError,
    UnsafeScenarioError,
    run_anyway_hint,
)
from swarm_common.scenario.safety_check import safety_problems

if TYPE_CHECKING:
    from swarm_common.scenario.spec import AgentSpec, Scenario

log = logging.getLogger(__name__)

Fail = Callable[[str], Exception]


def check_feasible(sc: Scenario) -> None:
    """Raise :class:`InfeasibleScenarioError` (one line: file, key, numbers) if the vehicles
    cannot fly ``sc`` (:func:`swarm_common.scenario.feasibility.feasibility_problem`); with
    ``sc.allow_infeasible`` log it as a warning instead (docs/scenarios.md)."""
    problem = feasibility_problem(sc)
    if problem is None:
        return
    if sc.allow_infeasible:
        log.warning("%s: %s (%s: running it anyway)", sc.path, problem, ALLOW_INFEASIBLE_FLAG)
        return
    raise InfeasibleScenarioError(
        f"{sc.path}: {problem}{run_anyway_hint(ALLOW_INFEASIBLE_FLAG)}"
    )


def check_safe(sc: Scenario) -> None:
    """Raise :class:`UnsafeScenarioError` (one line: file, key, value, bound) with the first
    broken load-time safety assumption (:func:`swarm_common.scenario.safety_check.
    safety_problems`, docs/safety.md "Load-time checks"); with ``sc.allow_unsafe`` log one
    warning per broken assumption instead."""
    problems = safety_problems(sc)
    if not problems:
        return
    if sc.allow_unsafe:
        for problem in problems:
            log.warning("%s: unsafe: %s (%s: running it anyway)", sc.path, problem,
                        ALLOW_UNSAFE_FLAG)
        return
    raise UnsafeScenarioError(
        f"{sc.path}: unsafe: {problems[0]}{run_anyway_hint(ALLOW_UNSAFE_FLAG)}"
    )


def trust_problem(sc: Scenario) -> str | None:
    """One line naming the key if the dcbf trust region's keys disagree, else None
    (docs/safety.md 5f): ``dcbf_trust_error_mps2`` without a jump bound, a trust region
    without it (it must cover the noise and estimate errors), or one at or above the full
    margin ``dcbf_accel_error_mps2`` that the trust region falls back to."""
    c = sc.controller
    jump, base, full = c.dcbf_trust_jump_mps2, c.dcbf_trust_error_mps2, c.dcbf_accel_error_mps2
    if jump == 0.0:
        if base > 0.0:
            return (f"controller.dcbf_trust_error_mps2 = {base:g}: only read with "
                    f"controller.dcbf_trust_jump_mps2 > 0 (the trust region is off)")
        return None
    if base <= 0.0:
        return (f"controller.dcbf_trust_jump_mps2 = {jump:g}: needs "
                f"controller.dcbf_trust_error_mps2 > 0 (the noise and estimate part of the "
                f"trust region's margin)")
    if base >= full:
        return (f"controller.dcbf_trust_error_mps2 = {base:g}: must be below "
                f"controller.dcbf_accel_error_mps2 = {full:g}, the full margin the trust "
                f"region falls back to")
    return None


def graph_problem(sc: Scenario) -> str | None:
    """One line naming the ``[formation]`` key if the neighbour graph is unusable, else None
    (docs/graphs.md): ``formation.edges`` listing an unknown id, a self-loop or a pair twice,
    or given with another graph kind; ``knn_k`` ≥ N; an edge longer than
    ``sensing_range_m`` in the desired formation (never sensed there); leaders that do not
    fix every follower or a graph that is not bearing rigid (:func:`graphs.rigidity_problem`)."""
    fm = sc.formation
    if fm.edges and fm.graph is not GraphKind.EDGES:
        return f'formation.edges: only read with formation.graph = "edges" (not "{fm.graph}")'
    if fm.graph is GraphKind.EDGES and not fm.edges:
        return 'formation.edges = []: formation.graph = "edges" needs at least one pair'
    if fm.graph is GraphKind.KNN and fm.knn_k >= sc.n:
        return f"formation.knn_k = {fm.knn_k}: must be below the number of agents ({sc.n})"
    lead = [sc.index_of(i) for i in sc.leader_ids]
    v = sc.vertices()
    spec = graphs.graph_spec(fm, sc.initial_positions(), v, lead)
    try:
        edges = graphs.build_edges(v, spec, sc.ids)
    except ValueError as exc:
        return str(exc)
    far = graphs.long_edges(v, edges, spec.range_vu)
    if far:
        i, j, d = far[0]
        return (
            f"formation.sensing_range_m = {fm.sensing_range_m:g}: {spec.describe()} links ids "
            f"{sc.ids[i]} and {sc.ids[j]}, {d * spec.scale:.2f} m apart in the desired "
            f"formation, never sensed there ({len(far)} edge(s) in all)"
        )
    problem = graphs.rigidity_problem(v, edges, sc.ids, lead)
    return None if problem is None else f"{spec.describe()}: {problem}"


def check_separation(
    agents: list[AgentSpec], leaders: list[int], d_safe: float, fail: Fail
) -> None:
    """Refuse a scenario that is unsafe before it starts: two agents starting closer than
    ``controller.d_safe_m``, or a formation whose vertices, scaled by the leaders'
    separation (Departure 1), put two agents closer than that. The first such pair in
    index order is named (its start before its vertices)."""
    p = np.array([a.position for a in agents])
    v = np.array([a.vertex for a in agents])
    k1, k2 = (next(k for k, a in enumerate(agents) if a.id == lid) for lid in leaders[:2])
    scale = float(np.linalg.norm(p[k1] - p[k2]) / np.linalg.norm(v[k1] - v[k2]))
    reach = d_safe / scale if scale > 0.0 else math.inf
    for i, j in sorted(graphs.close_pairs(p, d_safe) | graphs.close_pairs(v, reach)):
        d0 = float(np.linalg.norm(p[i] - p[j]))
        if d0 < d_safe:
            raise fail(
                f"agent[{j}].position = {p[j].tolist()}: starts {d0:.3f} m from agent id "
                f"{agents[i].id}, closer than controller.d_safe_m = {d_safe:g}"
            )
        dv = scale * float(np.linalg.norm(v[i] - v[j]))
        if dv < d_safe:
            raise fail(
                f"agent[{j}].vertex = {v[j].tolist()}: {dv:.3f} m from agent id "
                f"{agents[i].id}'s vertex at the leaders' scale, closer than "
                f"controller.d_safe_m = {d_safe:g}"
            )


def check_pads(agents: list[AgentSpec], d_safe: float, fail: Fail) -> None:
    """lifecycle.start = "ground": every ``position`` is a pad on the ground (z = 0) and the
    pads are at least 2·``controller.d_safe_m`` apart (the climb columns,
    offboard.agent.takeoff)."""
    for k, a in enumerate(agents):
        if abs(float(a.position[2])) > 1e-9:
            raise fail(
                f"agent[{k}].position = {a.position.tolist()}: with lifecycle.start = 'ground' "
                f"the position is a pad and its z must be 0"
            )
    pads = np.array([a.position[:2] for a in agents], dtype=float).reshape(-1, 2)
    for i, j in sorted(graphs.close_pairs(pads, 2.0 * d_safe)):
        d = float(np.linalg.norm(agents[i].position[:2] - agents[j].position[:2]))
        if d < 2.0 * d_safe - 1e-9:
            raise fail(
                f"agent[{j}].position = {agents[j].position.tolist()}: pad {d:.3f} m from "
                f"agent id {agents[i].id}'s, closer than 2 * controller.d_safe_m = "
                f"{2.0 * d_safe:g} (lifecycle.start = 'ground')"
            )


