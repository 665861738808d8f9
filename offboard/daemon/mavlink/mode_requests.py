"""The daemon's mode requests to its vehicle: start-up OFFBOARD / arm, OFFBOARD again after
a failsafe (the policy of offboard.daemon.mavlink.offboard_keeper.OffboardKeeper, docs/security.md
"Commands
never block; OFFBOARD after a failsafe"), and the disarm after a loss landing. Every
request is a non-blocking COMMAND_LONG with retries (offboard.daemon.mavlink.link); this module
only decides and collects outcomes, once per main-loop iteration."""

from __future__ import annotations

import logging

from offboard.daemon.mavlink.link import VehicleLink, mavlink
from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper, VehicleView
from swarm_common import px4

log = logging.getLogger(__name__)

MODE_COMMANDS = (("offboard", mavlink.MAV_CMD_DO_SET_MODE),
                 ("arm", mavlink.MAV_CMD_COMPONENT_ARM_DISARM))


class ModeRequests:
    """OFFBOARD / arm requests of agent ``agent_id`` over ``link``, as ``keeper`` decides."""

    def __init__(self, link: VehicleLink, keeper: OffboardKeeper, agent_id: int) -> None:
        self.link = link
        self.keeper = keeper
        self.id = agent_id
        self.disarming = False  # a disarm is in flight (then arm results are not the keeper's)

    def collect(self, now: float) -> None:
        """Hand finished OFFBOARD / arm commands to the keeper, logging each outcome."""
        for what, cmd in MODE_COMMANDS:
            done, res = self.link.commands.finished(cmd)
            if not done:
                continue
            ok = res == mavlink.MAV_RESULT_ACCEPTED
            if what == "arm" and self.disarming:
                self.disarming = False
                (log.info if ok else log.warning)(
                    "agent %d: DISARM %s (result %s)", self.id,
                    "accepted" if ok else "not accepted", res)
                continue
            self.keeper.result(what, ok, now)
            (log.info if ok else log.warning)(
                "agent %d: %s %s (result %s)", self.id, what.upper(),
                "accepted" if ok else "not accepted", res)

    def request(self, now: float, have_answer: bool, streaming_s: float) -> None:
        """Collect outcomes, then ask for what the keeper wants (nothing while a request is
        in flight or before the first setpoint). ``streaming_s``: how long fresh setpoints
        have streamed without a gap (0 when not streaming)."""
        self.collect(now)
        link = self.link
        if not have_answer or any(link.commands.busy(cmd) for _, cmd in MODE_COMMANDS):
            return
        main, sub = px4.split_mode(link.custom_mode)
        view = VehicleView(
            in_offboard=link.in_offboard,
            hold=(main, sub) == (px4.MAIN_AUTO, px4.SUB_AUTO_LOITER),
            armed=link.armed,
            failsafe_texts=link.failsafe_texts,
            streaming_s=streaming_s,
            critical=link.critical,
            reported_offboard=link.offboard_reported,
            offboard_lost_texts=link.offboard_lost_texts,
        )
        want = self.keeper.decide(now, view)
        if want == "offboard":
            link.commands.set_mode(px4.MAIN_OFFBOARD)
        elif want == "arm":
            link.commands.arm()

    def disarm(self) -> None:
        """A normal (not forced) disarm: the vehicle refuses it unless on the ground."""
        if not self.link.commands.busy(mavlink.MAV_CMD_COMPONENT_ARM_DISARM):
            self.disarming = True
            self.link.commands.disarm()


class SwarmReady:
    """The arming policy (docs/px4/offboard-component.md, "Arming policy"): the daemon
    runs no control step, so streams no setpoint and never asks for OFFBOARD or arm,
    until its swarm is ready, i.e. every other agent of the scenario has published an
    estimate (its initial one is sent as soon as its daemon has its vehicle's heartbeat).
    Ready is latched: a neighbour lost later is handled by the agent's prediction, not
    here. ``solo`` (``--solo``): ready at once. While waiting it says so every
    ``say_every`` s, naming the agents not heard from."""

    def __init__(self, agent_id: int, others: list[int], solo: bool, say_every: float) -> None:
        self.id = agent_id
        self.others = list(others)
        self.ready = solo or not self.others
        self.say_every = say_every
        self.since: float | None = None
        self.said = 0.0
        if solo:
            log.info("agent %d: --solo: flying without waiting for its swarm", agent_id)

    def check(self, heard: set[int], now: float) -> bool:
        """True once every other agent is in ``heard`` (then always)."""
        if self.ready:
            return True
        missing = [j for j in self.others if j not in heard]
        if not missing:
            self.ready = True
            log.info("agent %d: swarm ready (all %d agents heard from): arming allowed",
                     self.id, len(self.others) + 1)
            return True
        if self.since is None:
            self.since = now
        if now - self.said >= self.say_every:
            self.said = now
            log.info("agent %d: waiting for its swarm, not arming: %d of %d agents heard "
                     "from, missing %s (%.0f s; --solo flies alone)", self.id,
                     len(self.others) - len(missing) + 1, len(self.others) + 1,
                     missing, now - self.since)
        return False
