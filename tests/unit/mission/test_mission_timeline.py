"""A mission changed in flight (swarm_common.mission.timeline): a command waits for the
formation's next rest, every agent's state stays continuous, and a bad command changes
nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_common.mission.config import MissionError, parse_mission
from swarm_common.mission.plan import Limits, build_plan
from swarm_common.mission.timeline import MissionTimeline

SHAPE = np.array([[4.0, 0.0, 6.0], [4.0, 4.0, 6.0], [0.0, 0.0, 2.0], [0.0, 4.0, 2.0],
                  [0.0, 0.0, 6.0], [4.0, 4.0, 2.0]])
LIMITS = Limits(3.0, 1.0, 2.0, 0.5, 0.5)


def cfg(*wps, speed=1.5):
    return parse_mission({"speed_mps": speed, "max_speed_mps": 3.0, "waypoint": list(wps)})


def timeline():
    first = build_plan(cfg({"centroid": [2.0, 2.0, 4.0], "hold_s": 2.0},
                           {"centroid": [12.0, 2.0, 4.0], "hold_s": 1.0},
                           {"centroid": [12.0, 12.0, 4.0]}), SHAPE, LIMITS)
    return MissionTimeline(first, SHAPE, LIMITS)


def continuous(tl, t, h=1e-7):
    before, after = tl.all_xi(t - h), tl.all_xi(t + h)
    np.testing.assert_allclose(before, after, atol=1e-5)


def test_a_goto_mid_leg_waits_for_the_leg_and_flies_on_from_there():
    tl = timeline()
    first = tl.plan_at(0.0)
    mid = 0.5 * (first.departure_s[0] + first.arrival_s[1])  # flying leg 1
    start = tl.fly(cfg({"centroid": [12.0, -6.0, 5.0], "yaw_deg": 45.0}), mid)
    assert start == pytest.approx(first.arrival_s[1])  # at the end of the leg, not before
    np.testing.assert_allclose(tl.all_xi(mid), first.all_xi(mid))  # nothing changed before
    continuous(tl, start)
    new = tl.plan_at(start + 1.0)
    np.testing.assert_allclose(new.centroid_at(new.arrival_s[-1]), [12.0, -6.0, 5.0], atol=1e-12)
    assert new.yaw_jet(new.end_s)[0] == pytest.approx(math.radians(45.0))
    # the old plan's third waypoint is never flown
    assert tl.plan_at(first.arrival_s[2]) is new


def test_a_command_at_rest_starts_at_once_and_hold_stops_at_the_next_rest():
    tl = timeline()
    first = tl.plan_at(0.0)
    t_hold = first.arrival_s[0] + 0.5  # holding at waypoint 0
    assert tl.hold(t_hold) == pytest.approx(t_hold)
    late = first.end_s + 5.0
    np.testing.assert_allclose(tl.all_xi(late)[:, :3], first.all_xi(t_hold)[:, :3], atol=1e-12)
    assert np.all(tl.all_xi(late)[:, 3:] == 0.0)
    t2 = tl.fly(cfg({"centroid": [2.0, 2.0, 6.0], "scale": 1.3}), late)
    assert t2 == pytest.approx(late)
    continuous(tl, t2)


def test_a_bad_or_late_command_changes_nothing():
    tl = timeline()
    t = tl.plan_at(0.0).arrival_s[0]
    with pytest.raises(MissionError, match="waypoint\\[0\\]"):
        tl.fly(cfg({"centroid": [2.0, 2.0, 0.2]}), t)  # under the floor
    with pytest.raises(MissionError, match="waypoint\\[0\\]"):
        tl.fly(cfg({"centroid": [2.0, 2.0, 4.0], "scale": 0.05}), t)  # too dense
    tl.hold(t + 1.0)
    with pytest.raises(MissionError, match="in order"):
        tl.fly(cfg({"centroid": [2.0, 2.0, 4.0]}), t)
    with pytest.raises(MissionError, match="finite"):
        tl.hold(float("nan"))
    tl2 = timeline()  # the same timeline given only the good command
    tl2.hold(t + 1.0)
    for x in (0.0, 10.0, 30.0):
        np.testing.assert_allclose(tl.all_xi(x), tl2.all_xi(x))
