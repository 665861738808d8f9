"""A formation flown live (swarm_common.mission.live): the centroid follows a streamed
velocity within the limits, from wherever the plan in force is, and stops by itself."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from swarm_common.mission.config import MissionError, parse_mission
from swarm_common.mission.live import LIVE_TIMEOUT_S, MIN_BLEND_S, LivePlan, live_plan
from swarm_common.mission.plan import Limits
from swarm_common.scenario.mission_check import timeline_for
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]
# course8: leg 0 holds at (2, 2, 4) until 10 s, leg 1 translates to (14, 2, 4) until
# 27.85 s, leg 2 turns by 90 deg; limits 3 m/s, 1 m/s^2, 2 m/s^3, floor 0.8 m, lowest
# agent 2 m under the centroid
COURSE8 = load_scenario(ROOT / "scenarios" / "course8.toml")
LIMITS = Limits(3.0, 1.0, 2.0, -1e3, 0.5)  # the floor out of the way (random starts)
Q = np.array([[2.0, -1.0, 1.0], [-1.5, 2.0, -0.5], [0.5, 0.5, 1.5], [-1.0, -1.5, -2.0]])
TOL = 1e-3  # relative: what the duration search's sampling may miss between samples


def plan_from(v0, a0, vel, yaw=0.4, start=3.0, limits=LIMITS) -> LivePlan:
    return live_plan(start, np.array([1.0, -2.0, 5.0]), np.asarray(v0, float),
                     np.asarray(a0, float), 1.3, yaw, vel, Q, limits)


def random_starts() -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(v0, a0, v*) within the limits (v* at most 0.9 of the speed limit: a start that
    accelerates outwards at the speed limit cannot stay under it), seeded."""
    rng = np.random.default_rng(7)

    def ball(r: float) -> np.ndarray:
        x = rng.normal(size=3)
        return x / np.linalg.norm(x) * r * rng.uniform(0.1, 1.0)

    cases = [(ball(2.0), ball(0.7), ball(2.7)) for _ in range(8)]
    v = np.array([2.0, -1.0, 0.5])
    cases.append((v, np.array([0.4, 0.3, -0.2]), -1.2 * v))  # v0 opposite to v*, a0 != 0
    cases.append((v, -0.6 * v / np.linalg.norm(v), -1.2 * v))  # a0 along the change
    cases.append((np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 0.0])))  # a stop from rest
    return cases


def jets(plan: LivePlan, times: np.ndarray) -> np.ndarray:
    """(K, N, 12) every agent's jet at ``times``."""
    return np.array([plan.all_xi(float(t)) for t in times])


def test_the_jets_match_central_differences_on_every_segment():
    h = 1e-4  # s; truncation ~ h^2 * (next derivative) <= 1e-7, rounding ~ 1e-16 * 20 / h
    for v0, a0, vel in random_starts()[-3:-1] + random_starts()[:2]:
        plan = plan_from(v0, a0, vel)
        bounds = np.array(plan.segment_s)
        t = np.linspace(plan.start_s, plan.rest_s + 1.0, 400)
        t = t[np.min(np.abs(t[:, None] - bounds[None, :]), axis=1) > 3 * h]  # jerk jumps
        lo, hi, mid = jets(plan, t - h), jets(plan, t + h), jets(plan, t)
        fd = (hi - lo) / (2 * h)
        for k in range(3):  # p -> p', p' -> p'', p'' -> p'''
            np.testing.assert_allclose(fd[..., 3 * k:3 * k + 3], mid[..., 3 * k + 3:3 * k + 6],
                                       atol=1e-6, err_msg=f"derivative {k + 1}")
        moving = t < plan.rest_s
        assert np.any(np.abs(mid[moving, :, 9:12]) > 1e-3)  # the check did see a jerk


def test_the_limits_hold_under_dense_sampling_and_the_blend_is_short():
    for v0, a0, vel in random_starts():
        plan = plan_from(v0, a0, vel)
        t = np.arange(plan.start_s, plan.rest_s + 0.5, 1e-3)
        c = np.array([plan.pose_jet(float(x))[0] for x in t])  # (K, 4, 3)
        norms = np.linalg.norm(c[:, 1:], axis=2)
        peaks = norms.max(axis=0) / [LIMITS.max_speed_mps, LIMITS.max_accel_mps2,
                                     LIMITS.max_jerk_mps3]
        assert np.all(peaks <= 1.0 + TOL), (v0, a0, vel, peaks)
        # every agent moves like the centroid (scale and yaw are constant)
        xi = plan.all_xi(float(t[len(t) // 3]))
        np.testing.assert_array_equal(xi[:, 3:], np.broadcast_to(xi[0, 3:], xi[:, 3:].shape))
        # the shortest blend: a limit is (nearly) reached on it, unless it is the shortest
        t1 = plan.segment_s[1] - plan.start_s
        if t1 > MIN_BLEND_S * 1.01:
            on = t <= plan.segment_s[1]
            blend = (norms[on].max(axis=0) / [3.0, 1.0, 2.0]).max()
            assert blend >= 0.95, (v0, a0, vel, blend)
        # it reaches v* with zero acceleration, then brakes to rest
        end = plan.pose_jet(plan.segment_s[1])[0]
        np.testing.assert_allclose(end[1], vel, atol=1e-12)
        np.testing.assert_allclose(end[2], 0.0, atol=1e-12)


def test_the_position_is_the_integral_of_the_velocity():
    plan = plan_from([2.0, -1.0, 0.5], [0.4, 0.3, -0.2], [-2.4, 1.2, -0.6])
    t = np.linspace(plan.start_s, plan.rest_s, 40001)
    c = np.array([plan.pose_jet(float(x))[0] for x in t[::40000]])
    v = np.array([plan.pose_jet(float(x))[0][1] for x in t])
    dx = np.trapezoid(v, t, axis=0)  # error <= dt^2 / 12 * max|jerk| * T ~ 2e-7
    np.testing.assert_allclose(c[-1, 0] - c[0, 0], dx, atol=1e-6)


def test_it_rests_after_the_timeout_and_its_rest_is_what_commands_see():
    tl = timeline_for(COURSE8)
    start = tl.live([0.2, -0.1, 0.05], 5.0)  # at rest at waypoint 0: starts at once
    assert start == 5.0
    plan = tl.plan_at(5.0)
    assert isinstance(plan, LivePlan)
    t1 = plan.segment_s[1] - start
    assert t1 < LIVE_TIMEOUT_S  # a short blend: it cruises at v* until the timeout
    assert plan.segment_s[2] == pytest.approx(start + LIVE_TIMEOUT_S, abs=1e-12)
    np.testing.assert_allclose(tl.all_xi(start + 0.5 * (t1 + LIVE_TIMEOUT_S))[:, 3:6],
                               np.tile([0.2, -0.1, 0.05], (8, 1)), atol=1e-12)
    rest = plan.rest_s
    assert plan.arrival_s == plan.departure_s == (rest,) and plan.end_s == rest
    assert plan.transit_window == (start, rest)
    assert rest > start + LIVE_TIMEOUT_S
    for t in np.linspace(rest, rest + 100.0, 57):
        xi = tl.all_xi(float(t))
        assert np.all(xi[:, 3:] == 0.0)  # exactly at rest
        np.testing.assert_allclose(xi[:, :3], tl.all_xi(rest)[:, :3], atol=1e-12)
    assert np.linalg.norm(tl.all_xi(rest - 0.05)[:, 3:6]) > 0.0  # still moving just before
    assert plan.at_rest_from(start + 0.5) == rest
    assert plan.at_rest_from(0.5 * (plan.segment_s[2] + rest)) == rest  # braking
    assert plan.at_rest_from(rest + 2.0) == rest + 2.0
    pose = plan.rest_pose(rest)
    np.testing.assert_allclose(pose.centroid, tl.all_xi(rest + 1.0)[:, :3].mean(axis=0),
                               atol=1e-12)
    assert (pose.scale, pose.yaw_rad) == (1.0, 0.0)
    with pytest.raises(ValueError, match="moving"):
        plan.rest_pose(start + 0.5)
    assert plan.legs == () and plan.waypoint_at(rest + 1.0) == 0
    np.testing.assert_array_equal(plan.yaw_jet(start + 0.5), [0.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(plan.agent_xi(start + 0.7, 3), plan.all_xi(start + 0.7)[3])


def test_a_live_command_mid_translation_is_continuous_at_the_switch():
    tl = timeline_for(COURSE8)
    first = tl.plan_at(0.0)
    at = 15.0  # flying leg 1 (a pure translation), accelerating
    assert first.pose_jet(at)[0][2, 0] > 0.1
    assert tl.live([0.5, 1.0, 0.2], at) == at
    old = first.all_xi(at)
    np.testing.assert_allclose(tl.all_xi(at)[:, :9], old[:, :9], rtol=0, atol=1e-9)
    np.testing.assert_allclose(tl.all_xi(at - 1e-10)[:, :9], tl.all_xi(at)[:, :9], rtol=0,
                               atol=1e-9)
    np.testing.assert_array_equal(tl.all_xi(at - 0.5), first.all_xi(at - 0.5))


def test_a_new_command_replaces_the_last_at_its_time_and_order_is_kept():
    tl = timeline_for(COURSE8)
    tl.live([1.0, 0.0, 0.0], 20.0)
    a = tl.plan_at(20.0)
    assert tl.live([0.0, 1.5, 0.0], 20.6) == 20.6
    b = tl.plan_at(20.6)
    assert b is not a and tl.plan_at(20.59) is a
    np.testing.assert_allclose(tl.all_xi(20.6)[:, :9], a.all_xi(20.6)[:, :9], atol=1e-12)
    # a command in the middle of the brake starts from the braking state
    t_brake = 0.5 * (b.segment_s[2] + b.rest_s)
    assert tl.live([0.0, 0.0, 0.5], t_brake) == t_brake
    np.testing.assert_allclose(tl.all_xi(t_brake)[:, :9], b.all_xi(t_brake)[:, :9],
                               atol=1e-12)
    plans = tl.plans
    with pytest.raises(MissionError, match="in order"):
        tl.live([1.0, 0.0, 0.0], t_brake - 0.1)
    assert tl.plans == plans
    c = tl.plan_at(t_brake)
    assert tl.live([0.2, 0.0, 0.0], t_brake) == t_brake  # the same time: replaces it
    assert tl.plan_at(t_brake) is not c and len(tl.plans) == len(plans)


def test_on_a_leg_that_turns_it_starts_at_the_leg_s_arrival():
    tl = timeline_for(COURSE8)
    first = tl.plan_at(0.0)
    at = 0.5 * (first.departure_s[1] + first.arrival_s[2])  # leg 2 turns by 90 deg
    start = tl.live([-0.5, 0.0, 0.0], at)
    assert start == pytest.approx(first.arrival_s[2])
    np.testing.assert_array_equal(tl.all_xi(start - 0.01), first.all_xi(start - 0.01))
    plan = tl.plan_at(start)
    assert plan.start_pose.yaw_rad == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(tl.all_xi(start)[:, :9], first.all_xi(start)[:, :9], atol=1e-12)
    assert plan.at_rest_from(start) == start  # a start from rest is a rest
    np.testing.assert_allclose(plan.pose_jet(start + 3.0)[2], [math.pi / 2, 0, 0, 0])


def test_bad_velocities_are_refused_in_one_line_and_change_nothing():
    tl = timeline_for(COURSE8)
    plans = tl.plans
    bad = {
        "finite": [float("nan"), 0.0, 0.0],
        "3 finite": [1.0, 2.0],
        "numbers": ["a", "b", "c"],
        "faster": [2.5, 2.5, 0.0],
        "floor": [0.0, 0.0, -3.0],  # 4 m centroid, agents 2 m lower, floor 0.8 m
    }
    for word, vel in bad.items():
        with pytest.raises(MissionError, match=word) as err:
            tl.live(vel, 5.0)
        assert "\n" not in str(err.value)
        assert tl.plans == plans and tl.last_at_s == -np.inf
    tl.live([0.0, 0.0, -0.3], 5.0)  # a slow descent stays above it


def test_a_go_to_or_hold_after_live_waits_for_the_final_rest():
    tl = timeline_for(COURSE8)
    tl.live([0.8, 0.4, 0.0], 5.0)
    live = tl.plan_at(5.0)
    go = parse_mission({"speed_mps": 1.5, "max_speed_mps": 3.0,
                        "waypoint": [{"centroid": [2.0, 8.0, 4.0]}]})
    start = tl.fly(go, 5.5)
    assert start == live.rest_s
    np.testing.assert_allclose(tl.all_xi(start + 1e-9), live.all_xi(start), atol=1e-8)
    np.testing.assert_allclose(tl.plan_at(start + 60.0).centroid_at(start + 60.0),
                               [2.0, 8.0, 4.0], atol=1e-12)
    tl2 = timeline_for(COURSE8)
    tl2.live([0.8, 0.4, 0.0], 5.0)
    assert tl2.hold(5.2) == live.rest_s
    # a zero velocity is a stop: at rest from the end of its blend, not after the timeout
    tl3 = timeline_for(COURSE8)
    tl3.live([0.8, 0.4, 0.0], 5.0)
    tl3.live([0.0, 0.0, 0.0], 5.3)
    stop = tl3.plan_at(5.3)
    assert stop.rest_s == stop.segment_s[1] == stop.segment_s[2]
    assert tl3.fly(go, 5.4) == stop.rest_s
