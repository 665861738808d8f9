"""A follower's detour out of a pocket of obstacles (offboard.agent.detour)."""

from __future__ import annotations

import numpy as np

from offboard.agent.detour import DETOUR_M, DETOUR_S, Detour
from offboard.safety.dcbf.world_rows import WorldPlanes
from swarm_common.world.config import parse_world

BALL = parse_world({"obstacle": [{"kind": "sphere", "centre_m": [0.0, 0.0, 5.0],
                                  "radius_m": 0.5}]}, 0.5)


def test_around_the_ball_then_over_it() -> None:
    det = Detour(WorldPlanes(BALL, 10.0), index=3)
    p = np.array([1.2, 0.0, 5.0])  # 0.7 m from the ball's surface, east of it
    goal = np.array([-3.0, 0.5, 5.0])  # west, behind the ball (slightly north)
    assert det.start(10.0, p, goal)
    step = det.target - p
    n = np.array([1.0, 0.0, 0.0])  # the ball's normal at the agent
    assert abs(np.linalg.norm(step) - DETOUR_M) < 1e-12
    assert abs(step @ n) < 1e-12 and step[2] == 0.0  # along the surface, horizontally
    assert step[1] > 0.0  # the vertex's side of the ball (north)
    xi = np.arange(12.0)
    during = det.reference(10.0 + DETOUR_S - 0.01, xi)
    assert np.array_equal(during[0:3], det.target) and not during[3:].any()  # at rest
    assert det.reference(10.0 + DETOUR_S, xi) is xi  # over: the formation again
    # the next detour climbs
    assert det.start(20.0, p, goal)
    assert np.allclose(det.target - p, [0.0, 0.0, DETOUR_M])


def test_straight_behind_goes_sideways_and_alternates() -> None:
    det = Detour(WorldPlanes(BALL, 10.0), index=0)
    p = np.array([1.2, 0.0, 5.0])
    goal = np.array([-3.0, 0.0, 5.0])  # exactly behind the ball
    det.start(0.0, p, goal)
    first = det.target - p
    assert abs(first[0]) < 1e-12 and abs(abs(first[1]) - DETOUR_M) < 1e-12  # n × e_z
    det.start(10.0, p, goal)  # climbs
    det.start(20.0, p, goal)  # sideways again, the other way
    assert np.allclose(det.target - p, -first)


def test_no_obstacle_in_range_no_detour() -> None:
    det = Detour(WorldPlanes(BALL, 2.0), index=1)
    assert not det.start(0.0, np.array([10.0, 0.0, 5.0]), np.zeros(3))
    assert not det.active(0.0)
