"""The ``[mission]`` table: a good one round-trips, each bad one is one MissionError line
naming the key."""

from __future__ import annotations

import copy
import math
import tomllib
from typing import Any

import pytest

from swarm_common.mission.config import (
    MAX_WAYPOINTS,
    MissionConfig,
    MissionError,
    Waypoint,
    mission_toml,
    parse_mission,
)

GOOD_TOML = """
[mission]
speed_mps = 1.5
start_s = 2.0
max_speed_mps = 5.0
max_accel_mps2 = 1.5
max_jerk_mps3 = 3.0
arrive_radius_m = 0.5
[[mission.waypoint]]
centroid = [0.0, 0.0, 5.0]
scale = 1.0
yaw_deg = 0.0
hold_s = 3.0
[[mission.waypoint]]
centroid = [10, -4.5, 6.0]
scale = 2.5
yaw_deg = -450
hold_s = 0
speed_mps = 2.0
"""


def good() -> dict[str, Any]:
    return copy.deepcopy(tomllib.loads(GOOD_TOML)["mission"])


def refused(table: object) -> str:
    with pytest.raises(MissionError) as info:
        parse_mission(table)
    msg = str(info.value)
    assert "\n" not in msg and msg.strip() == msg and msg
    return msg


def test_a_good_table_parses_to_typed_values():
    cfg = parse_mission(good())
    assert cfg.speed_mps == 1.5 and cfg.start_s == 2.0
    assert cfg.waypoints[0] == Waypoint((0.0, 0.0, 5.0), 1.0, 0.0, 3.0, None)
    assert cfg.waypoints[1] == Waypoint((10.0, -4.5, 6.0), 2.5, -450.0, 0.0, 2.0)
    assert all(isinstance(x, float) for x in cfg.waypoints[1].centroid)


def test_defaults_apply_to_optional_keys():
    cfg = parse_mission({"speed_mps": 1, "waypoint": [{"centroid": [1, 2, 3]}]})
    assert cfg == MissionConfig(waypoints=(Waypoint((1.0, 2.0, 3.0)),), speed_mps=1.0)
    assert (cfg.start_s, cfg.max_speed_mps, cfg.max_accel_mps2) == (0.0, 5.0, 1.5)
    assert (cfg.max_jerk_mps3, cfg.arrive_radius_m) == (3.0, 0.5)
    w = cfg.waypoints[0]
    assert (w.scale, w.yaw_deg, w.hold_s, w.speed_mps) == (1.0, 0.0, 0.0, None)


def test_mission_toml_round_trips():
    cfg = parse_mission(good())
    back = mission_toml(cfg)
    assert parse_mission(back) == cfg
    assert "speed_mps" not in back["waypoint"][0] and back["waypoint"][1]["speed_mps"] == 2.0
    # the dict is plain TOML material: lists, floats, dicts
    assert isinstance(back["waypoint"][1]["centroid"], list)


def test_not_a_table():
    assert "[mission]" in refused([1, 2])
    assert "[mission]" in refused("speed_mps = 1")


def test_unknown_keys_list_the_allowed_ones():
    t = good()
    t["sped_mps"] = 1.0
    msg = refused(t)
    assert "mission.sped_mps" in msg and "allowed: speed_mps" in msg and "waypoint" in msg
    t = good()
    t["waypoint"][1]["yaw"] = 3.0
    msg = refused(t)
    assert "mission.waypoint[1].yaw" in msg and "yaw_deg" in msg and "centroid" in msg


def test_an_unknown_key_with_a_newline_stays_one_line():
    t = good()
    t["a\nb"] = 1.0
    assert "mission." in refused(t)


@pytest.mark.parametrize("key", ["speed_mps", "waypoint"])
def test_missing_required_keys(key):
    t = good()
    del t[key]
    assert f"mission.{key}" in refused(t)


def test_missing_centroid():
    t = good()
    del t["waypoint"][0]["centroid"]
    assert "mission.waypoint[0].centroid" in refused(t)


def test_empty_and_too_many_waypoints():
    t = good()
    t["waypoint"] = []
    assert "mission.waypoint" in refused(t)
    t["waypoint"] = [{"centroid": [0, 0, 1]}] * (MAX_WAYPOINTS + 1)
    msg = refused(t)
    assert "mission.waypoint" in msg and str(MAX_WAYPOINTS + 1) in msg
    t["waypoint"] = [{"centroid": [0, 0, 1]}] * MAX_WAYPOINTS
    assert len(parse_mission(t).waypoints) == MAX_WAYPOINTS


def test_waypoint_must_be_a_list_of_tables():
    t = good()
    t["waypoint"] = {"centroid": [0, 0, 1]}
    assert "mission.waypoint" in refused(t)
    t["waypoint"] = [{"centroid": [0, 0, 1]}, 7]
    assert "mission.waypoint[1]" in refused(t)


BAD_NUMBERS = [math.nan, math.inf, -math.inf, True, False, "1.0", None, [1.0], 10**400]


@pytest.mark.parametrize("value", BAD_NUMBERS, ids=repr)
@pytest.mark.parametrize(
    "key",
    ["speed_mps", "start_s", "max_speed_mps", "max_accel_mps2", "max_jerk_mps3", "arrive_radius_m"],
)
def test_bad_mission_numbers(key, value):
    t = good()
    t[key] = value
    assert f"mission.{key} = " in refused(t)


@pytest.mark.parametrize("value", BAD_NUMBERS, ids=repr)
@pytest.mark.parametrize("key", ["scale", "yaw_deg", "hold_s", "speed_mps"])
def test_bad_waypoint_numbers(key, value):
    t = good()
    t["waypoint"][1][key] = value
    assert f"mission.waypoint[1].{key} = " in refused(t)


def test_the_message_names_key_value_and_range():
    t = good()
    t["waypoint"][3 - 2]["scale"] = math.nan
    assert refused(t) == "mission.waypoint[1].scale = nan: must be a number in (0, 10]"


def test_a_huge_int_is_refused_not_crashed_and_the_line_stays_short():
    t = good()
    t["start_s"] = 10**400
    msg = refused(t)
    assert msg.startswith("mission.start_s = ") and len(msg) < 120


RANGES = [  # key, just outside, just inside (mission keys)
    ("speed_mps", 0.0, 1e-9),
    ("start_s", -1e-9, 0.0),
    ("start_s", 3600.001, 3600.0),
    ("max_speed_mps", 0.0, 15.0),
    ("max_speed_mps", 15.001, 15.0),
    ("max_accel_mps2", 0.0, 20.0),
    ("max_accel_mps2", 20.001, 1e-9),
    ("max_jerk_mps3", -1.0, 100.0),
    ("max_jerk_mps3", 100.001, 100.0),
    ("arrive_radius_m", 0.0, 100.0),
    ("arrive_radius_m", 100.5, 1e-9),
]


@pytest.mark.parametrize(("key", "out", "inside"), RANGES)
def test_mission_ranges(key, out, inside):
    t = good()
    t["max_speed_mps"] = 15.0
    t[key] = out
    assert f"mission.{key} = " in refused(t)
    t[key] = inside
    if key == "max_speed_mps":
        t["speed_mps"] = min(t["speed_mps"], inside)
        for w in t["waypoint"]:
            w.pop("speed_mps", None)
    assert getattr(parse_mission(t), key) == inside


WP_RANGES = [
    ("scale", 0.0, 10.0),
    ("scale", 10.001, 1e-9),
    ("yaw_deg", -720.001, -720.0),
    ("yaw_deg", 720.001, 720.0),
    ("hold_s", -0.001, 0.0),
    ("hold_s", 3600.5, 3600.0),
    ("speed_mps", 0.0, 1e-9),
]


@pytest.mark.parametrize(("key", "out", "inside"), WP_RANGES)
def test_waypoint_ranges(key, out, inside):
    t = good()
    t["waypoint"][0][key] = out
    assert f"mission.waypoint[0].{key} = " in refused(t)
    t["waypoint"][0][key] = inside
    assert getattr(parse_mission(t).waypoints[0], key) == inside


@pytest.mark.parametrize(
    "value",
    [
        [1.0, 2.0],
        [1.0, 2.0, 3.0, 4.0],
        [1.0, math.nan, 3.0],
        [1.0, True, 3.0],
        [0.0, 0.0, 10000.5],
        "1,2,3",
        5.0,
        [0.0, 0.0, 10**400],
    ],
    ids=repr,
)
def test_bad_centroids(value):
    t = good()
    t["waypoint"][1]["centroid"] = value
    msg = refused(t)
    assert msg.startswith("mission.waypoint[1].centroid = ") and "3 numbers" in msg


def test_cruise_speeds_may_not_exceed_max_speed():
    t = good()
    t["speed_mps"] = 5.5
    msg = refused(t)
    assert "mission.speed_mps" in msg and "max_speed_mps" in msg
    t = good()
    t["max_speed_mps"] = 1.8  # the mission's 1.5 fits, waypoint[1]'s 2.0 does not
    msg = refused(t)
    assert "mission.waypoint[1].speed_mps" in msg and "max_speed_mps" in msg
    t["waypoint"][1]["speed_mps"] = 1.8
    assert parse_mission(t).waypoints[1].speed_mps == 1.8
