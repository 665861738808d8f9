"""PX4 custom-mode packing shared by vehicle-sim, the daemons and the GCS."""

from __future__ import annotations

from swarm_common import px4
from swarm_common.enums import VehicleMode


def test_custom_mode_packing_matches_px4() -> None:
    assert px4.custom_mode(px4.MAIN_OFFBOARD) == 6 << 16 == 0x60000
    assert px4.custom_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER) == 0x3040000
    assert px4.split_mode(0x6040000) == (px4.MAIN_AUTO, px4.SUB_AUTO_LAND)


def test_short_names() -> None:
    for name, cm in px4.CUSTOM_MODE.items():
        assert px4.short_name(cm) == name
    assert px4.short_name(px4.custom_mode(px4.MAIN_ALTCTL)) == "ALTCTL"
    assert px4.short_name(px4.custom_mode(px4.MAIN_AUTO, 4)) == "MISSION"
    assert px4.short_name(px4.custom_mode(px4.MAIN_AUTO, 7)) == "AUTO"  # AUTO.FOLLOW
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
