"""Steering the formation from a ground station (gcs.formation.steer) and the dashboard's
navigation menu (gcs.dashboard.navigate): what each choice asks of the leaders, checked on
the replica of their timeline; refusals change nothing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gcs.dashboard.navigate import CHOICES, CLIMB_M, SCALE_STEP, STEP_M, TURN_DEG, command_for
from gcs.formation.steer import COMMAND_LEAD_S, FormationSteer
from swarm_common.mission.config import MissionError
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]


def steer() -> FormationSteer:
    return FormationSteer(load_scenario(ROOT / "scenarios" / "course8.toml"))


def waypoint(cmd) -> dict:
    (wp,) = json.loads(cmd.mission)["waypoint"]
    return wp


@pytest.mark.full
def test_every_menu_choice_moves_the_formation_from_its_next_rest():
    t = 2.0  # course8 holds at its first waypoint (2, 2, 4) until 10 s
    for choice, _ in CHOICES[:10]:
        s = steer()
        cmd = command_for(s, choice, t)
        assert cmd.kind == "mission" and cmd.at_s == pytest.approx(t + COMMAND_LEAD_S)
        wp = waypoint(cmd)
        d = np.array(wp["centroid"]) - [2.0, 2.0, 4.0]
        want = {"north": (0, STEP_M, 0), "south": (0, -STEP_M, 0), "east": (STEP_M, 0, 0),
                "west": (-STEP_M, 0, 0), "up": (0, 0, CLIMB_M), "down": (0, 0, -CLIMB_M)}
        np.testing.assert_allclose(d, want.get(choice, (0, 0, 0)), atol=1e-12)
        scale = {"grow": SCALE_STEP, "shrink": 1 / SCALE_STEP}.get(choice, 1.0)
        assert wp["scale"] == pytest.approx(scale)
        assert wp["yaw_deg"] == pytest.approx({"left": TURN_DEG, "right": -TURN_DEG}
                                              .get(choice, 0.0))
        # the replica flies it: at the end the formation rests there
        plan = s.timeline.plan_at(1e6)
        np.testing.assert_allclose(plan.centroid_at(1e6), wp["centroid"], atol=1e-9)


def test_hold_then_resume_flies_on_with_the_waypoints_not_reached():
    s = steer()
    hold = command_for(s, "hold", 15.0)  # flying leg 1 (10 s to 27.85 s)
    assert hold.kind == "hold" and s.holding
    resume = command_for(s, "resume", 40.0)
    table = json.loads(resume.mission)
    # course8's waypoints 2..5 (0 and 1 were reached before the hold took effect)
    assert [w["centroid"] for w in table["waypoint"]] == [
        [14.0, 14.0, 5.0], [2.0, 14.0, 5.0], [2.0, 2.0, 4.0], [6.0, 6.0, 4.0]]
    assert not s.holding


def test_refused_choices_change_nothing():
    s = steer()
    times = (5.0, 50.0, 90.0)
    before = [s.timeline.all_xi(x) for x in times]
    with pytest.raises(MissionError, match="resume"):
        command_for(s, "resume", 2.0)  # not held
    with pytest.raises(MissionError, match="floor"):
        s.nudge(2.0, d_centroid=(0.0, 0.0, -3.0))  # the lowest layer from 2 m to -1 m
    with pytest.raises(MissionError, match="separation"):
        s.nudge(2.0, scale_by=0.05)
    with pytest.raises(MissionError, match="unknown choice"):
        command_for(s, "barrel-roll", 2.0)
    for x, b in zip(times, before, strict=True):
        np.testing.assert_array_equal(s.timeline.all_xi(x), b)
    assert (s.scale, s.yaw_deg, s.holding) == (1.0, 0.0, False)


def test_steps_add_up_from_each_rest_and_the_floor_stops_them():
    s = steer()
    assert waypoint(command_for(s, "up", 2.0))["centroid"][2] == pytest.approx(5.0)
    assert waypoint(command_for(s, "up", 60.0))["centroid"][2] == pytest.approx(6.0)
    command_for(s, "down", 120.0)
    command_for(s, "down", 180.0)
    command_for(s, "down", 240.0)  # back to 3 m: the lowest layer at 1 m
    with pytest.raises(MissionError, match="floor"):
        command_for(s, "down", 300.0)  # it would be at 0 m


def test_a_goto_without_a_yaw_keeps_the_formations_own_yaw_and_scale():
    """course8 turns to 90° on its way: a go-to at t = 50 s, where it rests turned, keeps
    that yaw and scale instead of turning back to what the ground station last set."""
    s = steer()
    pose = s.rest_pose(50.0)
    assert abs(np.degrees(pose.yaw_rad)) > 45.0  # the course has turned by then
    wp = waypoint(s.goto(np.array([0.0, 0.0, 5.0]), 50.0))
    assert wp["yaw_deg"] == pytest.approx(np.degrees(pose.yaw_rad), abs=1e-9)
    assert wp["scale"] == pytest.approx(pose.scale, abs=1e-12)


def test_a_refused_goto_changes_nothing():
    s = steer()
    before = (s.yaw_deg, s.scale, len(s.timeline.plans))
    with pytest.raises(MissionError):
        s.goto(np.array([0.0, 0.0, -5.0]), 2.0, yaw_deg=45.0)  # under the floor
    assert (s.yaw_deg, s.scale, len(s.timeline.plans)) == before
