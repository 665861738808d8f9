"""The formation as one MAVLink vehicle (gcs.formation, docs/missions.md): an unmodified
pymavlink client uploads a 3-waypoint mission to system 200 on UDP 14560 + offset and starts
it, in a distributed lockstep run; the formation's centroid passes within 0.5 m of each
waypoint. A mission under the floor is refused with MAV_MISSION_INVALID and changes nothing.

The swarm is signed (the default); the client is a ground station of the same operator and
holds the key. The run packs the eight daemons into two processes (test_mission_packed:
the same run as one process per agent)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from formation_flight import assert_passes, fly_with, formation_port, swarm_key, waiting_course8
from pymavlink import mavutil

from gcs.formation.vehicle import FORMATION_SYSID
from gcs.mission.distributed import recorded_metrics
from swarm_common import frames
from swarm_common.signing import load_key, setup_signing
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics import geo

pytestmark = pytest.mark.timeout(300)
MAV = mavutil.mavlink
WAYPOINTS = [(6.0, 2.0, 4.0), (6.0, 6.0, 4.5), (2.0, 6.0, 4.0)]  # ENU centroids (m)
BAD = [(6.0, 2.0, 0.3)]  # the formation's lowest layer would be under the floor
# s of mission time: 3 legs of about 4.5 s, and the upload, in wall time, while the lockstep
# run goes on (on an idle machine the last waypoint is passed at 22 s)
DURATION_S = 40.0


class GroundStation(threading.Thread):
    """Waits for the formation's heartbeat, uploads BAD (expects MAV_MISSION_INVALID), then
    WAYPOINTS, and starts the mission; records every result."""

    def __init__(self, port: int, key: bytes) -> None:
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=245,
                                               source_component=190)
        setup_signing(self.conn.mav, key, 9)
        self.results: dict[str, int | None] = {}
        self.error: str | None = None

    def recv(self, kind: str, timeout: float = 20.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.conn.recv_match(type=kind, blocking=True, timeout=0.25)
            if m is not None and m.get_srcSystem() == FORMATION_SYSID:
                return m
            self.conn.mav.heartbeat_send(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        return None

    def upload(self, points: list[tuple[float, float, float]]) -> int | None:
        cfg = AutopilotConfig()
        self.conn.mav.mission_count_send(FORMATION_SYSID, 1, len(points),
                                         MAV.MAV_MISSION_TYPE_MISSION)
        for _ in points:
            req = self.recv("MISSION_REQUEST_INT")
            if req is None:
                return None
            e, n, u = points[req.seq]
            lat, lon = geo.latlon_e7(cfg, frames.enu_to_ned(np.array([e, n, u])))
            self.conn.mav.mission_item_int_send(
                FORMATION_SYSID, 1, req.seq, MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                MAV.MAV_CMD_NAV_WAYPOINT, 0, 1, 1.0, 0.0, 0.0, float("nan"), lat, lon, u,
                MAV.MAV_MISSION_TYPE_MISSION)
            if req.seq == len(points) - 1:
                break
        ack = self.recv("MISSION_ACK")
        return None if ack is None else int(ack.type)

    def run(self) -> None:
        try:
            if self.recv("HEARTBEAT", timeout=60.0) is None:
                self.error = "no heartbeat from the formation"
                return
            self.results["bad"] = self.upload(BAD)
            self.results["good"] = self.upload(WAYPOINTS)
            self.conn.mav.command_long_send(FORMATION_SYSID, 1, MAV.MAV_CMD_MISSION_START, 0,
                                            0, 0, 0, 0, 0, 0, 0)
            ack = self.recv("COMMAND_ACK")
            self.results["start"] = None if ack is None else int(ack.result)
        except Exception as exc:  # noqa: BLE001 - reported by the test
            self.error = repr(exc)


@pytest.mark.slow
def test_a_pymavlink_ground_station_flies_the_formation(tmp_path: Path) -> None:
    sc = waiting_course8(tmp_path)
    off, port = formation_port()
    key_path = swarm_key(tmp_path)
    gs = GroundStation(port, load_key(key_path))
    rec, facts = fly_with(gs, sc, tmp_path, off, DURATION_S, key_path)
    assert gs.error is None, gs.error
    assert gs.results == {"bad": MAV.MAV_MISSION_INVALID, "good": MAV.MAV_MISSION_ACCEPTED,
                          "start": MAV.MAV_RESULT_ACCEPTED}
    assert facts["formation_commands"] == ["mission"]  # the refused upload sent nothing
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], DURATION_S)
    assert_passes(ser.p.mean(axis=1), WAYPOINTS)  # in order
    assert m["collisions"] == 0 and m["h_min"] >= 0.0


class MavsdkGroundStation(threading.Thread):
    """An unmodified MAVSDK (native binding) on the formation vehicle's port: uploads
    MAVSDK_LEGS as a mission with a speed, starts it, waits (on MAVSDK's own telemetry) until
    the centroid is at the last leg, then sends ``goto_location`` to GOTO."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.port = port
        self.done: list[str] = []
        self.error: str | None = None

    def run(self) -> None:
        try:
            self._run()
        except Exception as exc:  # noqa: BLE001 - reported by the test
            self.error = repr(exc)

    def _run(self) -> None:
        import mavsdk
        from mavsdk.plugins.action import Action
        from mavsdk.plugins.mission import Mission, MissionItem, MissionPlan
        from mavsdk.plugins.telemetry import Telemetry

        cfg = mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION)
        m = mavsdk.Mavsdk(cfg)
        try:
            m.add_any_connection(f"udpout://127.0.0.1:{self.port}")
            system = m.first_autopilot(60.0)
            assert system is not None, "MAVSDK found no autopilot"
            geo_cfg = AutopilotConfig()
            items = []
            for e, n, u in MAVSDK_LEGS:
                lat, lon = geo.latlon_e7(geo_cfg, frames.enu_to_ned(np.array([e, n, u])))
                items.append(MissionItem(
                    latitude_deg=lat / 1e7, longitude_deg=lon / 1e7, relative_altitude_m=u,
                    speed_m_s=2.0, is_fly_through=False, acceptance_radius_m=0.5))
            mission = Mission(system)
            mission.upload_mission(MissionPlan(items))
            self.done.append("upload")
            mission.start_mission()
            self.done.append("start")
            tel = Telemetry(system)
            last = MAVSDK_LEGS[-1]
            deadline = time.monotonic() + 120.0
            while time.monotonic() < deadline:
                p = tel.position()
                if np.isfinite(p.latitude_deg):
                    ned = geo.ned_from_latlon(geo_cfg, p.latitude_deg, p.longitude_deg)
                    if np.hypot(ned[1] - last[0], ned[0] - last[1]) < 0.3:
                        break
                time.sleep(0.05)
            else:
                raise AssertionError("MAVSDK never saw the formation at the last leg")
            e, n, u = GOTO
            lat, lon = geo.latlon_e7(geo_cfg, frames.enu_to_ned(np.array([e, n, u])))
            Action(system).goto_location(lat / 1e7, lon / 1e7, geo_cfg.home_alt + u,
                                         float("nan"))
            self.done.append("goto")
        finally:
            m.destroy()


MAVSDK_LEGS = [(6.0, 2.0, 4.0), (6.0, 6.0, 4.0)]
# s of mission time: the lockstep run goes on while MAVSDK connects and uploads in wall time
# (seconds on a loaded machine), then two legs, the go-to and its lead (on an idle machine
# the go-to's point is passed at 21 s)
MAVSDK_S = 65.0
GOTO = (2.0, 6.0, 4.5)


@pytest.mark.slow
def test_mavsdk_uploads_starts_and_sends_the_formation_somewhere(tmp_path: Path) -> None:
    pytest.importorskip("mavsdk")
    sc = waiting_course8(tmp_path)
    off, port = formation_port()
    # MAVSDK does not sign: a swarm whose links are unsigned (--no-signing)
    gs = MavsdkGroundStation(port)
    rec, facts = fly_with(gs, sc, tmp_path, off, MAVSDK_S, None, join_s=10.0)
    assert gs.error is None, gs.error
    assert gs.done == ["upload", "start", "goto"]
    # MAVSDK's goto on a PX4 autopilot switches to HOLD (AUTO.LOITER) before DO_REPOSITION
    kinds = facts["formation_commands"]
    assert kinds[0] == kinds[-1] == "mission" and set(kinds) <= {"mission", "hold"}, kinds
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], MAVSDK_S)
    assert_passes(ser.p.mean(axis=1), [*MAVSDK_LEGS, GOTO])
    assert m["collisions"] == 0 and m["h_min"] >= 0.0
