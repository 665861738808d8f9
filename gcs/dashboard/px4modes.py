"""PX4 custom modes (HEARTBEAT.custom_mode) and the COMMAND_LONG recipes the GCS sends.

PX4 packs its mode in ``custom_mode`` as ``main_mode << 16 | sub_mode << 24``
(:func:`swarm_common.px4.custom_mode`). Mode names come from pymavlink's
``mavutil.PX4_CUSTOM_*`` constants; command and flag numbers from the common dialect.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from swarm_common import px4
from swarm_common.px4 import FORCE_MAGIC, custom_mode

__all__ = [
    "COMMANDS",
    "FORCE_MAGIC",
    "MAV_RESULT_NAMES",
    "CommandSpec",
    "custom_mode",
    "decode_px4_mode",
    "set_mode_spec",
    "short_mode",
]

MAIN_AUTO = px4.MAIN_AUTO
MAIN_OFFBOARD = px4.MAIN_OFFBOARD
SUB_LOITER = px4.SUB_AUTO_LOITER
SUB_LAND = px4.SUB_AUTO_LAND


def _names(prefix: str) -> dict[int, str]:
    """``{value: name}`` of every ``mavutil`` constant starting with ``prefix``."""
    return {
        int(v): k.removeprefix(prefix)
        for k, v in vars(mavutil).items()
        if k.startswith(prefix) and isinstance(v, int)
    }


# PX4 main modes (px4_custom_mode.h); SIMPLE and TERMINATION are absent from pymavlink's list.
MAIN_MODES = _names("PX4_CUSTOM_MAIN_MODE_") | {
    px4.MAIN_SIMPLE: "SIMPLE",
    px4.MAIN_TERMINATION: "TERMINATION",
}
# AUTO sub-modes; PRECLAND is absent from pymavlink's list.
AUTO_SUB_MODES = _names("PX4_CUSTOM_SUB_MODE_AUTO_") | {px4.SUB_AUTO_PRECLAND: "PRECLAND"}

MAV_RESULT_NAMES = {
    k: e.name.removeprefix("MAV_RESULT_")
    for k, e in mavlink.enums["MAV_RESULT"].items()
    if not e.name.endswith("_ENUM_END")
} | {6: "CANCELLED"}  # MAV_RESULT_CANCELLED: newer common.xml than this pymavlink


def decode_px4_mode(custom: int, base_mode: int = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED) -> str:
    """``custom_mode`` -> a PX4 name such as ``OFFBOARD``, ``AUTO.LOITER``, ``AUTO.LAND``."""
    if not base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
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
    return (out[0], out[1], out[2], out[3], out[4], out[5], out[6])


def set_mode_spec(label: str, main: int, sub: int = 0) -> CommandSpec:
    """DO_SET_MODE: param1 = base mode flags, param2 = PX4 main mode, param3 = sub-mode."""
    flags = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    return CommandSpec(label, mavlink.MAV_CMD_DO_SET_MODE, _p(flags, main, sub))


_ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
COMMANDS: dict[str, CommandSpec] = {
    "arm": CommandSpec("arm", _ARM, _p(1)),
    "disarm": CommandSpec("disarm", _ARM, _p(0)),
    "force_disarm": CommandSpec("force disarm", _ARM, _p(0, FORCE_MAGIC)),
    "offboard": set_mode_spec("start formation (OFFBOARD)", MAIN_OFFBOARD),
    "hold": set_mode_spec("hold (AUTO.LOITER)", MAIN_AUTO, SUB_LOITER),
    "land": CommandSpec("land", mavlink.MAV_CMD_NAV_LAND, _p()),
    "terminate": CommandSpec("emergency stop", mavlink.MAV_CMD_DO_FLIGHTTERMINATION, _p(1)),
}
