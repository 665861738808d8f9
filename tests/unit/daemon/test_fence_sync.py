"""What the daemon's follower filter does with its vehicle's fence (offboard.daemon.fence_sync),
and the swap itself in a dcbf follower (offboard.agent.fence_swap)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from conftest import ROOT
from pymavlink.dialects.v20 import common as M

from offboard.agent.factory import FollowerAgent, make_agent
from offboard.daemon.fence_sync import FenceSync
from offboard.safety.dcbf.filter import DcbfFilter
from swarm_common.enums import AgentAlarm, Method
from swarm_common.scenario.model import load_scenario
from swarm_common.world.config import Geofence
from swarm_common.world.mavlink_fence import FenceItem
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics.geo import latlon_e7
from vehicle_sim.services.geofence import scenario_fence_items

SC = load_scenario(ROOT / "scenarios" / "cube8_obstacles.toml")
BOX = SC.world.geofence
CFG = AutopilotConfig()
PENTAGON = ((0.0, -1.5), (8.0, -1.5), (8.0, 5.9), (4.0, 7.0), (0.0, 5.9))
DART = ((0.0, 0.0), (6.0, 3.0), (0.0, 6.0), (2.0, 3.0))


def _download(xy, command: int = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION):
    items = []
    for k, (x, y) in enumerate(xy):
        lat, lon = latlon_e7(CFG, [y, x, 0.0])
        items.append(FenceItem(k, M.MAV_FRAME_GLOBAL_INT, command, float(len(xy)), lat, lon))
    return 0x1234, items


class Recorder:
    def __init__(self, ok: bool = True) -> None:
        self.ok = ok
        self.fences: list[Geofence] = []

    def __call__(self, fence: Geofence) -> bool:
        self.fences.append(fence)
        return self.ok


def test_the_scenarios_own_fence_changes_nothing(caplog) -> None:
    rec = Recorder()
    sync = FenceSync(3, BOX, 0.5, rec)
    items = [FenceItem(i.seq, i.frame, i.command, i.param1, i.x, i.y)
             for i in scenario_fence_items(CFG, BOX)]
    with caplog.at_level(logging.INFO):
        sync.on_download((1, items))
    assert not rec.fences and sync.fence is BOX and not sync.disagree
    assert sync.summary() == "" and not caplog.records and sync.alarm_bits() == 0


def test_a_smaller_convex_polygon_is_taken_with_the_scenarios_band(caplog) -> None:
    rec = Recorder()
    sync = FenceSync(3, BOX, 0.5, rec)
    with caplog.at_level(logging.WARNING):
        sync.on_download(_download(PENTAGON))
    assert len(rec.fences) == 1 and sync.fence is rec.fences[0] and sync.adopted == 1
    assert sync.fence.z_range_m == BOX.z_range_m and sync.fence.margin_m == BOX.margin_m
    assert np.allclose(sync.fence.polygon_m, PENTAGON, atol=0.02)
    assert "the filter takes the vehicle's fence" in caplog.text
    sync.on_download(_download(PENTAGON))  # downloaded again: the same, nothing to do
    assert len(rec.fences) == 1


@pytest.mark.parametrize("case", ["dart", "exclusion", "empty", "no-filter"])
def test_what_the_filter_cannot_take_is_kept_and_said(case, caplog) -> None:
    rec = Recorder(ok=case != "no-filter")
    sync = FenceSync(3, BOX, 0.5, rec)
    got = {"dart": _download(DART),
           "exclusion": _download(PENTAGON, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION),
           "empty": (0, []), "no-filter": _download(PENTAGON)}[case]
    with caplog.at_level(logging.WARNING):
        sync.on_download(got)
    assert sync.fence is BOX and sync.refused == 1 and sync.adopted == 0 and sync.disagree
    assert "the filter and the simulator disagree" in caplog.text
    assert "disagree" in sync.summary()
    # every step's status carries it, so metrics, verdict and dashboard say it too
    assert sync.alarm_bits() == AgentAlarm.FENCE_MISMATCH
    if case != "no-filter":  # the vehicle back on the filter's fence: the alarm clears
        sync.on_download((5, [FenceItem(i.seq, i.frame, i.command, i.param1, i.x, i.y)
                              for i in scenario_fence_items(CFG, BOX)]))
        assert not sync.disagree and sync.alarm_bits() == 0


def test_a_bad_download_is_counted_and_dropped(caplog) -> None:
    sync = FenceSync(3, BOX, 0.5, Recorder())
    _, items = _download(PENTAGON)
    items[1] = FenceItem(1, items[1].frame, items[1].command, float("nan"), 0, 0)
    with caplog.at_level(logging.WARNING):
        sync.on_download((2, items))
        sync.on_download("no answer after 8 requests")
    assert sync.bad == 2 and sync.fence is BOX and caplog.text.count("dropped") == 2


def test_a_follower_swaps_its_fence_and_keeps_its_obstacles() -> None:
    agent = make_agent(SC, 5, method=Method.DCBF)
    assert isinstance(agent, FollowerAgent)
    world = agent._world
    assert world is not None
    obstacles = world.table.copy()
    dcbf = agent.filters[Method.DCBF]
    assert isinstance(dcbf, DcbfFilter)
    rows_before = len(dcbf.rows_out()[0])
    sync = FenceSync(5, BOX, 0.5, agent.replace_fence)
    sync.on_download(_download(PENTAGON))
    assert sync.adopted == 1 and agent._world is world  # the same planes, read each step
    assert np.array_equal(world.table, obstacles)
    assert np.array_equal(world.fence, sync.fence.planes())
    assert world.capacity == len(obstacles) + len(PENTAGON) + 2
    # one face more than the box: two more rows, which the compiled front reads too
    assert len(dcbf.rows_out()[0]) == rows_before + 2
    assert agent._front is not None and agent._front._rows_out[0] is dcbf.rows_out()[0]
    p = np.array([4.0, 6.6, 5.0])  # inside the box, 0.4 m from the pentagon's roof edge
    m = world.at(p)
    near = world.normals[:m] @ p - world.offsets[:m]
    assert near.min() < 0.0  # the new fence's side is a row: inside its margin


def test_a_follower_of_a_scenario_without_a_fence_takes_one() -> None:
    sc = load_scenario(ROOT / "scenarios" / "cube8.toml")
    agent = make_agent(sc, 5, method=Method.DCBF)
    assert isinstance(agent, FollowerAgent) and agent._world is None
    sync = FenceSync(5, None, sc.controller.d_safe_m, agent.replace_fence)
    sync.on_download(_download(PENTAGON))
    assert sync.adopted == 1 and agent._world is not None and agent.detour is not None
    assert len(agent._world.fence) == len(PENTAGON) + 2
