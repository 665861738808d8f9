"""What the UI's commands go through: MAVLink COMMAND_LONG (with ACK) and Zenoh Command.

:class:`LiveCommander` wraps a :class:`MavlinkGcs` and a :class:`ZenohFeed` (either may
be None); tests pass their own object with the same two methods (and, optionally,
``zenoh_up()`` and ``mission_time()``, used by the coordinated land-all and take-off:
docs/lifecycle.md).
"""

from __future__ import annotations

from typing import Any, Protocol

from swarm_common.wire import Command

from .mavlink_gcs import CommandResult
from .px4modes import COMMANDS


class Commander(Protocol):
    async def mav(self, sysid: int, key: str) -> CommandResult: ...

    def zenoh(self, cmd: Command) -> str: ...


class LiveCommander:
    def __init__(
        self, link: Any = None, feed: Any = None, timeout_s: float = 1.0, retries: int = 2
    ):
        self.link = link
        self.feed = feed
        self.timeout_s = timeout_s
        self.retries = retries

    async def mav(self, sysid: int, key: str) -> CommandResult:
        spec = COMMANDS[key]
        if self.link is None:
            return CommandResult(sysid, spec.command, spec.label, None, 0, 0.0, "NO-MAVLINK")
        return await self.link.command(sysid, spec, timeout_s=self.timeout_s, retries=self.retries)

    def zenoh_up(self) -> bool:
        """A Zenoh feed is started (a land-all then goes out as a Zenoh "land" command, a
        take-off as "takeoff")."""
        return self.feed is not None and bool(self.feed.started)

    def mission_time(self) -> float | None:
        """The swarm's latest reported mission time (s), None without Zenoh or status."""
        return None if self.feed is None else self.feed.mission_time()

    def zenoh(self, cmd: Command) -> str:
        if self.feed is None:
            raise RuntimeError("zenoh is off (started with --no-zenoh?)")
        return self.feed.publish(cmd)
