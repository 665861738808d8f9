"""COMMAND_LONG to the daemon's vehicle, never blocking: queued, (re)sent on :meth:`tick`,
completed by the vehicle's COMMAND_ACK (MAVLink command protocol; docs/security.md,
"Offboard daemon: link hygiene and failsafes"). The retry bookkeeping of one command is
:class:`offboard.daemon.link_guard.CommandRetry`; :class:`offboard.daemon.mavlink.link.VehicleLink`
owns one :class:`VehicleCommands` and sends its frames."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.link_guard import CommandRetry  # noqa: E402

mavlink = mavutil.mavlink
COMP_AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1


class VehicleCommands:
    """The commands in flight to vehicle (system) ``agent_id``, by command number; each
    frame goes out through ``send`` (the link's packing, sequence and signing)."""

    def __init__(self, agent_id: int, send: Callable[[Any], None]) -> None:
        self.agent_id = agent_id
        self._send = send
        self.pending: dict[int, CommandRetry] = {}

    def __bool__(self) -> bool:
        """True while some command is in flight or uncollected."""
        return bool(self.pending)

    def start(
        self, command: int, params: list[float], attempts: int = 3, timeout_s: float = 1.0
    ) -> None:
        """Queue COMMAND_LONG ``command`` (replacing one of the same number in flight);
        :meth:`tick` sends it, :meth:`finished` collects its outcome."""
        p = [float(x) for x in params] + [math.nan] * (7 - len(params))
        self.pending[command] = CommandRetry(command, p[:7], attempts, timeout_s)
        self.tick()

    def tick(self) -> None:
        """Send every command attempt that is due now."""
        now = time.monotonic()
        for retry in self.pending.values():
            if retry.due(now):
                self._send(mavlink.MAVLink_command_long_message(
                    self.agent_id, COMP_AUTOPILOT, retry.command, retry.attempt, *retry.params
                ))

    def on_ack(self, msg: Any, now: float) -> None:
        """A COMMAND_ACK from the vehicle: completes the command it answers when it is
        addressed to us (or to everyone)."""
        retry = self.pending.get(int(msg.command))
        target = int(getattr(msg, "target_system", 0))
        if retry is not None and target in (0, self.agent_id):
            retry.on_ack(int(msg.result), now, mavlink.MAV_RESULT_IN_PROGRESS)

    def busy(self, command: int) -> bool:
        retry = self.pending.get(command)
        return retry is not None and not retry.done

    def finished(self, command: int) -> tuple[bool, int | None]:
        """(True, MAV_RESULT or None when never acknowledged) once ``command`` is over
        (it is then forgotten); (False, None) while it is in flight or was never sent."""
        retry = self.pending.get(command)
        if retry is None or not retry.done:
            return False, None
        del self.pending[command]
        return True, retry.result

    def set_mode(self, main: int, sub: int = 0) -> int:
        """MAV_CMD_DO_SET_MODE to PX4 custom mode (main, sub); returns the command number."""
        params = [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
                  main, sub]
        self.start(mavlink.MAV_CMD_DO_SET_MODE, params)
        return int(mavlink.MAV_CMD_DO_SET_MODE)

    def arm(self) -> int:
        self.start(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1, 0])  # param1 1 = arm
        return int(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)

    def disarm(self) -> int:
        """A normal (not forced) disarm: the vehicle refuses it unless on the ground."""
        self.start(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [0, 0])
        return int(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)

    def message_interval(self, msg_id: int, interval_s: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL on this link (param2 in µs)."""
        self.start(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, [msg_id, round(interval_s * 1e6)])
        return int(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)
