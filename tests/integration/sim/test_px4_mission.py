"""The mission protocol of vehicle-sim over loopback UDP with unmodified clients: MAVSDK's
``mission`` and ``geofence`` plugins (upload, download, fly), and pymavlink doing what
MAVProxy's ``wp list`` does (MISSION_REQUEST_LIST, then one request per item)."""

from __future__ import annotations

import math

import pytest
from conftest import wait_for
from mavsdk_client import mavsdk_autopilot, position_ready
from pymavlink import mavwp
from pymavlink.dialects.v20 import common as M

from swarm_common.ports import vehicle_ports

pytestmark = pytest.mark.timeout(180)
ONE = ["--no-zenoh", "--vehicles", "1"]
M_PER_DEG = 111_320.0  # metres per degree of latitude (flat earth, for offsets only)


@pytest.fixture
def mavsdk_system(sim_factory):
    """(sim, system, (lat, lon) of vehicle 1) with an unmodified MAVSDK on its API link."""
    pytest.importorskip("mavsdk")
    from mavsdk.plugins.telemetry import Telemetry

    sim = sim_factory(ONE)
    with mavsdk_autopilot(sim) as system:
        tel = Telemetry(system)
        # not the health flag alone: under load a plan made at (NaN, NaN) was uploaded
        assert wait_for(lambda: position_ready(tel), 10.0), sim.text()
        pos = tel.position()
        yield sim, system, (pos.latitude_deg, pos.longitude_deg)


def _offset(here: tuple[float, float], north: float, east: float) -> tuple[float, float]:
    lat, lon = here
    return lat + north / M_PER_DEG, lon + east / (M_PER_DEG * math.cos(math.radians(lat)))


def _plan(here, legs, land_last: bool = False):
    from mavsdk.plugins.mission import MissionItem, MissionPlan

    items = []
    for k, (north, east, alt) in enumerate(legs):
        lat, lon = _offset(here, north, east)
        action = MissionItem.VehicleAction.NONE
        if land_last and k == len(legs) - 1:
            action = MissionItem.VehicleAction.LAND
        items.append(
            MissionItem(
                latitude_deg=lat, longitude_deg=lon, relative_altitude_m=alt,
                speed_m_s=3.0, is_fly_through=False, acceptance_radius_m=1.0,
                vehicle_action=action,
            )
        )  # fmt: skip
    return MissionPlan(items)


LEGS = [(0.0, 0.0, 8.0), (6.0, 0.0, 8.0), (6.0, 6.0, 6.0), (0.0, 6.0, 5.0)]


def test_mavsdk_mission_upload_download_and_wp_list(mavsdk_system, mav_client) -> None:
    from mavsdk.plugins.mission import Mission

    sim, system, here = mavsdk_system
    mis = Mission(system)
    plan = _plan(here, LEGS)
    mis.upload_mission(plan)
    got = mis.download_mission()
    assert len(got.mission_items) == len(plan.mission_items)
    for a, b in zip(plan.mission_items, got.mission_items, strict=True):
        assert b.latitude_deg == pytest.approx(a.latitude_deg, abs=2e-7)
        assert b.longitude_deg == pytest.approx(a.longitude_deg, abs=2e-7)
        assert b.relative_altitude_m == pytest.approx(a.relative_altitude_m, abs=1e-3)
        assert b.speed_m_s == pytest.approx(a.speed_m_s)
        assert b.acceptance_radius_m == pytest.approx(a.acceptance_radius_m)

    # pymavlink on the GCS link: wp list as MAVProxy sends it (float MISSION_REQUEST),
    # then the same items with MISSION_REQUEST_INT
    c = mav_client(vehicle_ports(1, sim.offset).gcs_remote)
    assert c.recv("HEARTBEAT", 10, sysid=1) is not None, sim.text()
    c.conn.target_system, c.conn.target_component = 1, 1
    c.conn.waypoint_request_list_send()
    cnt = c.recv("MISSION_COUNT", 5, sysid=1)
    assert cnt is not None and cnt.mission_type == M.MAV_MISSION_TYPE_MISSION
    wps = mavwp.MAVWPLoader(target_system=1, target_component=1)
    for seq in range(cnt.count):
        c.conn.waypoint_request_send(seq)
        it = c.recv("MISSION_ITEM", 5, sysid=1, cond=lambda m, s=seq: m.seq == s)
        assert it is not None, f"no MISSION_ITEM {seq}"
        wps.add(it)
    c.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)
    nav = [w for w in (wps.wp(i) for i in range(wps.count())) if w.command == 16]
    assert len(nav) == len(LEGS)
    for w, (north, east, alt) in zip(nav, LEGS, strict=True):
        lat, lon = _offset(here, north, east)
        assert (w.x, w.y, w.z) == pytest.approx((lat, lon, alt), abs=1e-5)  # float32 degrees
        assert w.frame == M.MAV_FRAME_GLOBAL_RELATIVE_ALT  # the float message's frame
    for seq in range(cnt.count):
        c.mav.mission_request_int_send(1, 1, seq, M.MAV_MISSION_TYPE_MISSION)
        it = c.recv("MISSION_ITEM_INT", 5, sysid=1, cond=lambda m, s=seq: m.seq == s)
        assert it is not None and it.command == wps.wp(seq).command
    # MISSION_CURRENT is streamed; a clear empties the store
    cur = c.recv("MISSION_CURRENT", 5, sysid=1)
    assert cur is not None and cur.total == cnt.count
    mis.clear_mission()
    c.conn.waypoint_request_list_send()
    assert c.recv("MISSION_COUNT", 5, sysid=1, cond=lambda m: m.count == 0) is not None


def test_mavsdk_geofence_round_trip(mavsdk_system, mav_client) -> None:
    from mavsdk.plugins.geofence import Circle, FenceType, Geofence, GeofenceData, Point, Polygon

    sim, system, here = mavsdk_system
    corners = [_offset(here, n, e) for n, e in ((-50, -50), (-50, 50), (50, 50), (50, -50))]
    poly = Polygon([Point(lat, lon) for lat, lon in corners], FenceType.INCLUSION)
    centre = _offset(here, 20.0, 0.0)
    circ = Circle(Point(*centre), 5.0, FenceType.EXCLUSION)
    gf = Geofence(system)
    gf.upload_geofence(GeofenceData([poly], [circ]))
    got = gf.download_geofence()
    assert len(got.polygons) == 1 and len(got.circles) == 1
    assert got.polygons[0].fence_type == FenceType.INCLUSION
    for p, (lat, lon) in zip(got.polygons[0].points, corners, strict=True):
        assert (p.latitude_deg, p.longitude_deg) == pytest.approx((lat, lon), abs=2e-7)
    assert got.circles[0].radius == pytest.approx(5.0)
    assert got.circles[0].fence_type == FenceType.EXCLUSION
    # the fence is kept apart from the mission: the mission store is still empty
    c = mav_client(vehicle_ports(1, sim.offset).gcs_remote)
    assert c.recv("HEARTBEAT", 10, sysid=1) is not None
    c.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert c.recv("MISSION_COUNT", 5, sysid=1, cond=lambda m: m.mission_type == 0).count == 0
    c.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_FENCE)
    fence = c.recv("MISSION_COUNT", 5, sysid=1, cond=lambda m: m.mission_type == 1)
    assert fence is not None and fence.count == 5


def test_unsupported_nav_command_is_refused(sim_factory, mav_client) -> None:
    """A NAV command AUTO.MISSION does not fly: MAV_MISSION_UNSUPPORTED, store unchanged."""
    sim = sim_factory(ONE)
    c = mav_client(vehicle_ports(1, sim.offset).gcs_remote)
    assert c.recv("HEARTBEAT", 10, sysid=1) is not None, sim.text()
    c.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
    req = c.recv("MISSION_REQUEST_INT", 5, sysid=1)
    assert req is not None and req.seq == 0
    c.mav.mission_item_int_send(
        1, 1, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_LOITER_TURNS, 0, 1,
        1, 0, 5, 0, 473977420, 85455940, 10.0, M.MAV_MISSION_TYPE_MISSION,
    )  # fmt: skip
    ack = c.recv("MISSION_ACK", 5, sysid=1)
    assert ack is not None and ack.type == M.MAV_MISSION_UNSUPPORTED
    c.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert c.recv("MISSION_COUNT", 5, sysid=1).count == 0


def test_mavsdk_mission_flies_to_the_end_and_lands(mavsdk_system) -> None:
    """arm -> start_mission -> progress reaches the end -> landed (needs AUTO.MISSION)."""
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.mission import Mission
    from mavsdk.plugins.telemetry import LandedState, Telemetry

    sim, system, here = mavsdk_system
    mis, act, tel = Mission(system), Action(system), Telemetry(system)
    legs = [(0.0, 0.0, 8.0), (5.0, 0.0, 8.0), (5.0, 5.0, 6.0)]
    mis.upload_mission(_plan(here, legs, land_last=True))
    act.arm()
    assert wait_for(tel.armed, 5.0), sim.text()
    mis.start_mission()
    total = len(legs)
    seen: list[int] = []

    def done() -> bool:
        prog = mis.mission_progress()
        if not seen or seen[-1] != prog.current:
            seen.append(prog.current)
        return prog.total == total and mis.is_mission_finished()

    assert wait_for(done, 90.0), f"progress {seen}\n{sim.text()}"
    assert seen == sorted(seen) and seen[-1] == total
    assert wait_for(lambda: tel.landed_state() == LandedState.ON_GROUND, 30.0), sim.text()
    assert wait_for(lambda: not tel.armed(), 10.0), sim.text()
    end = tel.position()
    lat, lon = _offset(here, 5.0, 5.0)
    assert end.latitude_deg == pytest.approx(lat, abs=2.0 / M_PER_DEG)
    assert end.longitude_deg == pytest.approx(lon, abs=3.0 / M_PER_DEG)
