"""Ground-station commands as the offboard daemon applies them (docs/lifecycle.md): the
collision-avoidance method, injected outages, the coordinated land-all and take-off, and
the scenario's communication outages; and the starts they lead to (the landing plan, the
leaders' real-time trajectory start). A mixin of :class:`offboard.daemon.core.OffboardDaemon`
(it uses the daemon's agent, bus and identity); bad fields are counted and dropped."""

from __future__ import annotations

import dataclasses
import logging
import math

from offboard.agent.factory import FollowerAgent, LeaderAgent
from offboard.agent.landing import landing_plan
from offboard.daemon.mavlink.link import VehicleLink
from offboard.daemon.zenoh.link import SwarmBus
from offboard.safety.filter import parse_method
from swarm_common import wire
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

# s: a take-off command reaching a held daemon at most this long after its at_s joins the
# common plan of t0 = at_s; a later one (the daemon's loop stalled) climbs from its step time
TAKEOFF_LATE_S = 1.0
TAKEOFF_LEAD_S = 60.0  # s, a take-off command's at_s may lie at most this far ahead
# s: a daemon that reaches the land-all time t_L at most this late flies the common landing
# plan of t_L; a later one (its loop stalled) flies that plan's pad, timed from its step
LAND_LATE_S = 1.0


class DaemonCommands:
    """Command handling of one daemon (the attributes below are the daemon's)."""

    id: int
    sc: Scenario
    agent: LeaderAgent | FollowerAgent
    bus: SwarmBus
    land_at: float | None
    extra_outages: list[tuple[float, float]]
    bad_commands: int
    trajectory_started: bool
    link: VehicleLink

    def comm_ok(self, t: float) -> bool:
        for a, b in (*self.sc.outages, *self.extra_outages):
            if a <= t < b:
                return False
        return True

    def _apply_commands(self, t: float) -> None:
        for cmd in self.bus.pop_commands():
            if cmd.kind == "method":
                try:
                    method = parse_method(cmd.method)
                except ValueError as exc:
                    log.warning("agent %d: command ignored: %s", self.id, exc)
                    continue
                self.agent.set_method(method)
                log.info("agent %d: method -> %s", self.id, method)
            elif cmd.kind == "outage" and cmd.duration_s > 0:
                self.extra_outages.append((t, t + cmd.duration_s))
                log.info("agent %d: injected outage %.2f s at t=%.2f", self.id, cmd.duration_s, t)
            elif cmd.kind == "land" and self.land_at is None:
                self._land_command(cmd, t)
            elif cmd.kind == "takeoff":
                self._takeoff_command(cmd, t)

    def _bad_command(self, cmd: wire.Command, why: str) -> None:
        self.bad_commands += 1
        log.warning("agent %d: %s command dropped: %s", self.id, cmd.kind, why)

    def _land_command(self, cmd: wire.Command, t: float) -> None:
        """Coordinated land-all at ``at_s`` (negative: now); ignored while on the pad."""
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

    def _maybe_start_landing(self, t: float) -> None:
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

    def _maybe_start_trajectory(self, t: float) -> None:
        """Real time: hold p_L(0) until flying in OFFBOARD, then start the trajectory at
        the next whole period (both leaders pick the same instant)."""
        assert isinstance(self.agent, LeaderAgent)
        if self.trajectory_started:
            return
        if self.link.armed and self.link.in_offboard:
            period = 1.0 / float(self.sc.leader_trajectory.frequency_hz)
            self.agent.start_time = math.ceil(t / period) * period
            self.trajectory_started = True
            log.info("agent %d: trajectory starts at t = %.2f s", self.id, self.agent.start_time)
        else:
            self.agent.start_time = math.inf
