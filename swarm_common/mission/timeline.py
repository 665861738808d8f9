"""A formation mission that changes in flight: the plans the leaders fly, one after the other.

A ground station (the formation's MAVLink vehicle, the dashboard, a script) changes the
mission with a command that takes effect at a run time ``at_s`` that every leader applies
at the same step (docs/missions.md, "Changing a mission in flight"):

* :meth:`MissionTimeline.fly` - fly these waypoints: go-to (one waypoint), a new scale or
  yaw (one waypoint at the present centroid), a whole uploaded mission;
* :meth:`MissionTimeline.hold` - stop and stay: fly no further waypoint.

A command never cuts a leg short. The formation is at rest at every waypoint (the legs are
rest-to-rest), so a new plan starts from the first rest at or after ``at_s`` and from the
pose there: every agent's state stays continuous, and the new plan obeys the same limits and
load-time checks as the first. While the formation flies a leg, a command waits for its end
(PX4 would brake at once; a formation brakes on its planned path at the next waypoint).

Every leader holds its own timeline and applies the same commands, so all compute the same
references. The in-process runner and the daemons drive the same object.
"""

from __future__ import annotations

import bisect
from dataclasses import replace

import numpy as np

from swarm_common.mission.config import MissionConfig, MissionError
from swarm_common.mission.plan import Limits, MissionPlan, Pose, build_plan


class MissionTimeline:
    """The plans in force from their start times (s): :meth:`plan_at` gives the one in force
    at a run time. ``shape`` (N, 3) m and ``limits`` as :func:`build_plan`'s."""

    def __init__(
        self, first: MissionPlan | None, shape: np.ndarray, limits: Limits,
    ) -> None:
        self.shape = np.asarray(shape, dtype=float)
        self.limits = limits
        if first is None:  # no mission yet: hold the scenario's formation from t = 0
            first = _still(self.shape)
        self._starts: list[float] = [-np.inf]
        self._plans: list[MissionPlan] = [first]
        self.last_at_s = -np.inf

    def plan_at(self, t: float) -> MissionPlan:
        """The plan in force at run time ``t`` (s)."""
        return self._plans[bisect.bisect_right(self._starts, t) - 1]

    @property
    def plans(self) -> list[tuple[float, MissionPlan]]:
        """(start time (s), plan) of every plan so far, oldest first."""
        return list(zip(self._starts, self._plans, strict=True))

    def agent_xi(self, t: float, i: int) -> np.ndarray:
        """(12,) agent ``i``'s desired [p, ṗ, p̈, p⃛] at run time ``t`` (s)."""
        return self.plan_at(t).agent_xi(t, i)

    def all_xi(self, t: float) -> np.ndarray:
        """(N, 12) every agent's desired state at ``t`` (s)."""
        return self.plan_at(t).all_xi(t)

    def _switch_time(self, at_s: float) -> tuple[float, Pose]:
        if not np.isfinite(at_s):
            raise MissionError(f"at_s = {at_s!r}: must be finite")
        if at_s < self.last_at_s:
            raise MissionError(f"at_s = {at_s:g} s: before the last command's "
                               f"{self.last_at_s:g} s (commands apply in order)")
        plan = self.plan_at(at_s)
        t = plan.at_rest_from(at_s)
        return t, plan.rest_pose(t)

    def _install(self, t: float, plan: MissionPlan, at_s: float) -> None:
        # a later plan replaces any that would start at or after t (commands apply in order)
        k = bisect.bisect_left(self._starts, t)
        del self._starts[k:], self._plans[k:]
        self._starts.append(t)
        self._plans.append(plan)
        self.last_at_s = at_s

    def fly(self, cfg: MissionConfig, at_s: float) -> float:
        """Fly ``cfg``'s waypoints from the first rest at or after ``at_s`` (s), from the
        pose there (``cfg.start_s`` is ignored); returns that start time. Raises
        :class:`MissionError` (one line, nothing changed) when the mission cannot be built
        from there (a waypoint under the floor, too dense)."""
        t, pose = self._switch_time(at_s)
        plan = build_plan(replace(cfg, start_s=t), self.shape, self.limits, start=pose,
                          start_s=t)
        self._install(t, plan, at_s)
        return t

    def hold(self, at_s: float) -> float:
        """Stop at the first rest at or after ``at_s`` (s) and stay there; returns that time."""
        t, pose = self._switch_time(at_s)
        self._install(t, _still(self.shape, pose), at_s)
        return t


def _still(shape: np.ndarray, pose: Pose | None = None) -> MissionPlan:
    """A plan that holds ``pose`` (default: the shape's own) forever."""
    pts = np.asarray(shape, dtype=float)
    q = pts - pts.mean(axis=0)
    if pose is None:
        pose = Pose(pts.mean(axis=0), 1.0, 0.0)
    return MissionPlan(legs=(), start_pose=pose, shape_offsets=q)
