"""Pilot test: the scenario's obstacles and geofence in the formation views (recorded state).

The snapshot tests (test_snapshots.py) cover a scenario without a world: drawn as before.
"""

from __future__ import annotations

import argparse

import pytest
from conftest import ROOT

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.cli import build, configure_parser
from gcs.dashboard.view.recorded import recorded_source
from gcs.dashboard.view.world_cells import world_cells
from gcs.dashboard.widgets import FormationView
from swarm_common.scenario.model import load_scenario
from swarm_common.world.config import Geofence, Obstacle, ObstacleKind, make_world

pytestmark = pytest.mark.asyncio

# around the recorded cube8 formation (x 2..6, y 0..4, z 2..6 m)
SPHERE = Obstacle(ObstacleKind.SPHERE, (3.0, 2.0, 4.0), 0.5, radius_m=0.4)
BOX = Obstacle(ObstacleKind.BOX, (4.5, 2.0, 4.0), 0.5, size_m=(0.6, 1.0, 0.6), yaw_deg=30.0)
# a fence wider than the formation: the views zoom out to show its corners
WORLD = make_world((SPHERE, BOX), Geofence((-1.0, -2.0, 0.0), (9.0, 6.0, 9.0), 0.5))
FENCE_GLYPHS = "┄┆·"


def grid(view: FormationView) -> list[str]:
    lines = view.render().plain.split("\n")
    assert len(lines) == view.content_size.height
    assert {len(line) for line in lines} == {view.content_size.width}
    return lines


def cells_showing(lines: list[str], chars: str) -> set[tuple[int, int]]:
    return {(c, r) for r, line in enumerate(lines) for c, ch in enumerate(line) if ch in chars}


async def test_obstacles_and_fence_are_drawn_under_the_formation():
    app = DashboardApp(recorded_source(), world=WORLD)
    async with app.run_test(size=(160, 48)) as pilot:
        await pilot.pause()
        for view_id, plane in (("#top", "xy"), ("#side-view", "xz")):
            view = app.query_one(view_id, FormationView)
            fit = view._fit()
            assert fit is not None
            wc = world_cells(WORLD, plane, fit)
            lines = grid(view)
            shaded = cells_showing(lines, "░")
            sphere, box = wc.obstacles
            # every shaded cell is an obstacle's, and each obstacle shows most of its cells
            # (the cube's edges, vertices and the vehicles are drawn over some)
            assert shaded <= sphere | box
            assert len(shaded & sphere) >= 0.7 * len(sphere) > 0, plane
            assert len(shaded & box) >= 0.7 * len(box) > 0, plane
            # the fence: its four corners are in view, its outline drawn where nothing is over it
            corners = wc.fence_h & wc.fence_v
            assert len(corners) == 4
            assert {lines[r][c] for c, r in corners} == {"·"}
            fence_shown = cells_showing(lines, "┄┆")
            assert fence_shown <= wc.fence_h | wc.fence_v
            assert len(fence_shown) >= 0.9 * len(wc.fence_h | wc.fence_v) - 4
            # and the vehicles are on top: from above, every id of the recorded swarm shows
            if plane == "xy":
                assert set("12345678") <= set("".join(lines))


async def test_no_world_draws_no_obstacle_or_fence():
    app = DashboardApp(recorded_source())
    async with app.run_test(size=(160, 48)) as pilot:
        await pilot.pause()
        for view in app.query(FormationView):
            text = "".join(grid(view))
            assert "░" not in text and "┄" not in text and "┆" not in text
            assert view.world is None


async def test_the_cli_hands_the_scenarios_world_to_the_app(port_offset):
    """``gcs dashboard --scenario`` (attached, MAVLink only): the app gets the world."""
    path = str(ROOT / "scenarios" / "cube8_obstacles.toml")
    args = configure_parser(argparse.ArgumentParser()).parse_args(
        ["--scenario", path, "--port-offset", str(port_offset), "--no-zenoh"])
    app, source, _, _ = build(args)
    try:
        assert app.world == load_scenario(path).world
        assert len(app.world.obstacles) == 10 and app.world.geofence is not None
    finally:
        source.close()
