"""cube8_obstacles with its geofence box written as a polygon prism, flown in process
(docs/world.md): the polygon's edge planes are dcbf rows like the box's faces, so the dcbf
filter keeps the fence barrier ≥ 0, for the box's own outline as a 4-vertex polygon and
for a hexagon drawn tighter around the formation's flight."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import ROOT

from gcs.mission.inproc import run_inproc
from swarm_common.scenario.model import load_scenario
from swarm_common.world.config import make_world, parse_world
from swarm_common.world.geometry import fence_distances

OBSTACLES = ROOT / "scenarios" / "cube8_obstacles.toml"
SQUARE = [[-2.0, -2.0], [8.0, -2.0], [8.0, 7.0], [-2.0, 7.0]]  # the box's x/y outline
# tight: the followers' vertices come within about 1 m of its sides (seed 2: 0.89 m, the
# margin plus the 0.39 m a vehicle parks off a surface), nearer than the floor or ceiling
HEXAGON = [[-1.6, 2.0], [-0.3, -1.4], [6.4, -1.4], [7.8, 2.0], [6.5, 5.9], [-0.3, 5.9]]


@pytest.mark.parametrize("polygon", [SQUARE, HEXAGON], ids=["square", "hexagon"])
def test_polygon_fence_kept_by_dcbf(polygon: list[list[float]]) -> None:
    sc = load_scenario(OBSTACLES)
    fence = parse_world({"geofence": {"polygon_m": polygon, "z_range_m": [0.0, 9.5]}},
                        sc.controller.d_safe_m).geofence
    assert fence is not None and len(fence.planes()) == len(polygon) + 2
    sc = dataclasses.replace(sc, world=make_world(sc.world.obstacles, fence))
    run = run_inproc(sc, "dcbf", seed=2, duration=20.0)
    m = run.metrics
    assert m["fence_h_min_m"] >= 0.0 and m["fence_min_margin_m"] >= fence.margin_m
    assert m["obstacle_h_min_m"] >= 0.0 and m["collisions"] == 0
    assert not [e for e in m["safety_alarms"] if e["assumption"] in ("obstacle", "geofence")]
    if polygon is HEXAGON:  # its sides, not the floor or ceiling, are what held a vehicle
        face = fence_distances(fence.planes(), np.asarray(run.series.p)).min(axis=(0, 1))
        assert np.min(face[:-2]) < 1.0 < np.min(face[-2:])
        assert abs(np.min(face[:-2]) - m["fence_min_margin_m"]) < 1e-9
