"""PX4 custom modes (HEARTBEAT.custom_mode) and the COMMAND_LONG recipes the GCS sends.

PX4 packs its mode in ``custom_mode`` as ``main_mode << 16 | sub_mode << 24``.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarm_common import px4
from swarm_common.px4 import AUTO_SUB_MODES, FORCE_MAGIC, MAIN_MODES, custom_mode  # noqa: F401

MAIN_AUTO = px4.MAIN_AUTO
MAIN_OFFBOARD = px4.MAIN_OFFBOARD
SUB_LOITER = px4.SUB_AUTO_LOITER
SUB_LAND = px4.SUB_AUTO_LAND

# MAV_CMD numbers (common.xml) used here.
MAV_CMD_NAV_LAND = 21
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_FLIGHTTERMINATION = 185
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128

MAV_RESULT_NAMES = {
    0: "ACCEPTED",
    1: "TEMPORARILY_REJECTED",
    2: "DENIED",
    3: "UNSUPPORTED",
    4: "FAILED",
    5: "IN_PROGRESS",
    6: "CANCELLED",
}


def decode_px4_mode(custom: int, base_mode: int = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED) -> str:
    """``custom_mode`` -> a PX4 name such as ``OFFBOARD``, ``AUTO.LOITER``, ``AUTO.LAND``."""
    if not base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return f"BASE:{base_mode}"
    main, sub = px4.split_mode(custom)
    name = MAIN_MODES.get(main)
    if name is None:
        return f"MODE:{custom:#x}"
    if main == MAIN_AUTO:
        return f"AUTO.{AUTO_SUB_MODES.get(sub, str(sub))}"
    return name


def short_mode(name: str) -> str:
    """Compact mode label for narrow tables."""
    return {
        "OFFBOARD": "OFFBRD",
        "AUTO.LOITER": "HOLD",
        "AUTO.LAND": "LAND",
        "POSCTL": "POSCTL",
        "TERMINATION": "TERM",
    }.get(name, name[:8])


@dataclass(frozen=True)
class CommandSpec:
    """One MAVLink COMMAND_LONG: number and params 1..7 (NaN-free)."""

    label: str
    command: int
    params: tuple[float, float, float, float, float, float, float]


def _p(*vals: float) -> tuple[float, float, float, float, float, float, float]:
    out = [0.0] * 7
    for k, v in enumerate(vals):
        out[k] = float(v)
    return tuple(out)  # type: ignore[return-value]


def set_mode_spec(label: str, main: int, sub: int = 0) -> CommandSpec:
    return CommandSpec(
        label,
        MAV_CMD_DO_SET_MODE,
        _p(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MAV_MODE_FLAG_SAFETY_ARMED, main, sub),
    )


COMMANDS: dict[str, CommandSpec] = {
    "arm": CommandSpec("arm", MAV_CMD_COMPONENT_ARM_DISARM, _p(1)),
    "disarm": CommandSpec("disarm", MAV_CMD_COMPONENT_ARM_DISARM, _p(0)),
    "force_disarm": CommandSpec("force disarm", MAV_CMD_COMPONENT_ARM_DISARM, _p(0, FORCE_MAGIC)),
    "offboard": set_mode_spec("start formation (OFFBOARD)", MAIN_OFFBOARD),
    "hold": set_mode_spec("hold (AUTO.LOITER)", MAIN_AUTO, SUB_LOITER),
    "land": CommandSpec("land", MAV_CMD_NAV_LAND, _p()),
    "terminate": CommandSpec("emergency stop", MAV_CMD_DO_FLIGHTTERMINATION, _p(1)),
}
