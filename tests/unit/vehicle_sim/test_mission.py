"""vehicle_sim mission protocol, AUTO.MISSION executor and geofence (pure pieces)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common.enums import VehicleMode
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.autopilot.nav import NavKind
from vehicle_sim.physics import geo
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services import mission_items as mi
from vehicle_sim.services.geofence import Circle, Geofence, Polygon, fence_from_items
from vehicle_sim.services.mission_executor import MissionExecutor
from vehicle_sim.services.mission_transfer import RETRY_S, TIMEOUT_S, MissionTransfer
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
CFG = SimpleNamespace(home_lat=47.397742, home_lon=8.545594, home_alt=488.0)
GCS = (255, 190)
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
MISSION, FENCE, RALLY = mi.MISSION, mi.FENCE, mi.RALLY


def _from(msg, sysid: int = GCS[0], compid: int = GCS[1], restricted: bool = False):
    msg._header.srcSystem, msg._header.srcComponent = sysid, compid
    msg._restricted = restricted
    return msg


def _latlon_e7(east: float, north: float) -> tuple[int, int]:
    return geo.latlon_e7(CFG, np.array([north, east, 0.0]))


def _item(seq, cmd=M.MAV_CMD_NAV_WAYPOINT, east=0.0, north=0.0, z=5.0, frame=REL, mt=MISSION,
          p1=0.0, p2=0.0, p4=math.nan, xy=None):  # fmt: skip
    x, y = _latlon_e7(east, north) if xy is None else xy
    m = M.MAVLink_mission_item_int_message(
        1, 1, seq, frame, cmd, 0, 1, p1, p2, 0.0, p4, x, y, z, mt
    )
    return _from(m)


def _upload(tr: MissionTransfer, items, mt=MISSION, now=0.0):
    """Drive an upload; returns every reply in order."""
    out = tr.on_count(_from(M.MAVLink_mission_count_message(1, 1, len(items), mt)), "gcs", now)
    for it in items:
        out += tr.on_item(it, "gcs", now, is_int=True)
    return [m for m, _ in out]


def _acks(msgs):
    return [m.type for m in msgs if m.get_type() == "MISSION_ACK"]


# ---------------------------------------------------------------------------------------
# transfer
def test_upload_then_download_round_trips() -> None:
    tr = MissionTransfer(CFG)
    items = [_item(0, M.MAV_CMD_NAV_TAKEOFF, z=8.0), _item(1, east=10.0), _item(2, north=5.0)]
    out = _upload(tr, items)
    reqs = [m.seq for m in out if m.get_type() == "MISSION_REQUEST_INT"]
    assert reqs == [0, 1, 2] and _acks(out) == [M.MAV_MISSION_ACCEPTED]
    assert all(m.target_system == GCS[0] and m.target_component == GCS[1] for m in out)
    assert tr.changed == [MISSION] and len(tr.stores[MISSION]) == 3 and tr.stores[FENCE] == []
    ((cnt, _),) = tr.on_request_list(_from(M.MAVLink_mission_request_list_message(1, 1, 0)), "g")
    assert cnt.count == 3 and cnt.mission_type == MISSION
    for src in items:
        req = _from(M.MAVLink_mission_request_int_message(1, 1, src.seq, MISSION))
        ((got, dest),) = tr.on_request(req, "g", is_int=True)
        assert dest == "g" and got.get_type() == "MISSION_ITEM_INT"
        for f in ("seq", "frame", "command", "x", "y", "z", "param1", "mission_type"):
            assert getattr(got, f) == pytest.approx(getattr(src, f), nan_ok=True), f
    ((flt, _),) = tr.on_request(_from(M.MAVLink_mission_request_message(1, 1, 1, 0)), "g", False)
    assert flt.get_type() == "MISSION_ITEM" and flt.x == pytest.approx(items[1].x / 1e7)
    ((bad, _),) = tr.on_request(_from(M.MAVLink_mission_request_int_message(1, 1, 3, 0)), "g", True)
    assert bad.type == M.MAV_MISSION_INVALID_SEQUENCE


@pytest.mark.parametrize(
    ("item", "result"),
    [
        (_item(0, M.MAV_CMD_NAV_LOITER_TURNS), M.MAV_MISSION_UNSUPPORTED),
        (_item(0, frame=M.MAV_FRAME_BODY_FRD), M.MAV_MISSION_UNSUPPORTED_FRAME),
        (_item(0, p1=-1.0), M.MAV_MISSION_INVALID_PARAM1),
        (_item(0, xy=(0, 0)), M.MAV_MISSION_INVALID_PARAM5_X),  # a waypoint needs a position
        (_item(0, east=50_000.0), M.MAV_MISSION_INVALID_PARAM5_X),  # beyond MAX_DISTANCE_M
        (_item(0, xy=(91 * 10**7, 0)), M.MAV_MISSION_INVALID_PARAM5_X),
        (_item(0, z=math.nan), M.MAV_MISSION_INVALID_PARAM7),
        (_item(0, mt=FENCE), M.MAV_MISSION_ERROR),  # mission type changed mid-upload
    ],
)
def test_bad_item_ends_upload_with_its_error(item, result) -> None:
    tr = MissionTransfer(CFG)
    tr.stores[MISSION] = [mi.item_from_int(_item(0))]
    out = _upload(tr, [item])
    assert _acks(out) == [result]
    assert tr.upload is None and tr.changed == [] and len(tr.stores[MISSION]) == 1
    assert tr.errors


def test_sequence_errors_and_repeats() -> None:
    tr = MissionTransfer(CFG)
    tr.on_count(_from(M.MAVLink_mission_count_message(1, 1, 3, 0)), "g", 0.0)
    assert tr.on_item(_item(0), "g", 0.0, True)[0][0].seq == 1
    assert tr.on_item(_item(0), "g", 0.1, True) == []  # a repeat: ignored
    out = [m for m, _ in tr.on_item(_item(2), "g", 0.2, True)]
    assert _acks(out) == [M.MAV_MISSION_INVALID_SEQUENCE] and tr.upload is None


def test_no_space_zero_count_clear_and_busy() -> None:
    tr = MissionTransfer(CFG)
    big = M.MAVLink_mission_count_message(1, 1, mi.CAPACITY[RALLY] + 1, RALLY)
    assert _acks([m for m, _ in tr.on_count(_from(big), "g", 0.0)]) == [M.MAV_MISSION_NO_SPACE]
    _upload(tr, [_item(0)])
    zero = M.MAVLink_mission_count_message(1, 1, 0, MISSION)
    assert _acks([m for m, _ in tr.on_count(_from(zero), "g", 0.0)]) == [M.MAV_MISSION_ACCEPTED]
    assert tr.stores[MISSION] == []
    _upload(tr, [_item(0)])
    clear = _from(M.MAVLink_mission_clear_all_message(1, 1, M.MAV_MISSION_TYPE_ALL))
    assert _acks([m for m, _ in tr.on_clear_all(clear, "g")]) == [M.MAV_MISSION_ACCEPTED]
    assert tr.stores[MISSION] == []
    # another client's MISSION_COUNT while an upload runs: busy (until it times out)
    tr.on_count(_from(M.MAVLink_mission_count_message(1, 1, 2, 0)), "g", 10.0)
    other = _from(M.MAVLink_mission_count_message(1, 1, 2, 0), sysid=254)
    assert _acks([m for m, _ in tr.on_count(other, "h", 10.1)]) == [M.MAV_MISSION_ERROR]
    assert tr.on_count(other, "h", 10.0 + TIMEOUT_S + 1)[0][0].get_type() == "MISSION_REQUEST_INT"


def test_retry_then_timeout() -> None:
    tr = MissionTransfer(CFG)
    tr.on_count(_from(M.MAVLink_mission_count_message(1, 1, 2, 0)), "g", 0.0)
    assert tr.tick(RETRY_S / 2) == []
    ((again, dest),) = tr.tick(RETRY_S)
    assert again.seq == 0 and dest == "g"
    assert tr.tick(TIMEOUT_S + 0.1) == [] and tr.upload is None and tr.errors


def test_float_items_get_float_requests() -> None:
    tr = MissionTransfer(CFG)
    tr.on_count(_from(M.MAVLink_mission_count_message(1, 1, 2, 0)), "g", 0.0)
    lat, lon = CFG.home_lat + 1e-4, CFG.home_lon
    f0 = _from(M.MAVLink_mission_item_message(1, 1, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
               M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, math.nan, lat, lon, 6.0, 0))  # fmt: skip
    ((req, _),) = tr.on_item(f0, "g", 0.0, is_int=False)
    assert req.get_type() == "MISSION_REQUEST" and req.seq == 1
    assert tr.upload is not None and tr.upload.items[0].x == round(lat * 1e7)


def test_fence_lists_are_checked_whole() -> None:
    tr = MissionTransfer(CFG)
    inc = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    two = [_item(i, inc, east=e, mt=FENCE, p1=3) for i, e in enumerate((0.0, 10.0))]
    assert _acks(_upload(tr, two, FENCE)) == [M.MAV_MISSION_INVALID_PARAM1]  # 2 of 3 vertices
    small = [_item(0, inc, mt=FENCE, p1=2)]
    assert _acks(_upload(tr, small, FENCE)) == [M.MAV_MISSION_INVALID_PARAM1]
    rally = [_item(0, M.MAV_CMD_NAV_RALLY_POINT, east=3.0, mt=RALLY)]
    assert _acks(_upload(tr, rally, RALLY)) == [M.MAV_MISSION_ACCEPTED]
    assert tr.stores[RALLY] and tr.stores[MISSION] == []


# ---------------------------------------------------------------------------------------
# frames
def test_item_frames_to_enu() -> None:
    it = mi.item_from_int(_item(0, east=12.0, north=-7.0, z=9.0))
    assert mi.item_position_enu(CFG, it) == pytest.approx([12.0, -7.0, 9.0], abs=0.02)
    amsl = mi.item_from_int(_item(0, east=1.0, z=CFG.home_alt + 4.0, frame=M.MAV_FRAME_GLOBAL_INT))
    assert mi.item_position_enu(CFG, amsl)[2] == pytest.approx(4.0)
    local = mi.item_from_int(_item(0, frame=M.MAV_FRAME_LOCAL_NED, xy=(30_000, 10_000), z=-2.0))
    assert mi.item_position_enu(CFG, local) == pytest.approx([1.0, 3.0, 2.0])
    assert mi.item_position_enu(CFG, mi.item_from_int(_item(0, xy=(0, 0)))) is None
    assert mi.yaw_enu(90.0) == pytest.approx(0.0, abs=1e-9)  # heading east = ENU yaw 0
    assert mi.yaw_enu(0.0) == pytest.approx(math.pi / 2)


# ---------------------------------------------------------------------------------------
# executor
def _fly(ex: MissionExecutor, p, dt=0.1, t_end=200.0, speed=2.0):
    """A kinematic vehicle that moves at ``speed`` toward each target; returns kinds seen."""
    p = np.array(p, dtype=float)
    kinds, t = [], 0.0
    while t < t_end:
        tgt = ex.nav_target(p, np.zeros(3), t)
        if tgt is None or ex.finished:
            return kinds, p, t
        if not kinds or kinds[-1] != tgt.kind:
            kinds.append(tgt.kind)
        goal = tgt.position_enu.copy()
        if tgt.kind in (NavKind.LAND, NavKind.RTL):
            goal[2] = 0.0
        d = goal - p
        n = float(np.linalg.norm(d))
        p = goal if n <= speed * dt else p + d / n * speed * dt
        t += dt
    raise AssertionError("mission never ended")


def test_executor_flies_takeoff_waypoints_loiter_land() -> None:
    items = [
        _item(0, M.MAV_CMD_NAV_TAKEOFF, xy=(0, 0), z=6.0),
        _item(1, M.MAV_CMD_DO_CHANGE_SPEED, frame=M.MAV_FRAME_MISSION, xy=(0, 0), p2=3.0),
        _item(2, east=10.0, z=6.0, p1=2.0),  # hold 2 s
        _item(3, M.MAV_CMD_NAV_LOITER_TIME, east=10.0, north=10.0, z=6.0, p1=1.0),
        _item(4, M.MAV_CMD_NAV_LAND, xy=(0, 0), z=0.0),
    ]
    ex = MissionExecutor(CFG, [mi.item_from_int(i) for i in items], np.zeros(3), lambda: 1.0)
    kinds, p, t = _fly(ex, [0.0, 0.0, 0.0])
    assert kinds == [NavKind.TAKEOFF, NavKind.GOTO, NavKind.LOITER, NavKind.GOTO,
                     NavKind.LOITER, NavKind.LAND]  # fmt: skip
    assert ex.reached == [0, 1, 2, 3, 4] and ex.finished and ex.speed == 3.0
    assert p[:2] == pytest.approx([10.0, 10.0], abs=1.1) and p[2] == pytest.approx(0.0)
    # takeoff 6 m at 2 m/s, 10 m, hold 2 s, 10 m, hold 1 s, 6 m down: at least ~17 s
    assert t >= 16.0
    after = ex.nav_target(p, np.zeros(3), t + 1.0)  # landed: the LAND target stays
    assert after is not None and after.kind == NavKind.LAND and ex.reached == [0, 1, 2, 3, 4]
    ex.start()  # a finished mission starts again from its first item
    assert ex.current == 0 and not ex.finished


def test_executor_waypoint_radius_and_rtl() -> None:
    rtl = _item(1, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=M.MAV_FRAME_MISSION, xy=(0, 0))
    items = [_item(0, east=20.0, z=5.0, p2=4.0), rtl]
    ex = MissionExecutor(CFG, [mi.item_from_int(i) for i in items], np.array([1, 2, 0]),
                         lambda: 0.5)  # fmt: skip
    tgt = ex.nav_target(np.array([16.5, 0.0, 5.0]), np.zeros(3), 0.0)  # 3.5 m < param2 = 4
    assert tgt is not None and tgt.kind == NavKind.RTL
    assert tgt.position_enu == pytest.approx([1, 2, 0]) and ex.reached == [0]
    assert ex.nav_target(np.array([1.0, 2.0, 3.0]), np.zeros(3), 1.0).kind == NavKind.RTL
    assert ex.nav_target(np.array([1.0, 2.0, 0.0]), np.zeros(3), 2.0) is None
    assert ex.reached == [0]  # no MISSION_ITEM_REACHED for RTL (as PX4)
    assert not ex.set_current(2) and ex.set_current(0) and not ex.finished


def test_executor_takeoff_already_above() -> None:
    ex = MissionExecutor(CFG, [mi.item_from_int(_item(0, M.MAV_CMD_NAV_TAKEOFF, z=3.0)),
                               mi.item_from_int(_item(1, east=5.0, z=8.0))],
                         np.zeros(3), lambda: 1.0)  # fmt: skip
    tgt = ex.nav_target(np.array([0.0, 0.0, 8.0]), np.zeros(3), 0.0)
    assert tgt is not None and tgt.kind == NavKind.GOTO and ex.reached == [0]


# ---------------------------------------------------------------------------------------
# geofence
def test_geofence_zones_and_limits() -> None:
    square = Polygon(np.array([[-10, -10], [10, -10], [10, 10], [-10, 10]], float), True)
    hole = Circle(5.0, 5.0, 2.0, inclusion=False)
    gf = Geofence([square, hole])
    home = np.zeros(3)
    assert gf.breach(np.array([0.0, 0.0, 5.0]), home) is None
    assert "inclusion" in gf.breach(np.array([11.0, 0.0, 5.0]), home)
    assert "exclusion" in gf.breach(np.array([5.5, 5.0, 5.0]), home)
    assert "from home" in Geofence().breach(np.array([30.0, 0, 1]), home, max_hor_m=20.0)
    assert "above home" in Geofence().breach(np.array([0.0, 0, 31]), home, max_ver_m=30.0)
    assert Geofence().breach(np.array([30.0, 0, 31]), home) is None  # limits off at 0
    # two inclusion zones: inside either is inside
    gf2 = Geofence([Circle(0, 0, 3, True), Circle(20, 0, 3, True)])
    assert gf2.breach(np.array([20.0, 1.0, 1.0]), home) is None
    assert gf2.breach(np.array([10.0, 0.0, 1.0]), home) is not None


def test_fence_from_items() -> None:
    inc = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    corners = [(-20.0, -20.0), (20.0, -20.0), (20.0, 20.0), (-20.0, 20.0)]
    items = [_item(i, inc, east=e, north=n, mt=FENCE, p1=4) for i, (e, n) in enumerate(corners)]
    items.append(_item(4, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, east=8.0, mt=FENCE, p1=3.0))
    stored = [mi.item_from_int(i) for i in items]
    assert mi.check_list(stored, FENCE) == M.MAV_MISSION_ACCEPTED
    gf = fence_from_items(CFG, stored)
    assert len(gf.zones) == 2
    assert gf.breach(np.array([0.0, 0.0, 5.0]), np.zeros(3)) is None
    assert gf.breach(np.array([8.0, 1.0, 5.0]), np.zeros(3)) is not None
    assert gf.breach(np.array([0.0, 25.0, 5.0]), np.zeros(3)) is not None


# ---------------------------------------------------------------------------------------
# the service on a vehicle
def _vehicle() -> Vehicle:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    return Vehicle(1, 0, dyn, AutopilotConfig())


def _sent(v: Vehicle, kind: str):
    return [m for m, _ in v.outbox if m.get_type() == kind]


def test_service_restricted_peers_download_only() -> None:
    v = _vehicle()
    svc = v.mission
    assert not svc.has_mission() and svc.start(0.0) == M.MAV_RESULT_DENIED
    count = _from(M.MAVLink_mission_count_message(1, 1, 1, 0), restricted=True)
    v.handle(count, "u", 0.0, 0.0)
    assert [a.type for a in _sent(v, "MISSION_ACK")] == [M.MAV_MISSION_DENIED]
    v.outbox.clear()
    v.handle(_from(M.MAVLink_mission_count_message(1, 1, 1, 0)), "s", 0.0, 0.0)
    v.handle(_item(0, east=3.0), "s", 0.0, 0.0)
    assert [a.type for a in _sent(v, "MISSION_ACK")] == [M.MAV_MISSION_ACCEPTED]
    v.update(0.0)
    assert svc.has_mission() and _sent(v, "MISSION_CURRENT")[-1].total == 1
    v.outbox.clear()
    req = _from(M.MAVLink_mission_request_list_message(1, 1, 0), restricted=True)
    v.handle(req, "u", 0.0, 0.0)
    assert _sent(v, "MISSION_COUNT")[0].count == 1
    clear = _from(M.MAVLink_mission_clear_all_message(1, 1, 0), restricted=True)
    v.handle(clear, "u", 0.0, 0.0)
    assert svc.has_mission()
    assert svc.start(0.0) == M.MAV_RESULT_ACCEPTED


def test_service_fence_breach_acts_once() -> None:
    v = _vehicle()
    v.params.set("GF_MAX_VER_DIST", 1.0)  # the spawn height of cube8 is well above 1 m
    v.params.set("GF_ACTION", 2)  # hold
    v.update(0.0)
    assert v.mission.fence_breached and not v.armed
    assert not [e for e in v.events if "geofence" in e[1]]  # disarmed: flag only
    v.arm(0.0)
    v.update(0.1)
    v.update(0.2)
    lines = [e for e in v.events if "geofence breach" in e[1]]
    assert len(lines) == 1 and "hold" in lines[0][1]
    assert v.mode == VehicleMode.HOLD
    v.params.set("GF_MAX_VER_DIST", 0.0)
    v.update(0.3)
    assert not v.mission.fence_breached


@pytest.mark.parametrize(("action", "mode"), [(3, VehicleMode.RTL), (5, VehicleMode.LAND)])
def test_service_fence_action_rtl_and_land(action: int, mode: VehicleMode) -> None:
    v = _vehicle()
    v.params.set("GF_MAX_HOR_DIST", 0.5)
    v.home_enu = v.home_enu + np.array([0.0, 10.0, 0.0])  # home 10 m north of the vehicle
    v.params.set("GF_ACTION", action)
    v.arm(0.0)
    v.update(0.0)
    assert v.mission.fence_breached and v.mode == mode
