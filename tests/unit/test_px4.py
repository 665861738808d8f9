"""PX4 custom-mode packing shared by vehicle-sim, the daemons and the GCS."""

from __future__ import annotations

from swarm_common import px4


def test_custom_mode_packing_matches_px4() -> None:
    assert px4.custom_mode(px4.MAIN_OFFBOARD) == 6 << 16 == 0x60000
    assert px4.custom_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER) == 0x3040000
    assert px4.split_mode(0x6040000) == (px4.MAIN_AUTO, px4.SUB_AUTO_LAND)


def test_short_names() -> None:
    for name, cm in px4.CUSTOM_MODE.items():
        assert px4.short_name(cm) == name
    assert px4.short_name(px4.custom_mode(px4.MAIN_ALTCTL)) == "ALTCTL"
    assert px4.short_name(px4.custom_mode(px4.MAIN_AUTO, 4)) == "AUTO"  # AUTO.MISSION
    assert px4.short_name(px4.custom_mode(42)) == "MODE42"
