"""PX4 custom modes as MAVLink carries them: one definition for vehicle, daemon and GCS.

PX4 packs its mode into HEARTBEAT ``custom_mode`` as ``main_mode << 16 | sub_mode << 24``
and takes the same numbers in DO_SET_MODE (param2 = main, param3 = sub).
"""

from __future__ import annotations

MAIN_MANUAL = 1
MAIN_ALTCTL = 2
MAIN_POSCTL = 3
MAIN_AUTO = 4
MAIN_OFFBOARD = 6
SUB_AUTO_LOITER = 3
SUB_AUTO_LAND = 6

MAIN_MODES = {
    MAIN_MANUAL: "MANUAL",
    MAIN_ALTCTL: "ALTCTL",
    MAIN_POSCTL: "POSCTL",
    MAIN_AUTO: "AUTO",
    5: "ACRO",
    MAIN_OFFBOARD: "OFFBOARD",
    7: "STABILIZED",
    8: "RATTITUDE",
    9: "TERMINATION",
}
AUTO_SUB_MODES = {
    1: "READY",
    2: "TAKEOFF",
    SUB_AUTO_LOITER: "LOITER",
    4: "MISSION",
    5: "RTL",
    SUB_AUTO_LAND: "LAND",
    8: "FOLLOW",
    9: "PRECLAND",
}

FORCE_MAGIC = 21196  # COMPONENT_ARM_DISARM param2: force (PX4)


def custom_mode(main: int, sub: int = 0) -> int:
    """``main_mode << 16 | sub_mode << 24``."""
    return (main & 0xFF) << 16 | (sub & 0xFF) << 24


def split_mode(custom: int) -> tuple[int, int]:
    """``custom_mode`` -> (main, sub)."""
    return (custom >> 16) & 0xFF, (custom >> 24) & 0xFF


# The modes vehicle-sim implements, by the short names it reports (Truth, STATUSTEXT)
CUSTOM_MODE = {
    "POSCTL": custom_mode(MAIN_POSCTL),
    "OFFBOARD": custom_mode(MAIN_OFFBOARD),
    "HOLD": custom_mode(MAIN_AUTO, SUB_AUTO_LOITER),
    "LAND": custom_mode(MAIN_AUTO, SUB_AUTO_LAND),
}
_SHORT_NAME = {v: k for k, v in CUSTOM_MODE.items()}


def short_name(custom: int) -> str:
    """Short name of a mode: the simulator's names (HOLD, LAND, ...), else PX4's main
    mode name, else ``MODE<n>``."""
    name = _SHORT_NAME.get(custom)
    if name is not None:
        return name
    main, _ = split_mode(custom)
    return MAIN_MODES.get(main, f"MODE{main}")
