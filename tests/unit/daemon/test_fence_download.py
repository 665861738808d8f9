"""The daemon's download of its vehicle's fence (offboard.daemon.mavlink.fence_download),
against the simulator's mission protocol (vehicle_sim.services.mission_transfer), every
frame packed and parsed as on the wire."""

from __future__ import annotations

import os
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as M  # noqa: E402

from offboard.daemon.mavlink.fence_download import (  # noqa: E402
    ATTEMPTS,
    RETRY_AFTER_S,
    RETRY_S,
    FenceDownload,
)
from swarm_common.world.config import parse_world  # noqa: E402
from swarm_common.world.mission_current import MissionCurrent, fence_id_of  # noqa: E402
from vehicle_sim.autopilot.config import AutopilotConfig  # noqa: E402
from vehicle_sim.services.geofence import plan_id, scenario_fence_items  # noqa: E402
from vehicle_sim.services.mission_transfer import MissionTransfer  # noqa: E402

AGENT = 4
FENCE = M.MAV_MISSION_TYPE_FENCE
HEX = parse_world({"geofence": {"polygon_m": [[8.0, 2.0], [5.0, 7.2], [-1.0, 7.2], [-4.0, 2.0],
                                              [-1.0, -3.2], [5.0, -3.2]],
                                "z_range_m": [0.0, 10.0]}}, 0.5).geofence


class Wire:
    """The daemon and its vehicle, one MAVLink parser each: a frame goes out packed by its
    sender and comes in parsed by its receiver (source ids and all)."""

    def __init__(self) -> None:
        self.daemon = M.MAVLink(None, AGENT, M.MAV_COMP_ID_ONBOARD_COMPUTER)
        self.vehicle = M.MAVLink(None, AGENT, M.MAV_COMP_ID_AUTOPILOT1)
        self.to_vehicle: list[Any] = []

    def from_daemon(self, msg: Any) -> None:
        self.to_vehicle.append(self.vehicle.parse_buffer(msg.pack(self.daemon))[0])

    def from_vehicle(self, msg: Any) -> Any:
        return self.daemon.parse_buffer(msg.pack(self.vehicle))[0]


def _serve(wire: Wire, store: MissionTransfer, dl: FenceDownload, now: float,
           lose: int = 0) -> int:
    """The vehicle answers every request the daemon sent (the first ``lose`` are lost);
    returns how many requests it saw."""
    seen = 0
    while wire.to_vehicle:
        req = wire.to_vehicle.pop(0)
        seen += 1
        if seen <= lose:
            continue
        kind = req.get_type()
        if kind == "MISSION_REQUEST_LIST":
            outs = store.on_request_list(req, None)
        elif kind == "MISSION_REQUEST_INT":
            outs = store.on_request(req, None, is_int=True)
        else:
            continue  # the daemon's final MISSION_ACK
        for out, _ in outs:
            msg = wire.from_vehicle(out)
            {"MISSION_COUNT": dl.on_count, "MISSION_ITEM_INT": dl.on_item,
             "MISSION_ACK": dl.on_ack}[msg.get_type()](msg, now)
    return seen


def _current(wire: Wire, fence_id: int) -> Any:
    return wire.from_vehicle(MissionCurrent(0, 0xFFFF, 0, 2, fence_id=fence_id))


def test_a_changed_fence_id_downloads_the_fence_once() -> None:
    wire, store = Wire(), MissionTransfer(AutopilotConfig())
    items = scenario_fence_items(AutopilotConfig(), HEX)
    store.stores[FENCE] = items
    dl = FenceDownload(AGENT, wire.from_daemon)
    fid = plan_id(items)
    cur = _current(wire, fid)
    assert fence_id_of(cur) == fid != 0  # read from the frame: pymavlink has no field
    dl.on_current(cur, 0.0)
    assert _serve(wire, store, dl, 0.0) == 1 + len(items) + 1  # list, items, final ACK
    got = dl.take()
    assert isinstance(got, tuple) and got[0] == fid
    assert [(i.seq, i.x, i.y, i.param1) for i in got[1]] == [
        (i.seq, i.x, i.y, i.param1) for i in items]
    assert dl.take() is None and dl.known_id == fid
    dl.on_current(_current(wire, fid), 1.0)  # the same fence: nothing to do
    assert not wire.to_vehicle and not dl.busy
    dl.on_current(_current(wire, 0), 2.0)  # cleared: download again (0 items)
    _serve(wire, store.__class__(AutopilotConfig()), dl, 2.0)
    assert dl.take() == (0, [])


def test_lost_requests_are_sent_again_then_the_download_fails_and_retries_later() -> None:
    wire, store = Wire(), MissionTransfer(AutopilotConfig())
    store.stores[FENCE] = scenario_fence_items(AutopilotConfig(), HEX)
    dl = FenceDownload(AGENT, wire.from_daemon)
    dl.on_current(_current(wire, 7), 0.0)
    _serve(wire, store, dl, 0.0, lose=1)  # the MISSION_REQUEST_LIST is lost
    dl.tick(RETRY_S / 2)
    assert not wire.to_vehicle  # not yet
    dl.tick(RETRY_S)
    assert len(wire.to_vehicle) == 1  # asked again
    wire.to_vehicle.clear()
    t = RETRY_S
    for _ in range(ATTEMPTS):
        t += RETRY_S
        dl.tick(t)
    assert not dl.busy and isinstance(dl.take(), str) and dl.failed == 1
    dl.on_current(_current(wire, 7), t + 0.1)  # too soon after the failure
    assert not dl.busy
    dl.on_current(_current(wire, 7), t + RETRY_AFTER_S)
    _serve(wire, store, dl, t + RETRY_AFTER_S)
    got = dl.take()
    assert isinstance(got, tuple) and len(got[1]) == 6 and dl.completed == 1


def test_frames_for_another_system_or_type_do_not_count() -> None:
    wire = Wire()
    dl = FenceDownload(AGENT, wire.from_daemon)
    dl.on_current(_current(wire, 5), 0.0)
    dl.on_count(wire.from_vehicle(M.MAVLink_mission_count_message(AGENT + 1, 191, 3, FENCE)), 0.0)
    dl.on_count(wire.from_vehicle(M.MAVLink_mission_count_message(AGENT, 191, 3, 0)), 0.0)
    assert dl.count is None
    dl.on_count(wire.from_vehicle(M.MAVLink_mission_count_message(AGENT, 191, 300, FENCE)), 0.0)
    assert not dl.busy and "300" in str(dl.take())  # over the fence's capacity: failed
    dl.on_current(_current(wire, 6), 5.0)
    dl.on_ack(wire.from_vehicle(M.MAVLink_mission_ack_message(
        AGENT, 191, M.MAV_MISSION_INVALID_SEQUENCE, FENCE)), 5.0)
    assert not dl.busy and dl.failed == 2


def test_a_fence_change_during_a_download_restarts_it() -> None:
    wire = Wire()
    dl = FenceDownload(AGENT, wire.from_daemon)
    dl.on_current(_current(wire, 5), 0.0)
    dl.on_count(wire.from_vehicle(M.MAVLink_mission_count_message(AGENT, 191, 3, FENCE)), 0.0)
    wire.to_vehicle.clear()
    dl.on_current(_current(wire, 9), 0.1)
    assert dl.pending_id == 9 and dl.count is None
    assert [m.get_type() for m in wire.to_vehicle] == ["MISSION_REQUEST_LIST"]
