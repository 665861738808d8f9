"""Steering the formation from a ground station: the commands that change its mission in
flight, each checked on a replica of the leaders' timeline before it is sent
(docs/missions.md, "Changing a mission in flight").

One implementation for every ground-station side: the formation's MAVLink vehicle
(:mod:`gcs.formation.vehicle`) and the dashboard's navigation menu
(:mod:`gcs.dashboard.navigate`). :class:`FormationSteer` keeps the formation's scale, yaw
and cruise speed as the ground station last set them, and the scenario's mission for
resuming it after a hold.
"""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

import numpy as np

from gcs.formation.translate import checked, mission_table
from swarm_common import wire
from swarm_common.enums import CommandKind
from swarm_common.mission.config import MissionConfig, MissionError, mission_toml
from swarm_common.mission.plan import Pose
from swarm_common.scenario.flight_check import checked_timeline
from swarm_common.scenario.spec import Scenario

COMMAND_LEAD_S = 1.0  # s of mission time between a command and when the leaders apply it


class FormationSteer:
    """The ground station's side of the formation's mission (module docstring). Each method
    takes the swarm's latest mission time ``t`` (s), applies the command to the replica at
    ``t`` + :data:`COMMAND_LEAD_S` and returns the :class:`wire.Command` to publish; a
    command the leaders could not fly raises :class:`MissionError` and changes nothing."""

    def __init__(self, sc: Scenario) -> None:
        if sc.mission is None:
            raise MissionError("steering the formation needs a scenario with a [mission]")
        self.base: MissionConfig = sc.mission
        self.timeline = checked_timeline(sc)
        self.scale = 1.0
        self.yaw_deg = 0.0
        self.speed = self.base.speed_mps
        self.holding = False
        self._flying: MissionConfig | None = self.base  # what a resume flies on with
        self._from = 0.0  # when that mission's plan started (s)

    def at(self, t: float) -> float:
        return float(t) + COMMAND_LEAD_S

    def rest_pose(self, t: float) -> Pose:
        """The formation's pose at its first rest at or after ``t`` + the lead."""
        plan = self.timeline.plan_at(self.at(t))
        return plan.rest_pose(plan.at_rest_from(self.at(t)))

    def fly(self, table: dict[str, Any], t: float) -> wire.Command:
        """Fly a ``[mission]`` table's waypoints (validated) from the next rest."""
        cfg = checked(table)
        start = self.timeline.fly(cfg, self.at(t))
        self._flying, self._from, self.holding = cfg, start, False
        return wire.Command(kind=CommandKind.MISSION, at_s=self.at(t), mission=json.dumps(table))

    def hold(self, t: float) -> wire.Command:
        """Stop at the next rest and stay; :meth:`resume` flies on."""
        self.timeline.hold(self.at(t))
        self.holding = True
        return wire.Command(kind=CommandKind.HOLD, at_s=self.at(t))

    def resume(self, t: float) -> wire.Command:
        """Fly on the waypoints of the mission that a hold stopped, those not reached."""
        if self._flying is None or not self.holding:
            raise MissionError("nothing to resume: the formation is not held")
        plans = self.timeline.plans
        held_from, _ = plans[-1]
        done = plans[-2][1].waypoint_at(held_from) if len(plans) > 1 else 0
        rest = self._flying.waypoints[done:]
        if not rest:
            raise MissionError("nothing to resume: every waypoint was reached")
        return self.fly(mission_toml(replace(self._flying, waypoints=rest)), t)

    def live(self, velocity: np.ndarray, t: float) -> wire.Command:
        """Fly the centroid at ``velocity`` (m/s, ENU) from ``t`` + the lead, on the
        replica first (:meth:`MissionTimeline.live`: it brakes to rest by itself unless a
        newer velocity follows); a live stream ends any mission a hold could resume."""
        at = self.at(t)
        v = np.asarray(velocity, dtype=float)
        self.timeline.live(v, at)
        self._flying, self.holding = None, False
        return wire.Command(kind=CommandKind.LIVE, at_s=at,
                            velocity=(float(v[0]), float(v[1]), float(v[2])))

    def centroid_at_command(self, t: float) -> np.ndarray:
        """The centroid (m, ENU) of the leaders' plan when a command sent at ``t`` applies."""
        at = self.at(t)
        return np.asarray(self.timeline.plan_at(at).centroid_at(at), dtype=float)

    def goto(self, centroid: np.ndarray, t: float, yaw_deg: float | None = None) -> wire.Command:
        """Go to ``centroid`` (m, ENU) at the scale and yaw of the formation's next rest
        (or at ``yaw_deg``); a refused go-to changes nothing."""
        pose = self.rest_pose(t)
        yaw = float(np.degrees(pose.yaw_rad)) if yaw_deg is None else float(yaw_deg)
        cmd = self.fly(self.one(centroid, pose.scale, yaw), t)
        self.scale, self.yaw_deg = pose.scale, yaw
        return cmd

    def nudge(
        self, t: float, d_centroid: tuple[float, float, float] = (0.0, 0.0, 0.0),
        scale_by: float = 1.0, d_yaw_deg: float = 0.0,
    ) -> wire.Command:
        """Move the formation from its next rest: by ``d_centroid`` (m), its scale by the
        factor ``scale_by``, its yaw by ``d_yaw_deg``."""
        pose = self.rest_pose(t)
        scale = pose.scale * scale_by
        yaw = float(np.degrees(pose.yaw_rad)) + d_yaw_deg
        cmd = self.fly(self.one(pose.centroid + np.array(d_centroid), scale, yaw), t)
        self.scale, self.yaw_deg = scale, yaw
        return cmd

    def one(self, centroid: np.ndarray, scale: float, yaw_deg: float) -> dict[str, Any]:
        """A one-waypoint ``[mission]`` table at the present speed and the base limits."""
        return mission_table([{"centroid": [float(x) for x in centroid], "scale": float(scale),
                               "yaw_deg": float(yaw_deg)}], self.speed, self.base)
