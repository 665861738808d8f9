"""The scenario's geofence preloaded into every simulated vehicle
(vehicle_sim.services.geofence.scenario_fence_items): the simulator's breach check and a
ground station's fence list agree with the offboard filter's fence, horizontally."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT
from pymavlink.dialects.v20 import common as M

from swarm_common.scenario.model import load_scenario
from swarm_common.world.config import parse_world
from swarm_common.world.geometry import fence_margins
from swarm_common.world.mission_current import fence_id_of
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services.geofence import fence_from_items, plan_id, scenario_fence_items
from vehicle_sim.vehicle import Vehicle

BOX = load_scenario(ROOT / "scenarios" / "cube8_obstacles.toml").world
HEXAGON = parse_world({"geofence": {"polygon_m": [[8.0, 2.0], [5.0, 7.2], [-1.0, 7.2],
                                                  [-4.0, 2.0], [-1.0, -3.2], [5.0, -3.2]],
                                    "z_range_m": [0.0, 10.0]}}, 0.5)


@pytest.mark.parametrize("world", [BOX, HEXAGON], ids=["box", "hexagon"])
def test_the_simulators_fence_is_the_filters_horizontally(world) -> None:
    cfg = AutopilotConfig()
    fence = world.geofence
    items = scenario_fence_items(cfg, fence)
    assert all(it.command == M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
               and it.mission_type == M.MAV_MISSION_TYPE_FENCE for it in items)
    zone = fence_from_items(cfg, items)
    planes, _ = world.fence_arrays()
    rng = np.random.default_rng(7)
    lo, hi = np.array(fence.min_m) - 3.0, np.array(fence.max_m) + 3.0
    p = lo + rng.random((4000, 3)) * (hi - lo)
    p[:, 2] = 0.5 * (fence.min_m[2] + fence.max_m[2])  # inside the altitude band
    margin = fence_margins(planes, p)
    clear = np.abs(margin) > 0.02  # the degE7 round trip moves a vertex by about 1 cm
    home = np.zeros(3)
    for q, m in zip(p[clear], margin[clear], strict=True):
        assert (zone.breach(q, home) is None) == (m > 0.0), (q, m)


def test_a_vehicle_lists_the_scenario_fence_and_warns_when_a_client_changes_it() -> None:
    """Preloaded: a download lists the fence's vertices; an upload of another fence is
    taken (the simulator checks it), with a warning, and a new MISSION_CURRENT.fence_id."""
    v = Vehicle(1, 0, SwarmDynamics(load_scenario(ROOT / "scenarios" / "cube8.toml"),
                                    held=True), AutopilotConfig())
    items = scenario_fence_items(v.cfg, HEXAGON.geofence)
    v.mission.preload_fence(items)
    assert v.mission.geofence and len(v.mission.geofence.zones) == 1
    req = M.MAVLink_mission_request_list_message(1, 1, M.MAV_MISSION_TYPE_FENCE)
    req._header.srcSystem, req._header.srcComponent = 255, 190
    v.handle(req, "s", 0.0, 0.0)
    counts = [m for m, _ in v.outbox if m.get_type() == "MISSION_COUNT"]
    assert counts and counts[0].count == 6 and counts[0].mission_type == M.MAV_MISSION_TYPE_FENCE
    v.update(0.0)
    assert not [e for e in v.events if "geofence changed" in e[1]]  # its own fence: quiet
    first = [fence_id_of(m) for m, _ in v.outbox if m.get_type() == "MISSION_CURRENT"]
    assert first and first[-1] == plan_id(items) != 0
    v.outbox.clear()
    v.mission.transfer.stores[M.MAV_MISSION_TYPE_FENCE] = items[:3]  # a client's upload
    v.mission.transfer.changed.append(M.MAV_MISSION_TYPE_FENCE)
    v.update(0.1)
    assert [e for e in v.events if "the offboard filter takes it" in e[1]]
    # MISSION_CURRENT tells every peer at once (not at its next 1 Hz turn): a new fence_id
    now = [fence_id_of(m) for m, _ in v.outbox if m.get_type() == "MISSION_CURRENT"]
    assert now == [plan_id(items[:3])] and now[0] not in (0, first[-1])
    # the truth reports the outline the vehicle now stores, once (the run's verdict)
    news = v.mission.take_fence_news()
    assert news is not None and v.mission.take_fence_news() is None
    assert len(news) == 6  # the hexagon's first three vertices: a triangle
    assert np.allclose(news.reshape(3, 2), HEXAGON.geofence.polygon_m[:3], atol=0.02)
    v.mission.transfer.stores[M.MAV_MISSION_TYPE_FENCE] = items  # the hexagon again
    v.mission.transfer.changed.append(M.MAV_MISSION_TYPE_FENCE)
    v.update(0.2)
    outline = v.mission.take_fence_news()
    assert outline is not None and len(outline) == 12
    assert np.allclose(outline.reshape(6, 2), HEXAGON.geofence.polygon_m, atol=0.02)
