"""Ground-station commands as the offboard daemon applies them (docs/lifecycle.md): the
collision-avoidance method, injected outages, the coordinated land-all and take-off, and
the scenario's communication outages; and the landing they lead to. One handler per
:class:`swarm_common.enums.CommandKind` in a dispatch table; a command of a kind without
one (decoding rejects those, so a local caller's mistake) is counted and logged, and bad
fields are counted and dropped: never a crash."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from collections.abc import Callable, Iterable

import numpy as np

from offboard.agent.factory import FollowerAgent, LeaderAgent
from offboard.agent.landing import landing_plan
from offboard.safety.filter import parse_method
from swarm_common import wire
from swarm_common.enums import CommandKind
from swarm_common.mission.config import parse_mission
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

# s: a take-off command reaching a held daemon at most this long after its at_s joins the
# common plan of t0 = at_s; a later one (the daemon's loop stalled) climbs from its step time
TAKEOFF_LATE_S = 1.0
TAKEOFF_LEAD_S = 60.0  # s, a take-off command's at_s may lie at most this far ahead
# s: a daemon that reaches the land-all time t_L at most this late flies the common landing
# plan of t_L; a later one (its loop stalled) flies that plan's pad, timed from its step
LAND_LATE_S = 1.0


Handler = Callable[[wire.Command, float], None]


class GroundCommands:
    """The ground-station commands of one agent and what they set: the land-all time, the
    injected outages, the counts of dropped commands."""

    def __init__(self, sc: Scenario, agent: LeaderAgent | FollowerAgent, agent_id: int,
                 land_at: float | None = None) -> None:
        self.sc = sc
        self.agent = agent
        self.id = agent_id
        self.land_at = land_at  # mission time (s) of the coordinated land-all, once known
        self.extra_outages: list[tuple[float, float]] = []  # injected [a, b) of mission time
        self.bad_commands = 0  # commands with unusable fields: counted, logged, dropped
        self.unknown_commands = 0  # commands of a kind without a handler: counted, logged
        self.handlers: dict[CommandKind, Handler] = {
            CommandKind.METHOD: self._method_command,
            CommandKind.OUTAGE: self._outage_command,
            CommandKind.LAND: self._land_command,
            CommandKind.TAKEOFF: self._takeoff_command,
            CommandKind.MISSION: self._mission_command,
            CommandKind.HOLD: self._hold_command,
            CommandKind.LIVE: self._live_command,
        }

    def comm_ok(self, t: float) -> bool:
        """False inside a communication outage (the scenario's or an injected one)."""
        for a, b in (*self.sc.outages, *self.extra_outages):
            if a <= t < b:
                return False
        return True

    def apply(self, cmds: Iterable[wire.Command], t: float) -> None:
        """Apply ``cmds`` in order at the step of mission time ``t``."""
        for cmd in cmds:
            try:
                kind = CommandKind(cmd.kind)
            except ValueError:
                kind = None
            handler = None if kind is None else self.handlers.get(kind)
            if handler is None:
                self.unknown_commands += 1
                log.warning("agent %d: command of unknown kind %r dropped", self.id, cmd.kind)
                continue
            handler(cmd, t)

    def _method_command(self, cmd: wire.Command, t: float) -> None:
        """Switch the collision-avoidance method (an unknown name is ignored)."""
        try:
            method = parse_method(cmd.method)
        except ValueError as exc:
            log.warning("agent %d: command ignored: %s", self.id, exc)
            return
        self.agent.set_method(method)
        log.info("agent %d: method -> %s", self.id, method)

    def _outage_command(self, cmd: wire.Command, t: float) -> None:
        """A communication outage of ``duration_s`` from now (none: ignored)."""
        if cmd.duration_s > 0:
            self.extra_outages.append((t, t + cmd.duration_s))
            log.info("agent %d: injected outage %.2f s at t=%.2f", self.id, cmd.duration_s, t)

    def _bad_command(self, cmd: wire.Command, why: str) -> None:
        self.bad_commands += 1
        log.warning("agent %d: %s command dropped: %s", self.id, cmd.kind, why)

    def _land_command(self, cmd: wire.Command, t: float) -> None:
        """Coordinated land-all at ``at_s`` (negative: now); ignored while on the pad and
        once a land-all time is set."""
        if self.land_at is not None:
            return
        if not math.isfinite(cmd.at_s):
            self._bad_command(cmd, f"at_s = {cmd.at_s!r}")
        elif not self.agent.takeoff_held:
            self.land_at = cmd.at_s if cmd.at_s >= 0.0 else t
            log.info("agent %d: land-all at t=%.2f s", self.id, self.land_at)

    def _takeoff_command(self, cmd: wire.Command, t: float) -> None:
        """Coordinated take-off with the climbs at ``at_s`` (negative: now) if held on the
        pad; ``at_s`` finite and at most TAKEOFF_LEAD_S ahead of t, else dropped. A copy
        that finds nothing held (started already, an airborne start) changes nothing. One
        that arrives more than TAKEOFF_LATE_S after ``at_s`` (this daemon's loop stalled
        while the others started) does not jump into the plan: this agent climbs the same
        layered plan from t instead (docs/lifecycle.md)."""
        if not math.isfinite(cmd.at_s) or cmd.at_s - t > TAKEOFF_LEAD_S:
            self._bad_command(cmd, f"at_s = {cmd.at_s!r} at t = {t:.2f} s")
            return
        if not self.agent.takeoff_held:
            return
        t0 = cmd.at_s if cmd.at_s >= 0.0 else t
        if t - t0 > TAKEOFF_LATE_S:
            log.warning("agent %d: take-off for t=%.2f s arrived late, at t=%.2f s: climbing "
                        "from now", self.id, t0, t)
            t0 = t
        if self.agent.start_takeoff(t0):
            log.info("agent %d: take-off at t=%.2f s", self.id, t0)

    def _formation_at(self, cmd: wire.Command, t: float) -> float | None:
        """The mission time of a formation command (negative ``at_s``: now), or None
        (counted, logged) when it is not finite or more than TAKEOFF_LEAD_S ahead."""
        if not math.isfinite(cmd.at_s) or cmd.at_s - t > TAKEOFF_LEAD_S:
            self._bad_command(cmd, f"at_s = {cmd.at_s!r} at t = {t:.2f} s")
            return None
        return cmd.at_s if cmd.at_s >= 0.0 else t

    def _mission_command(self, cmd: wire.Command, t: float) -> None:
        """The leaders fly the command's formation waypoints from the first rest at or after
        ``at_s`` (docs/missions.md); followers have nothing to change (they read the
        formation from the leaders). A table that does not parse or cannot be flown from
        there is counted, logged and dropped: the formation flies on as before."""
        at = self._formation_at(cmd, t)
        if at is None or not isinstance(self.agent, LeaderAgent):
            return
        try:
            cfg = parse_mission(json.loads(cmd.mission))
            start = self.agent.fly_mission(cfg, at)
        except (ValueError, RecursionError) as exc:  # MissionError, JSON errors
            self._bad_command(cmd, str(exc).splitlines()[0][:300])
            return
        log.info("agent %d: mission of %d waypoints from t=%.2f s", self.id,
                 len(cfg.waypoints), start)

    def _hold_command(self, cmd: wire.Command, t: float) -> None:
        """The formation stops at its next rest at or after ``at_s`` and stays there."""
        at = self._formation_at(cmd, t)
        if at is None or not isinstance(self.agent, LeaderAgent):
            return
        try:
            start = self.agent.hold_formation(at)
        except ValueError as exc:
            self._bad_command(cmd, str(exc).splitlines()[0][:300])
            return
        log.info("agent %d: formation holds from t=%.2f s", self.id, start)

    def _live_command(self, cmd: wire.Command, t: float) -> None:
        """The formation's centroid flies at ``velocity`` (m/s, ENU) from ``at_s``, then
        brakes to rest unless a newer live command follows (docs/missions.md, "Flying the
        formation live"). A velocity the leaders could not fly is counted and dropped."""
        at = self._formation_at(cmd, t)
        if at is None or not isinstance(self.agent, LeaderAgent):
            return
        try:
            start = self.agent.fly_live(np.asarray(cmd.velocity, dtype=float), at)
        except ValueError as exc:  # MissionError
            self._bad_command(cmd, str(exc).splitlines()[0][:300])
            return
        log.debug("agent %d: live velocity %s from t=%.2f s", self.id, cmd.velocity, start)

    def maybe_start_landing(self, t: float) -> None:
        """From the first step at or after ``land_at``: the common plan of offboard.agent.landing,
        computed for t_L = ``land_at`` (the same on every agent, no communication). A step
        more than LAND_LATE_S after t_L (this daemon's loop stalled across it) keeps the
        plan's pads and flies its timing from t, from the reference it holds now, instead
        of jumping into the plan, whose reference may by then be metres lower
        (docs/lifecycle.md)."""
        if self.land_at is not None and t >= self.land_at and self.agent.landing is None:
            plan = landing_plan(self.sc, self.land_at)
            if t - self.land_at > LAND_LATE_S:
                log.warning("agent %d: land-all of t=%.2f s started late, at t=%.2f s: the "
                            "same pad, timed from now", self.id, self.land_at, t)
                plan = dataclasses.replace(plan, t_land=t)
            self.agent.start_landing(plan)
            log.info("agent %d: landing at t=%.2f s (transit %.2f s)", self.id, t, plan.t_h)
