"""A formation mission that changes in flight: the plans the leaders fly, one after the other.

A ground station (the formation's MAVLink vehicle, the dashboard, a script) changes the
mission with a command that takes effect at a run time ``at_s`` that every leader applies
at the same step (docs/missions.md, "Changing a mission in flight"):

* :meth:`MissionTimeline.fly` - fly these waypoints: go-to (one waypoint), a new scale or
  yaw (one waypoint at the present centroid), a whole uploaded mission;
* :meth:`MissionTimeline.hold` - stop and stay: fly no further waypoint;
* :meth:`MissionTimeline.live` - follow a streamed centroid velocity
  (:mod:`swarm_common.mission.live`): from ``at_s`` itself when the formation is at rest,
  flies live or only translates, else from the end of the leg that scales or turns.

A command never cuts a leg short. The formation is at rest at every waypoint (the legs are
rest-to-rest), so a new plan starts from the first rest at or after ``at_s`` and from the
pose there: every agent's state stays continuous, and the new plan obeys the same limits and
load-time checks as the first. While the formation flies a leg, a command waits for its end
(PX4 would brake at once; a formation brakes on its planned path at the next waypoint).
After a live stream the next rest is the live plan's final one (after its timeout brake):
a go-to or hold waits for the formation to stop by itself (or for a zero velocity's stop).

Every leader holds its own timeline and applies the same commands, so all compute the same
references. The in-process runner and the daemons drive the same object.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from swarm_common.mission.config import MissionConfig, MissionError
from swarm_common.mission.live import LivePlan, live_plan
from swarm_common.mission.plan import Limits, MissionPlan, Pose, build_plan

Plan = MissionPlan | LivePlan  # what a timeline holds: read alike (the same methods)
STILL = 1e-12  # a leg whose scale and yaw change less than this only translates


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
        self._plans: list[Plan] = [first]
        self.last_at_s = -np.inf
        self.revision = 0  # counts the plans installed: a cached ξ of another is stale
        # what else a new plan must pass before it is installed (the scenario's world:
        # swarm_common.scenario.flight_check): one line of what it breaks, or None
        self.check: Callable[[Plan, float], str | None] | None = None

    def plan_at(self, t: float) -> Plan:
        """The plan in force at run time ``t`` (s)."""
        return self._plans[bisect.bisect_right(self._starts, t) - 1]

    @property
    def plans(self) -> list[tuple[float, Plan]]:
        """(start time (s), plan) of every plan so far, oldest first."""
        return list(zip(self._starts, self._plans, strict=True))

    def agent_xi(self, t: float, i: int) -> np.ndarray:
        """(12,) agent ``i``'s desired [p, ṗ, p̈, p⃛] at run time ``t`` (s)."""
        return self.plan_at(t).agent_xi(t, i)

    def all_xi(self, t: float) -> np.ndarray:
        """(N, 12) every agent's desired state at ``t`` (s)."""
        return self.plan_at(t).all_xi(t)

    def _check_at(self, at_s: float) -> None:
        if not np.isfinite(at_s):
            raise MissionError(f"at_s = {at_s!r}: must be finite")
        if at_s < self.last_at_s:
            raise MissionError(f"at_s = {at_s:g} s: before the last command's "
                               f"{self.last_at_s:g} s (commands apply in order)")

    def _switch_time(self, at_s: float) -> tuple[float, Pose]:
        self._check_at(at_s)
        plan = self.plan_at(at_s)
        t = plan.at_rest_from(at_s)
        return t, plan.rest_pose(t)

    def _install(self, t: float, plan: Plan, at_s: float) -> None:
        problem = None if self.check is None else self.check(plan, t)
        if problem is not None:
            raise MissionError(problem)
        # a later plan replaces any that would start at or after t (commands apply in order)
        k = bisect.bisect_left(self._starts, t)
        del self._starts[k:], self._plans[k:]
        self._starts.append(t)
        self._plans.append(plan)
        self.last_at_s = at_s
        self.revision += 1

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

    def live(self, velocity: object, at_s: float) -> float:
        """Fly the centroid at ``velocity`` ((3,) m/s ENU) from ``at_s`` (s) for
        :data:`~swarm_common.mission.live.LIVE_TIMEOUT_S`, then brake to rest
        (:func:`~swarm_common.mission.live.live_plan`); returns the start time: ``at_s``
        when the plan in force there is live, at rest or on a leg that only translates (from
        its centroid's position, velocity and acceleration there: continuous), else that
        leg's arrival (from rest). Raises :class:`MissionError` (one line, nothing changed)
        on a bad or too fast velocity, or one that takes an agent under the floor."""
        self._check_at(at_s)
        plan = self.plan_at(at_s)
        t = plan.at_rest_from(at_s)
        if t == at_s or isinstance(plan, LivePlan) or _translating(plan, at_s):
            t = at_s
            c, s, y = plan.pose_jet(at_s)
            c0, v0, a0, scale, yaw = c[0], c[1], c[2], float(s[0]), float(y[0])
        else:
            pose = plan.rest_pose(t)
            c0, v0, a0 = pose.centroid, np.zeros(3), np.zeros(3)
            scale, yaw = pose.scale, pose.yaw_rad
        q = self.shape - self.shape.mean(axis=0)
        new = live_plan(t, c0, v0, a0, scale, yaw, velocity, q, self.limits)
        self._install(t, new, at_s)
        return t


def _translating(plan: MissionPlan, t: float) -> bool:
    """True when ``plan`` flies, at ``t`` (s), a leg whose scale and yaw do not change."""
    for leg in plan.legs:
        if leg.t0 <= t < leg.arrival_s:
            return (abs(leg.end.scale - leg.start.scale) <= STILL
                    and abs(leg.end.yaw_rad - leg.start.yaw_rad) <= STILL)
    return False


def _still(shape: np.ndarray, pose: Pose | None = None) -> MissionPlan:
    """A plan that holds ``pose`` (default: the shape's own) forever."""
    pts = np.asarray(shape, dtype=float)
    q = pts - pts.mean(axis=0)
    if pose is None:
        pose = Pose(pts.mean(axis=0), 1.0, 0.0)
    return MissionPlan(legs=(), start_pose=pose, shape_offsets=q)
