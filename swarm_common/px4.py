"""PX4 custom modes as MAVLink carries them: one definition for vehicle, daemon and GCS.

PX4 packs its mode into HEARTBEAT ``custom_mode`` as ``main_mode << 16 | sub_mode << 24``
and takes the same numbers in DO_SET_MODE (param2 = main, param3 = sub). The numbers are
pymavlink's ``mavutil.PX4_CUSTOM_MAIN_MODE_*`` / ``PX4_CUSTOM_SUB_MODE_*`` (PX4's
``px4_custom_mode.h``); the few PX4 has and pymavlink lacks are named here.
"""

from __future__ import annotations

import os
import struct

from swarm_common.enums import VehicleMode

# mavutil picks its MAVLink dialect version when first imported: every process of the
# project speaks MAVLink 2 (the same setdefault as offboard/daemon/mavlink/link.py).
os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

MAIN_MANUAL: int = mavutil.PX4_CUSTOM_MAIN_MODE_MANUAL
MAIN_ALTCTL: int = mavutil.PX4_CUSTOM_MAIN_MODE_ALTCTL
MAIN_POSCTL: int = mavutil.PX4_CUSTOM_MAIN_MODE_POSCTL
MAIN_AUTO: int = mavutil.PX4_CUSTOM_MAIN_MODE_AUTO
MAIN_ACRO: int = mavutil.PX4_CUSTOM_MAIN_MODE_ACRO
MAIN_OFFBOARD: int = mavutil.PX4_CUSTOM_MAIN_MODE_OFFBOARD
MAIN_STABILIZED: int = mavutil.PX4_CUSTOM_MAIN_MODE_STABILIZED
MAIN_RATTITUDE: int = mavutil.PX4_CUSTOM_MAIN_MODE_RATTITUDE
MAIN_SIMPLE = 9  # PX4_CUSTOM_MAIN_MODE_SIMPLE (not in pymavlink)
MAIN_TERMINATION = 10  # PX4_CUSTOM_MAIN_MODE_TERMINATION (not in pymavlink)

SUB_AUTO_READY: int = mavutil.PX4_CUSTOM_SUB_MODE_AUTO_READY
SUB_AUTO_TAKEOFF: int = mavutil.PX4_CUSTOM_SUB_MODE_AUTO_TAKEOFF
SUB_AUTO_LOITER: int = mavutil.PX4_CUSTOM_SUB_MODE_AUTO_LOITER
SUB_AUTO_MISSION: int = mavutil.PX4_CUSTOM_SUB_MODE_AUTO_MISSION
SUB_AUTO_RTL: int = mavutil.PX4_CUSTOM_SUB_MODE_AUTO_RTL
SUB_AUTO_LAND: int = mavutil.PX4_CUSTOM_SUB_MODE_AUTO_LAND
SUB_AUTO_FOLLOW_TARGET: int = mavutil.PX4_CUSTOM_SUB_MODE_AUTO_FOLLOW_TARGET
SUB_AUTO_PRECLAND = 9  # PX4_CUSTOM_SUB_MODE_AUTO_PRECLAND (not in pymavlink)

MAIN_MODES = {
    MAIN_MANUAL: "MANUAL",
    MAIN_ALTCTL: "ALTCTL",
    MAIN_POSCTL: "POSCTL",
    MAIN_AUTO: "AUTO",
    MAIN_ACRO: "ACRO",
    MAIN_OFFBOARD: "OFFBOARD",
    MAIN_STABILIZED: "STABILIZED",
    MAIN_RATTITUDE: "RATTITUDE",
    MAIN_SIMPLE: "SIMPLE",
    MAIN_TERMINATION: "TERMINATION",
}
AUTO_SUB_MODES = {
    SUB_AUTO_READY: "READY",
    SUB_AUTO_TAKEOFF: "TAKEOFF",
    SUB_AUTO_LOITER: "LOITER",
    SUB_AUTO_MISSION: "MISSION",
    SUB_AUTO_RTL: "RTL",
    SUB_AUTO_LAND: "LAND",
    SUB_AUTO_FOLLOW_TARGET: "FOLLOW",
    SUB_AUTO_PRECLAND: "PRECLAND",
}

FORCE_MAGIC = 21196  # COMPONENT_ARM_DISARM param2: force (PX4; no MAVLink enum)


def custom_mode(main: int, sub: int = 0) -> int:
    """``main_mode << 16 | sub_mode << 24``."""
    return (main & 0xFF) << 16 | (sub & 0xFF) << 24


def split_mode(custom: int) -> tuple[int, int]:
    """``custom_mode`` -> (main, sub)."""
    return (custom >> 16) & 0xFF, (custom >> 24) & 0xFF


# The modes vehicle-sim implements, by the short names it reports (Truth, STATUSTEXT)
CUSTOM_MODE: dict[VehicleMode, int] = {
    VehicleMode.POSCTL: custom_mode(MAIN_POSCTL),
    VehicleMode.OFFBOARD: custom_mode(MAIN_OFFBOARD),
    VehicleMode.HOLD: custom_mode(MAIN_AUTO, SUB_AUTO_LOITER),
    VehicleMode.LAND: custom_mode(MAIN_AUTO, SUB_AUTO_LAND),
    VehicleMode.ALTCTL: custom_mode(MAIN_ALTCTL),
    VehicleMode.TAKEOFF: custom_mode(MAIN_AUTO, SUB_AUTO_TAKEOFF),
    VehicleMode.RTL: custom_mode(MAIN_AUTO, SUB_AUTO_RTL),
    VehicleMode.MISSION: custom_mode(MAIN_AUTO, SUB_AUTO_MISSION),
}
_SHORT_NAME = {v: k for k, v in CUSTOM_MODE.items()}


def vehicle_mode(main: int, sub: int = 0) -> VehicleMode | None:
    """The simulator's mode for a PX4 (main, sub) pair; None when it does not implement it
    (OFFBOARD, POSCTL and ALTCTL ignore ``sub``, as PX4 does)."""
    if main in (MAIN_OFFBOARD, MAIN_POSCTL, MAIN_ALTCTL):
        sub = 0
    if not (0 <= main <= 0xFF and 0 <= sub <= 0xFF):
        return None
    return _SHORT_NAME.get(custom_mode(main, sub))


def short_name(custom: int) -> str:
    """Short name of a mode: the simulator's names (HOLD, LAND, ...), else PX4's main
    mode name, else ``MODE<n>``."""
    name = _SHORT_NAME.get(custom)
    if name is not None:
        return str(name)
    main, _ = split_mode(custom)
    return MAIN_MODES.get(main, f"MODE{main}")


def int32_to_wire(value: int) -> float:
    """The float whose four bytes are ``value``'s (PX4's bytewise INT32 encoding of
    PARAM_VALUE / PARAM_SET.param_value)."""
    return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])


def wire_to_int32(value: float) -> int:
    """Inverse of :func:`int32_to_wire`."""
    return int(struct.unpack("<i", struct.pack("<f", value))[0])
