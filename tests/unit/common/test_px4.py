"""PX4 custom-mode packing shared by vehicle-sim, the daemons and the GCS."""

from __future__ import annotations

from pymavlink import mavutil

from gcs.dashboard import px4modes
from swarm_common import px4
from swarm_common.enums import VehicleMode

# PX4's px4_custom_mode.h, written out: enum PX4_CUSTOM_MAIN_MODE and
# enum PX4_CUSTOM_SUB_MODE_AUTO (sub mode 7 was RTGS, now RESERVED_DO_NOT_USE)
PX4_MAIN_MODES = {
    "MANUAL": 1, "ALTCTL": 2, "POSCTL": 3, "AUTO": 4, "ACRO": 5, "OFFBOARD": 6,
    "STABILIZED": 7, "RATTITUDE": 8, "SIMPLE": 9, "TERMINATION": 10,
}  # fmt: skip
PX4_AUTO_SUB_MODES = {
    "READY": 1, "TAKEOFF": 2, "LOITER": 3, "MISSION": 4, "RTL": 5, "LAND": 6,
    "RESERVED_DO_NOT_USE": 7, "FOLLOW_TARGET": 8, "PRECLAND": 9,
}  # fmt: skip
PYMAVLINK_OLD_NAMES = {"RTGS": "RESERVED_DO_NOT_USE"}


def test_custom_mode_packing_matches_px4() -> None:
    assert px4.custom_mode(px4.MAIN_OFFBOARD) == 6 << 16 == 0x60000
    assert px4.custom_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER) == 0x3040000
    assert px4.split_mode(0x6040000) == (px4.MAIN_AUTO, px4.SUB_AUTO_LAND)


def test_short_names() -> None:
    for name, cm in px4.CUSTOM_MODE.items():
        assert px4.short_name(cm) == name
    assert px4.short_name(px4.custom_mode(px4.MAIN_ALTCTL)) == "ALTCTL"
    assert px4.short_name(px4.custom_mode(px4.MAIN_AUTO, 4)) == "MISSION"
    assert px4.short_name(px4.custom_mode(px4.MAIN_AUTO, 7)) == "AUTO"  # AUTO.7: reserved
    assert px4.short_name(px4.custom_mode(px4.MAIN_TERMINATION)) == "TERMINATION"
    assert px4.short_name(px4.custom_mode(42)) == "MODE42"


def test_numbers_are_pymavlinks_px4_modes() -> None:
    from pymavlink import mavutil

    for name, cm in px4.CUSTOM_MODE.items():
        want = "LOITER" if name == "HOLD" else str(name)
        assert mavutil.interpret_px4_mode(0, cm) == want


def test_vehicle_mode_of_main_sub() -> None:
    assert px4.vehicle_mode(px4.MAIN_OFFBOARD, 7) == VehicleMode.OFFBOARD  # sub ignored
    assert px4.vehicle_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LAND) == VehicleMode.LAND
    assert px4.vehicle_mode(px4.MAIN_AUTO, px4.SUB_AUTO_MISSION) == VehicleMode.MISSION
    assert px4.vehicle_mode(px4.MAIN_ALTCTL, 3) == VehicleMode.ALTCTL
    assert px4.vehicle_mode(px4.MAIN_AUTO, px4.SUB_AUTO_FOLLOW_TARGET) is None
    assert px4.vehicle_mode(px4.MAIN_OFFBOARD + 256) is None  # not a uint8: not masked
    assert px4.vehicle_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER + 256) is None


def test_main_mode_numbers_are_px4s() -> None:
    """Every main mode the project names has PX4's number, and it names them all."""
    for name, number in PX4_MAIN_MODES.items():
        assert getattr(px4, f"MAIN_{name}") == number, name
        assert px4.MAIN_MODES[number] == name
        assert px4modes.MAIN_MODES[number] == name
    assert set(px4.MAIN_MODES) == set(PX4_MAIN_MODES.values())
    assert set(px4modes.MAIN_MODES) == set(PX4_MAIN_MODES.values())


def test_auto_sub_mode_numbers_are_px4s() -> None:
    for attr in dir(px4):
        if attr.startswith("SUB_AUTO_"):
            name = attr.removeprefix("SUB_AUTO_")
            assert getattr(px4, attr) == PX4_AUTO_SUB_MODES[name], attr
    named = {v: k for k, v in PX4_AUTO_SUB_MODES.items() if k != "RESERVED_DO_NOT_USE"}
    assert set(px4.AUTO_SUB_MODES) == set(named)
    assert px4modes.AUTO_SUB_MODES[px4.SUB_AUTO_PRECLAND] == "PRECLAND"
    assert px4modes.decode_px4_mode(px4.custom_mode(px4.MAIN_TERMINATION)) == "TERMINATION"
    assert px4modes.decode_px4_mode(px4.custom_mode(px4.MAIN_AUTO, 9)) == "AUTO.PRECLAND"


def test_pymavlink_px4_mode_constants_agree() -> None:
    """pymavlink's PX4_CUSTOM_* constants, where it has them, are PX4's numbers and the
    project's."""
    mains = {k.removeprefix("PX4_CUSTOM_MAIN_MODE_"): v for k, v in vars(mavutil).items()
             if k.startswith("PX4_CUSTOM_MAIN_MODE_")}  # fmt: skip
    subs = {k.removeprefix("PX4_CUSTOM_SUB_MODE_AUTO_"): v for k, v in vars(mavutil).items()
            if k.startswith("PX4_CUSTOM_SUB_MODE_AUTO_")}  # fmt: skip
    assert len(mains) >= 8 and len(subs) >= 6  # the constants are still there
    for name, number in mains.items():
        assert PX4_MAIN_MODES[name] == number, name
        assert getattr(px4, f"MAIN_{name}") == number, name
    for name, number in subs.items():
        name = PYMAVLINK_OLD_NAMES.get(name, name)
        assert PX4_AUTO_SUB_MODES[name] == number, name
        if hasattr(px4, f"SUB_AUTO_{name}"):
            assert getattr(px4, f"SUB_AUTO_{name}") == number, name
