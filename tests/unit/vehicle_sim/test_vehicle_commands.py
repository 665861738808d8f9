"""VehicleCommands (unit test of one class): COMMAND_LONG frames sent through the link's
send, completed only by an ACK addressed to this system (or to everyone)."""

from __future__ import annotations

from typing import Any

from offboard.daemon.mavlink.commands import VehicleCommands, mavlink

ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM


def _ack(result: int, target: int) -> Any:
    return mavlink.MAVLink_command_ack_message(ARM, result, 0, 0, target, 191)


def test_an_ack_for_another_system_does_not_complete_the_command() -> None:
    sent: list[Any] = []
    cmds = VehicleCommands(4, sent.append)
    assert cmds.arm() == ARM
    (frame,) = sent
    assert (frame.target_system, frame.command, frame.param1, frame.confirmation) == (4, ARM, 1, 0)
    cmds.on_ack(_ack(mavlink.MAV_RESULT_ACCEPTED, 5), 0.1)  # another vehicle's answer
    assert cmds.busy(ARM) and cmds.finished(ARM) == (False, None)
    cmds.on_ack(_ack(mavlink.MAV_RESULT_IN_PROGRESS, 4), 0.1)  # working on it: still open
    assert cmds.busy(ARM)
    cmds.on_ack(_ack(mavlink.MAV_RESULT_ACCEPTED, 0), 0.2)  # broadcast: ours too
    assert not cmds.busy(ARM) and cmds.finished(ARM) == (True, mavlink.MAV_RESULT_ACCEPTED)
    assert not cmds and cmds.finished(ARM) == (False, None)  # forgotten once collected


def test_a_command_never_sent_is_neither_busy_nor_finished() -> None:
    cmds = VehicleCommands(4, lambda msg: None)
    assert not cmds.busy(ARM) and cmds.finished(ARM) == (False, None) and not cmds
