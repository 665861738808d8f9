"""The formation flown live (gcs.formation.live, docs/missions.md "Flying the formation
live"): an unmodified pymavlink client streams velocity setpoints to the formation's
MAVLink vehicle, switches it to OFFBOARD, and stops streaming once the centroid has gone
MOVE_M east. In a distributed lockstep run the formation flies east at the commanded speed
with its shape kept, then brakes to rest by itself, and the vehicle leaves OFFBOARD.

The client reacts to the formation's own LOCAL_POSITION_NED, never to wall time, so the
outcome does not depend on how fast the lockstep run goes."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from formation_flight import WAIT_AT, fly_with, formation_port, swarm_key, waiting_course8
from pymavlink import mavutil

from gcs.formation.vehicle import FORMATION_SYSID
from gcs.mission.distributed import recorded_metrics
from swarm_common import px4
from swarm_common.scenario.mission_check import mission_shape
from swarm_common.signing import load_key, setup_signing

pytestmark = pytest.mark.timeout(300)
MAV = mavutil.mavlink
SPEED = 1.0  # m/s east
MOVE_M = 4.0  # the client stops streaming once the centroid is this far east of its start
DURATION_S = 40.0
START = WAIT_AT  # ENU (m): the waypoint where the formation forms and waits
FORMED_M, FORMED_MPS = 0.1, 0.05  # the client starts once the centroid is there, at rest
VELOCITY_ONLY = (MAV.POSITION_TARGET_TYPEMASK_X_IGNORE | MAV.POSITION_TARGET_TYPEMASK_Y_IGNORE
                 | MAV.POSITION_TARGET_TYPEMASK_Z_IGNORE | MAV.POSITION_TARGET_TYPEMASK_AX_IGNORE
                 | MAV.POSITION_TARGET_TYPEMASK_AY_IGNORE | MAV.POSITION_TARGET_TYPEMASK_AZ_IGNORE
                 | MAV.POSITION_TARGET_TYPEMASK_YAW_IGNORE
                 | MAV.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)


class LivePilot(threading.Thread):
    """Streams (0, SPEED, 0) NED at 10 Hz, asks for OFFBOARD, stops when the centroid has
    moved MOVE_M east, then reads the mode the formation reports."""

    def __init__(self, port: int, key: bytes) -> None:
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=245,
                                               source_component=190)
        setup_signing(self.conn.mav, key, 9)
        self.error: str | None = None
        self.offboard_result: int | None = None
        self.denied_before_stream: int | None = None
        self.mode_after: int | None = None
        self.start_east: float | None = None

    def recv(self, kind: str, timeout: float = 20.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.conn.recv_match(type=kind, blocking=True, timeout=0.1)
            if m is not None and m.get_srcSystem() == FORMATION_SYSID:
                return m
            self.conn.mav.heartbeat_send(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        return None

    def formed(self):
        """The first LOCAL_POSITION_NED with the centroid at rest at its waypoint."""
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline:
            m = self.recv("LOCAL_POSITION_NED", timeout=5.0)
            if m is None:
                continue
            at = np.hypot(np.hypot(m.x - START[1], m.y - START[0]), -m.z - START[2])
            if at < FORMED_M and np.linalg.norm([m.vx, m.vy, m.vz]) < FORMED_MPS:
                return m
        return None

    def set_mode(self, main: int) -> int | None:
        self.conn.mav.command_long_send(FORMATION_SYSID, 1, MAV.MAV_CMD_DO_SET_MODE, 0,
                                        MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, 0, 0, 0,
                                        0, 0)
        ack = self.recv("COMMAND_ACK")
        return None if ack is None else int(ack.result)

    def setpoint(self) -> None:
        self.conn.mav.set_position_target_local_ned_send(
            0, FORMATION_SYSID, 1, MAV.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY,
            0.0, 0.0, 0.0, 0.0, SPEED, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def run(self) -> None:
        try:
            first = self.formed()
            if first is None:
                self.error = "the formation never formed at its waypoint"
                return
            self.start_east = float(first.y)
            self.denied_before_stream = self.set_mode(px4.MAIN_OFFBOARD)  # PX4: no stream
            for _ in range(5):
                self.setpoint()
                time.sleep(0.1)
            self.offboard_result = self.set_mode(px4.MAIN_OFFBOARD)
            deadline = time.monotonic() + 120.0
            while time.monotonic() < deadline:
                self.setpoint()
                m = self.conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=0.1)
                if (m is not None and m.get_srcSystem() == FORMATION_SYSID
                        and float(m.y) - self.start_east >= MOVE_M):
                    break
            else:
                self.error = "the formation never moved MOVE_M east"
                return
            # the stream is gone: the vehicle leaves OFFBOARD (the newest heartbeat within
            # 10 s of wall time; older ones may still wait in the socket)
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline:
                hb = self.recv("HEARTBEAT", timeout=2.0)
                if hb is not None:
                    self.mode_after = px4.split_mode(int(hb.custom_mode))[0]
                    if self.mode_after != px4.MAIN_OFFBOARD:
                        break
        except Exception as exc:  # noqa: BLE001 - reported by the test
            self.error = repr(exc)


@pytest.mark.slow
def test_a_client_flies_the_formation_live_with_velocity_setpoints(tmp_path: Path) -> None:
    sc = waiting_course8(tmp_path)
    off, port = formation_port()
    key_path = swarm_key(tmp_path)
    pilot = LivePilot(port, load_key(key_path))
    rec, facts = fly_with(pilot, sc, tmp_path, off, DURATION_S, key_path)
    assert pilot.error is None, pilot.error
    assert pilot.denied_before_stream == MAV.MAV_RESULT_DENIED
    assert pilot.offboard_result == MAV.MAV_RESULT_ACCEPTED
    assert pilot.mode_after is not None and pilot.mode_after != px4.MAIN_OFFBOARD
    kinds = facts["formation_commands"]
    assert kinds and set(kinds) == {"live"}
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], DURATION_S)
    assert m["collisions"] == 0 and m["h_min"] >= 0.0
    centroid = ser.p.mean(axis=1)
    moved = centroid[-1] - np.array(START)
    assert moved[0] >= MOVE_M - 0.1, moved  # east, at least as far as the client flew it
    assert abs(moved[1]) <= 0.3 and abs(moved[2]) <= 0.3, moved
    dt = sc.control_dt
    vel = np.gradient(centroid, dt, axis=0)
    # from when the client saw it formed: the commanded velocity, never much more
    at = np.linalg.norm(centroid - np.array(START), axis=1)
    formed = np.flatnonzero((at < FORMED_M) & (np.linalg.norm(vel, axis=1) < FORMED_MPS))
    assert formed.size
    vel = vel[formed[0]:]
    cruising = np.flatnonzero(vel[:, 0] > 0.5 * SPEED)
    assert cruising.size * dt >= 2.0
    assert np.max(vel[:, 0]) <= SPEED * 1.1
    # at the end it is at rest, with the scenario's shape around the centroid (yaw 0,
    # scale 1: the formation error of each agent)
    assert np.linalg.norm(vel[-1]) < 0.05
    shape = mission_shape(sc) - mission_shape(sc).mean(axis=0)
    err = (ser.p[-1] - centroid[-1]) - shape
    assert float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) <= 0.15
