"""Publishing the dashboard's Zenoh commands (:class:`swarm_common.wire.Command`: method,
outage, land-all, take-off, the formation's steering) through the commander
(:mod:`.commands`), each one logged in the event log; the app then repeats a take-off or
land-all (:func:`.group_commands.repeat_command`).

* :func:`describe` - a command as the event log words it (``method rcbf``, ``land-all at
  t=12.00 s``).
* :func:`publish` - publish one command and log it, or log why it was not sent.
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

from pymavlink.dialects.v20 import common as mavlink

from swarm_common.wire import Command

log = logging.getLogger(__name__)

NOTICE = mavlink.MAV_SEVERITY_NOTICE
WARNING = mavlink.MAV_SEVERITY_WARNING
ERROR = mavlink.MAV_SEVERITY_ERROR


class PublishHost(Protocol):
    """What :func:`publish` needs of the app."""

    commander: Any
    published: list[str]

    def log_event(self, agent: int, kind: str, text: str, severity: int = ...) -> None: ...


def describe(cmd: Command) -> str:
    """What ``cmd`` does, as the event log says it."""
    return {
        "method": f"method {cmd.method}", "outage": f"outage {cmd.duration_s:g} s",
        "land": f"land-all at t={cmd.at_s:.2f} s" if cmd.at_s >= 0 else "land-all now",
        "takeoff": f"take-off at t={cmd.at_s:.2f} s" if cmd.at_s >= 0 else "take-off now",
    }.get(cmd.kind, cmd.kind)


def publish(host: PublishHost, cmd: Command) -> bool:
    """Publish ``cmd`` through ``host.commander`` and log it (its key kept in
    ``host.published``); True when it went out. Without a command link, or when the
    publication fails (logged with its error, the dashboard goes on), False."""
    who = "all" if cmd.agent == 0 else f"#{cmd.agent}"
    what = describe(cmd)
    if host.commander is None:
        host.log_event(0, "cmd", f"{what} ({who}): read-only (no command link)", WARNING)
        return False
    try:
        key = host.commander.zenoh(cmd)
    except Exception as exc:  # RuntimeError, ValueError, zenoh.ZError, ...: logged, go on
        log.warning("publishing %s failed", what, exc_info=True)
        host.log_event(cmd.agent, "cmd", f"{what} ({who}) failed: {exc}", ERROR)
        return False
    host.published.append(key)
    host.log_event(
        cmd.agent,
        cmd.kind if cmd.kind in ("outage", "land", "takeoff") else "method",
        f"{what} ({who}) published",
        NOTICE,
    )
    return True
