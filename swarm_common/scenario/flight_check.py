"""The checks that every plan flown in flight passes, as the one the scenario loaded with.

Entry point: :func:`checked_timeline`, the mission timeline of a scenario whose every new
plan (a go-to, an uploaded mission, a live velocity: :mod:`swarm_common.mission.timeline`)
must also keep the leaders clear of the scenario's obstacles and inside its geofence
(:func:`swarm_common.scenario.world_check.plan_world_problem`). The leaders fly their
reference with no filter, so a ground station's command that would take them into an
obstacle is refused, on the ground station's copy of the timeline and on each leader's,
as the load-time check refuses such a ``[mission]`` (docs/world.md).
"""

from __future__ import annotations

from swarm_common.mission.timeline import MissionTimeline, Plan
from swarm_common.scenario.mission_check import timeline_for
from swarm_common.scenario.spec import Scenario
from swarm_common.scenario.world_check import plan_world_problem


def checked_timeline(sc: Scenario) -> MissionTimeline:
    """A fresh timeline of ``sc``'s mission whose new plans pass the world's checks."""
    timeline = timeline_for(sc)
    if not sc.world.empty:
        def check(plan: Plan, t0: float) -> str | None:
            return plan_world_problem(sc, plan, t0)

        timeline.check = check
    return timeline
