"""The compiled plan evaluation (swarm_common.mission.plan_kernel) against the plan's own
pose walk: positions from the poses, the leg found at every boundary as bisect finds it.
The derivatives are held to finite differences in test_mission_plan.py."""

from __future__ import annotations

import math

import numpy as np

from swarm_common.mission.plan import build_plan
from swarm_common.mission.profile import POWERS, sigma_jet_kernel, sigma_jets
from tests.unit.mission.test_mission_plan import CFG, LIMITS, SHAPE, rz


def test_positions_follow_the_pose_at_every_boundary():
    plan = build_plan(CFG, SHAPE, LIMITS)
    q = SHAPE - SHAPE.mean(axis=0)
    edges = [x for leg in plan.legs for x in (leg.t0, leg.arrival_s, leg.departure_s)]
    ts = np.concatenate([np.linspace(-3.0, plan.end_s + 3.0, 4001), edges,
                         np.nextafter(edges, -np.inf), np.nextafter(edges, np.inf)])
    worst = 0.0
    for t in ts:
        c, s, y = plan.pose_jet(float(t))
        want = c[0] + s[0] * q @ rz(float(y[0])).T
        got = plan.all_xi(float(t))
        worst = max(worst, float(np.abs(got[:, 0:3] - want).max()))
        for i in (0, 3):
            assert np.array_equal(plan.agent_xi(float(t), i), got[i])
    assert worst < 1e-12


def test_at_rest_outside_the_legs_and_a_nan_time_like_bisect():
    plan = build_plan(CFG, SHAPE, LIMITS)
    before, after = plan.all_xi(-1e9), plan.all_xi(plan.end_s + 1e9)
    assert np.all(before[:, 3:] == 0.0) and np.all(after[:, 3:] == 0.0)
    moving = plan.all_xi(0.5 * (plan.legs[1].t0 + plan.legs[1].arrival_s))
    assert np.abs(moving[:, 3:6]).max() > 0.1
    # bisect_right puts NaN after every start: the last leg's end pose, at rest
    assert np.array_equal(plan.all_xi(math.nan), after)


def test_compiled_profile_agrees_with_the_vectorised_one():
    tau = np.concatenate([np.linspace(-0.5, 1.5, 20001), [0.0, 0.5, 1.0]])
    rows = sigma_jets(tau)
    st = np.empty(4)
    for k, t in enumerate(tau):
        sigma_jet_kernel(float(t), POWERS, st)
        assert np.allclose(st, rows[k], rtol=0.0, atol=1e-12)
