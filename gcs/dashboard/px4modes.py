"""PX4 custom modes (HEARTBEAT.custom_mode) and the COMMAND_LONG recipes the GCS sends.

PX4 packs its mode in ``custom_mode`` as ``main_mode << 16 | sub_mode << 24``.
"""

from __future__ import annotations

from dataclasses import dataclass

MAIN_MODES = {
    1: "MANUAL",
    2: "ALTCTL",
    3: "POSCTL",
    4: "AUTO",
    5: "ACRO",
    6: "OFFBOARD",
    7: "STABILIZED",
    8: "RATTITUDE",
    9: "TERMINATION",
}
AUTO_SUB_MODES = {
    1: "READY",
    2: "TAKEOFF",
    3: "LOITER",
    4: "MISSION",
    5: "RTL",
    6: "LAND",
    8: "FOLLOW",
    9: "PRECLAND",
}

MAIN_AUTO = 4
MAIN_OFFBOARD = 6
SUB_LOITER = 3
SUB_LAND = 6

# MAV_CMD numbers (common.xml) used here.
MAV_CMD_NAV_LAND = 21
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_FLIGHTTERMINATION = 185
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128
FORCE_MAGIC = 21196.0

MAV_RESULT_NAMES = {
    0: "ACCEPTED",
    1: "TEMPORARILY_REJECTED",
    2: "DENIED",
    3: "UNSUPPORTED",
    4: "FAILED",
    5: "IN_PROGRESS",
    6: "CANCELLED",
}


def custom_mode(main: int, sub: int = 0) -> int:
    return (main & 0xFF) << 16 | (sub & 0xFF) << 24


def decode_px4_mode(custom: int, base_mode: int = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED) -> str:
    """``custom_mode`` -> a PX4 name such as ``OFFBOARD``, ``AUTO.LOITER``, ``AUTO.LAND``."""
    if not base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return f"BASE:{base_mode}"
    main = (custom >> 16) & 0xFF
    sub = (custom >> 24) & 0xFF
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
