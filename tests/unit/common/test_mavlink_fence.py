"""A fence as a vehicle stores it, read back for the filter (swarm_common.world.mavlink_fence):
the simulator's encoding inverted, what the filter cannot represent told apart from what is
not a fence at all, and every field from the socket checked."""

from __future__ import annotations

import math

import pytest
from conftest import ROOT
from pymavlink.dialects.v20 import common as M

from swarm_common.scenario.model import load_scenario
from swarm_common.world.config import MAX_FENCE_VERTICES, parse_world
from swarm_common.world.mavlink_fence import (
    OPEN_BAND_M,
    FenceItem,
    filter_fence,
    horizontal_vertices,
    read_fence,
    same_outline,
)
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics.geo import latlon_e7
from vehicle_sim.services.geofence import scenario_fence_items

BOX = load_scenario(ROOT / "scenarios" / "cube8_obstacles.toml").world.geofence
HEXAGON = parse_world({"geofence": {"polygon_m": [[8.0, 2.0], [5.0, 7.2], [-1.0, 7.2],
                                                  [-4.0, 2.0], [-1.0, -3.2], [5.0, -3.2]],
                                    "z_range_m": [0.0, 10.0], "margin_m": 0.4}}, 0.5).geofence
CFG = AutopilotConfig()
POLY_IN = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION


def _items(fence) -> list[FenceItem]:
    """The simulator's FENCE items of ``fence`` as the daemon downloads them."""
    return [FenceItem(it.seq, it.frame, it.command, it.param1, it.x, it.y)
            for it in scenario_fence_items(CFG, fence)]


def _polygon(xy, command: int = POLY_IN, first: int = 0) -> list[FenceItem]:
    out = []
    for k, (x, y) in enumerate(xy):
        lat, lon = latlon_e7(CFG, [y, x, 0.0])  # NED offset
        out.append(FenceItem(first + k, M.MAV_FRAME_GLOBAL_INT, command, float(len(xy)), lat,
                             lon))
    return out


@pytest.mark.parametrize("fence", [BOX, HEXAGON], ids=["box", "hexagon"])
def test_the_simulators_encoding_reads_back_to_a_centimetre(fence) -> None:
    read = read_fence(_items(fence))
    assert read.kind == "polygon"
    for (x, y), (x0, y0) in zip(read.xy, horizontal_vertices(fence), strict=True):
        assert math.hypot(x - x0, y - y0) < 0.02
    assert same_outline(read.xy, fence)
    # the first vertex elsewhere and the other winding are the same outline
    assert same_outline(read.xy[2:] + read.xy[:2], fence)
    assert same_outline(read.xy[::-1], fence)
    assert not same_outline(read.xy, None)


def test_a_smaller_polygon_keeps_the_filters_band_and_margin() -> None:
    xy = ((0.0, -1.0), (7.0, -1.0), (7.5, 3.0), (3.5, 6.0), (0.0, 5.0))
    read = read_fence(_polygon(xy))
    assert read.kind == "polygon" and not same_outline(read.xy, HEXAGON)
    fence = filter_fence(read.xy, HEXAGON, 0.5)
    assert not isinstance(fence, str)
    assert fence.z_range_m == HEXAGON.z_range_m and fence.margin_m == HEXAGON.margin_m
    assert len(fence.planes()) == len(xy) + 2  # one per side, floor, ceiling
    open_fence = filter_fence(read.xy, None, 0.5)  # no scenario fence: no altitude limit
    assert not isinstance(open_fence, str)
    assert open_fence.z_range_m == OPEN_BAND_M and open_fence.margin_m == 0.5


def test_what_the_filter_cannot_represent_is_unsupported_not_bad() -> None:
    square = ((0.0, 0.0), (6.0, 0.0), (6.0, 6.0), (0.0, 6.0))
    dart = ((0.0, 0.0), (6.0, 3.0), (0.0, 6.0), (2.0, 3.0))  # not convex
    read = read_fence(_polygon(dart))
    assert read.kind == "polygon"
    why = filter_fence(read.xy, HEXAGON, 0.5)
    assert isinstance(why, str) and "not convex" in why
    hole = _polygon(((2.0, 2.0), (3.0, 2.0), (3.0, 3.0)),
                    M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, first=4)
    assert read_fence(_polygon(square) + hole).kind == "unsupported"
    lat, lon = latlon_e7(CFG, [1.0, 1.0, 0.0])
    circle = FenceItem(4, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 30.0, lat,
                       lon)
    assert "inclusion circle" in read_fence([*_polygon(square), circle]).reason
    two = _polygon(square) + _polygon(((10.0, 0.0), (12.0, 0.0), (11.0, 2.0)), first=4)
    assert read_fence(two).kind == "unsupported"
    n = MAX_FENCE_VERTICES + 1
    many = [(10.0 * math.cos(2 * math.pi * k / n), 10.0 * math.sin(2 * math.pi * k / n))
            for k in range(n)]
    assert read_fence(_polygon(many)).kind == "unsupported"
    ret = FenceItem(0, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_FENCE_RETURN_POINT, 0.0, lat, lon)
    assert read_fence([]).kind == "none" and read_fence([ret]).kind == "none"


def _with(items: list[FenceItem], k: int, **change) -> list[FenceItem]:
    out = list(items)
    fields = out[k].__dict__ | change
    out[k] = FenceItem(**fields)
    return out


@pytest.mark.parametrize("change", [
    {"param1": math.nan}, {"param1": 3.5}, {"param1": 2.0}, {"param1": 1e9},
    {"x": 91 * 10**7}, {"y": -181 * 10**7},
    {"x": latlon_e7(CFG, [20_000.0, 0.0, 0.0])[0]},  # 20 km north of the origin
    {"seq": 7}, {"command": 16}, {"frame": M.MAV_FRAME_BODY_FRD},
], ids=["nan-count", "fraction", "two", "huge", "lat", "lon", "far", "seq", "command", "frame"])
def test_a_bad_field_is_bad(change) -> None:
    items = _with(_items(HEXAGON), 2, **change)
    assert read_fence(items).kind == "bad"


def test_a_short_polygon_and_too_many_items_are_bad() -> None:
    items = _items(HEXAGON)
    assert read_fence(items[:5]).kind == "bad"  # param1 says 6
    assert "items" in read_fence(items * 50).reason  # 300 > 256
