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
from swarm_common.world.geodesy import DEFAULT_ORIGIN
from swarm_common.world.mavlink_fence import FenceItem, horizontal_vertices, same_outline
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


def _heard(sync: FenceSync) -> FenceSync:
    """``sync`` once its vehicle's GPS_GLOBAL_ORIGIN (the default origin) was heard."""
    sync.on_origin(DEFAULT_ORIGIN, 0.0)
    return sync


class Recorder:
    def __init__(self, ok: bool = True) -> None:
        self.ok = ok
        self.fences: list[Geofence] = []

    def __call__(self, fence: Geofence) -> bool:
        self.fences.append(fence)
        return self.ok


def test_the_scenarios_own_fence_changes_nothing(caplog) -> None:
    rec = Recorder()
    sync = _heard(FenceSync(3, BOX, 0.5, rec))
    items = [FenceItem(i.seq, i.frame, i.command, i.param1, i.x, i.y)
             for i in scenario_fence_items(CFG, BOX)]
    with caplog.at_level(logging.INFO):
        sync.on_download((1, items))
    assert not rec.fences and sync.fence is BOX and not sync.disagree
    assert sync.summary() == "" and not caplog.records and sync.alarm_bits() == 0


def test_a_smaller_convex_polygon_is_taken_with_the_scenarios_band(caplog) -> None:
    rec = Recorder()
    sync = _heard(FenceSync(3, BOX, 0.5, rec))
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
    sync = _heard(FenceSync(3, BOX, 0.5, rec))
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
    sync = _heard(FenceSync(3, BOX, 0.5, Recorder()))
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
    sync = _heard(FenceSync(5, BOX, 0.5, agent.replace_fence))
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
    sync = _heard(FenceSync(5, None, sc.controller.d_safe_m, agent.replace_fence))
    sync.on_download(_download(PENTAGON))
    assert sync.adopted == 1 and agent._world is not None and agent.detour is not None
    assert len(agent._world.fence) == len(PENTAGON) + 2


# a vehicle whose local frame sits 1.2 km north-east of the default origin
AWAY = AutopilotConfig(home_lat=CFG.home_lat + 0.008, home_lon=CFG.home_lon + 0.011)


def _stored(cfg: AutopilotConfig, fence: Geofence) -> tuple[int, list[FenceItem]]:
    """What the simulator stores for ``fence`` on a vehicle of ``cfg``, as downloaded."""
    return 7, [FenceItem(i.seq, i.frame, i.command, i.param1, i.x, i.y)
               for i in scenario_fence_items(cfg, fence)]


def test_a_download_waits_for_the_origin_and_is_read_about_it(caplog) -> None:
    """The scenario's box stored about another origin: read about the default it would be
    1.2 km off (a fence to take, wrongly); the download waits for GPS_GLOBAL_ORIGIN and,
    read about it, is the filter's own fence."""
    rec = Recorder()
    sync = FenceSync(3, BOX, 0.5, rec)
    with caplog.at_level(logging.INFO):
        sync.on_download(_stored(AWAY, BOX), 10.0)
        sync.on_origin(None, 12.0)  # no origin yet: nothing read
        assert not rec.fences and sync.fence is BOX and not sync.disagree
        origin = (AWAY.home_lat, AWAY.home_lon)
        sync.on_origin(origin, 12.5)
    assert not rec.fences and sync.fence is BOX and not sync.disagree
    assert sync.summary() == "" and sync.alarm_bits() == 0
    assert "local origin is 47.4057420, 8.5565940" in caplog.text  # it says where
    # the same download read about the default origin is another fence: the test can fail
    wrong = _heard(FenceSync(3, BOX, 0.5, Recorder()))
    wrong.on_download(_stored(AWAY, BOX), 10.0)
    assert wrong.adopted == 1 or wrong.disagree


def test_an_origin_that_moves_rereads_the_last_download() -> None:
    rec = Recorder()
    sync = _heard(FenceSync(3, BOX, 0.5, rec))
    sync.on_download(_stored(AWAY, BOX), 1.0)  # read about the default: a shifted box
    assert rec.fences or sync.disagree
    sync.on_origin((AWAY.home_lat, AWAY.home_lon), 2.0)  # the vehicle's origin: the box
    assert sync.fence is not None and not sync.disagree
    assert same_outline(horizontal_vertices(sync.fence), BOX)  # back on the box, to 5 cm
    assert sync.fence.z_range_m == BOX.z_range_m


def test_a_vehicle_without_an_origin_has_its_fence_read_about_the_default(caplog) -> None:
    rec = Recorder()
    sync = FenceSync(3, BOX, 0.5, rec)
    sync.on_download(_download(PENTAGON), 100.0)
    sync.on_origin(None, 104.9)
    assert not rec.fences  # still waiting
    with caplog.at_level(logging.WARNING):
        sync.on_origin(None, 105.0)
    assert len(rec.fences) == 1 and sync.adopted == 1
    assert "sent no GPS_GLOBAL_ORIGIN in 5 s" in caplog.text
