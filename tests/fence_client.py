"""A ground station's side of the fence tests, with pymavlink as it comes: upload a fence
over the mission protocol, and ask a vehicle for one message (MAV_CMD_REQUEST_MESSAGE)."""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from vehicle_sim.autopilot.config import AutopilotConfig  # noqa: E402
from vehicle_sim.physics.geo import latlon_e7  # noqa: E402

M = mavutil.mavlink
# the scenario fence the fence tests append to cube8, and the smaller pentagon they upload
BOX = "\n[geofence]\nmin_m = [-2.0, -2.0, 0.0]\nmax_m = [9.0, 8.0, 9.5]\nmargin_m = 0.5\n"
PENTAGON = ((0.0, -1.5), (8.0, -1.5), (8.0, 5.9), (4.0, 7.0), (0.0, 5.9))  # ENU, m


def _gcs(port: int) -> Any:
    return mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                                      source_component=190)


def upload_fence(port: int, xy: tuple[tuple[float, float], ...], target: int) -> int:
    """Upload ``xy`` (ENU, m, about the default origin) as one inclusion polygon to vehicle
    ``target``'s GCS link at ``port``; the final MISSION_ACK's result."""
    conn = _gcs(port)
    cfg = AutopilotConfig()
    try:
        conn.mav.mission_count_send(target, 1, len(xy), M.MAV_MISSION_TYPE_FENCE)
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            m = conn.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                                blocking=True, timeout=0.5)
            if m is None or m.get_srcSystem() != target:
                continue
            if m.get_type() == "MISSION_ACK":
                return int(m.type)
            x, y = xy[m.seq]
            lat, lon = latlon_e7(cfg, np.array([y, x, 0.0]))  # NED offset from the origin
            conn.mav.mission_item_int_send(
                target, 1, m.seq, M.MAV_FRAME_GLOBAL_INT,
                M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 0, 1, float(len(xy)), 0, 0, 0,
                lat, lon, 0.0, M.MAV_MISSION_TYPE_FENCE)
        raise AssertionError("no MISSION_ACK for the fence upload")
    finally:
        conn.close()


def request_message(port: int, target: int, msg_id: int, kind: str) -> Any:
    """Ask vehicle ``target``'s GCS link at ``port`` for message ``msg_id`` (of type
    ``kind``) with MAV_CMD_REQUEST_MESSAGE until it comes (20 s at most)."""
    conn = _gcs(port)
    try:
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            conn.mav.command_long_send(target, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, msg_id, 0, 0,
                                       0, 0, 0, 0)
            m = conn.recv_match(type=kind, blocking=True, timeout=0.5)
            if m is not None and m.get_srcSystem() == target:
                return m
        raise AssertionError(f"no {kind}")
    finally:
        conn.close()
