"""Formation missions: waypoints of a formation pose (centroid, scale, yaw) flown in time.

Entry points: :func:`~swarm_common.mission.config.parse_mission` validates a ``[mission]``
table into a :class:`~swarm_common.mission.config.MissionConfig` (errors:
:class:`~swarm_common.mission.config.MissionError`);
:func:`~swarm_common.mission.plan.build_plan` times it into a
:class:`~swarm_common.mission.plan.MissionPlan` that gives each agent's desired state.

* :mod:`.config` - the ``[mission]`` TOML table: validation, typed view, back to TOML.
* :mod:`.profile` - the septic rest-to-rest profile sigma(tau) and its peak derivatives.
* :mod:`.plan` - leg timing under speed/acceleration/jerk limits; pose and agent jets at t.
* :mod:`.plan_kernel` - the compiled evaluation of a plan: every agent's jet in one call.
* :mod:`.live` - :class:`~swarm_common.mission.live.LivePlan`, the formation flown at a
  streamed centroid velocity (blend, cruise, timeout brake, rest) within the limits.
* :mod:`.timeline` - :class:`~swarm_common.mission.timeline.MissionTimeline`, the plans
  flown one after the other as ground-station commands change the mission in flight.
"""

__all__ = ["config", "live", "plan", "plan_kernel", "profile", "timeline"]
