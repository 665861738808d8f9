"""Commands for the whole swarm from the dashboard: confirmation, take-off, land-all.

* :func:`group_question` - the confirmation a command for more than one vehicle asks
  first: what it does and every target by id (``y`` sends, ``n`` cancels).
* :func:`takeoff_sequence` - ``u``: OFFBOARD, then arm, for every vehicle (each ACK logged);
  once every one ACKed, one Zenoh take-off at the swarm's mission time + TAKEOFF_LEAD_S.
* :func:`mission_time_plus` - a coordinated command's common start time.
* :func:`repeat_command` - a take-off or land-all is published again COMMAND_REPEATS times:
  a Zenoh put is not acknowledged, and it is lost to a daemon whose link is congested (its
  process stalled) or reconnecting; every daemon acts on the first copy and ignores the
  others (the same ``at_s``).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Iterable
from typing import Any, Protocol

from pymavlink.dialects.v20 import common as mavlink

from swarm_common.wire import Command

from .mavlink_gcs import CommandResult

log = logging.getLogger(__name__)

LAND_LEAD_S = 1.0  # s of mission time between the land-all key and the common t_L
TAKEOFF_LEAD_S = 1.0  # s of mission time between the last ACK and the common take-off t0
COMMAND_REPEATS = 20
COMMAND_REPEAT_S = 0.5


class GroupHost(Protocol):
    """What these commands need of the app."""

    commander: Any
    command_repeat_s: float

    def log_event(self, agent: int, kind: str, text: str, severity: int = ...) -> None: ...
    def log_results(self, results: Iterable[CommandResult]) -> None: ...
    def send_zenoh(self, cmd: Command) -> None: ...


def id_list(ids: list[int]) -> str:
    return " ".join(f"#{i}" for i in ids)


def group_question(what: str, ids: list[int]) -> str:
    """The confirmation of a group command: what, and every target by id."""
    return f"{what} -> {len(ids)} vehicles?\n{id_list(ids)}\n(y: send to all of them, n: cancel)"


def mission_time_plus(commander: Any, lead_s: float) -> float:
    """The swarm's latest mission time + ``lead_s`` (-1: now, when none is known)."""
    t_now = getattr(commander, "mission_time", lambda: None)()
    return -1.0 if t_now is None else float(t_now) + lead_s


async def takeoff_sequence(host: GroupHost, ids: list[int]) -> None:
    """OFFBOARD then arm every vehicle; all ACKed: the coordinated take-off."""
    for key in ("offboard", "arm"):
        results = await asyncio.gather(*(host.commander.mav(i, key) for i in ids))
        host.log_results(results)
        failed = [r.sysid for r in results if not r.ok]
        if failed:
            who = ",".join(f"#{i}" for i in failed)
            host.log_event(0, "cmd", f"take-off not sent: {key} refused by {who}",
                           mavlink.MAV_SEVERITY_ERROR)
            return
    at_s = mission_time_plus(host.commander, TAKEOFF_LEAD_S)
    host.send_zenoh(Command(kind="takeoff", agent=0, at_s=at_s))


async def repeat_command(host: GroupHost, cmd: Command) -> None:
    """Publish ``cmd`` again COMMAND_REPEATS times, ``command_repeat_s`` apart, quietly."""
    for _ in range(COMMAND_REPEATS):
        await asyncio.sleep(host.command_repeat_s)
        try:
            host.commander.zenoh(cmd)
        except Exception:  # the link went down: the first copy's outcome stands
            log.debug("re-publishing %s failed", cmd.kind, exc_info=True)
            return
