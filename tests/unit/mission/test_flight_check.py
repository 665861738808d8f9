"""Plans sent in flight pass the world's checks (swarm_common.scenario.flight_check): a go-to
or a live velocity that would take a leader into an obstacle is refused, one line naming
the obstacle, on the ground station's and on every leader's copy of the timeline, and
nothing changes; one that stays clear is flown."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gcs.formation.steer import FormationSteer
from gcs.formation.translate import checked
from offboard.agent.leader import LeaderAgent
from swarm_common.mission.config import MissionError
from swarm_common.scenario.model import load_scenario
from swarm_common.world.config import parse_world

ROOT = Path(__file__).resolve().parents[3]
COURSE8 = load_scenario(ROOT / "scenarios" / "course8.toml")
# a tall cylinder across the x axis at x = 30: every leader crossing it hits it
WALL = parse_world({"obstacle": [{"kind": "cylinder", "centre_m": [30.0, 2.0],
                                  "radius_m": 4.0, "z_range_m": [0.0, 12.0]}]},
                   COURSE8.controller.d_safe_m)
SC = dataclasses.replace(COURSE8, world=WALL)
T = 2.0  # course8 holds at its first waypoint (2, 2, 4) until 10 s


def state(steer: FormationSteer) -> tuple[int, float]:
    return len(steer.timeline.plans), steer.timeline.last_at_s


def test_a_goto_through_an_obstacle_is_refused_and_changes_nothing() -> None:
    steer = FormationSteer(SC)
    before = state(steer)
    with pytest.raises(MissionError, match=r"obstacle\[0\] \(cylinder\)"):
        steer.goto(np.array([40.0, 2.0, 4.0]), T)
    assert state(steer) == before
    steer.goto(np.array([2.0, 12.0, 4.0]), T)  # away from the wall: flown
    assert len(steer.timeline.plans) == before[0] + 1


def test_the_same_goto_is_flown_without_the_obstacle() -> None:
    steer = FormationSteer(COURSE8)
    steer.goto(np.array([40.0, 2.0, 4.0]), T)


def test_a_live_velocity_into_the_obstacle_is_refused() -> None:
    steer = FormationSteer(SC)
    steer.goto(np.array([21.0, 2.0, 4.0]), T)  # stop 5 m short of the wall's face
    t = steer.timeline.plan_at(T + 2.0).end_s + 1.0  # at rest there
    steer.live(np.array([0.0, 1.0, 0.0]), t)  # along the wall: flown
    before = state(steer)
    with pytest.raises(MissionError, match="obstacle"):
        steer.live(np.array([2.5, 0.0, 0.0]), t + 0.5)  # into it before it could stop
    assert state(steer) == before


def test_every_leader_checks_what_it_is_sent() -> None:
    """A leader refuses a plan into the obstacle even when a ground station sent it."""
    lead = LeaderAgent(SC, next(a.id for a in SC.agents if a.is_leader))
    table = FormationSteer(COURSE8).one(np.array([40.0, 2.0, 4.0]), 1.0, 0.0)
    before = len(lead._timeline().plans)
    with pytest.raises(MissionError, match="obstacle"):
        lead.fly_mission(checked(table), T)
    assert len(lead._timeline().plans) == before


def test_a_hold_passes_the_world_check() -> None:
    steer = FormationSteer(SC)
    steer.hold(T)
    assert steer.holding
