"""The simulator reports a stored fence that a ground station changed in its Zenoh truth
(``wire.Truth.fences``; docs/world.md, "Scored from the truth"), so a run's verdict scores
the fence each vehicle enforces: ``vehicle-sim`` in real time, an unmodified pymavlink
client uploading a pentagon over the mission protocol on the GCS link, a real Zenoh
subscriber to the truth."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import CUBE8, free_port_offset, wait_for

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from swarm_common import wire  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402
from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT, open_session  # noqa: E402
from vehicle_sim.autopilot.config import AutopilotConfig  # noqa: E402
from vehicle_sim.physics.geo import latlon_e7  # noqa: E402

pytestmark = pytest.mark.timeout(120)
M = mavutil.mavlink
BOX = "\n[geofence]\nmin_m = [-2.0, -2.0, 0.0]\nmax_m = [9.0, 8.0, 9.5]\nmargin_m = 0.5\n"
PENTAGON = ((0.0, -1.5), (8.0, -1.5), (8.0, 5.9), (4.0, 7.0), (0.0, 5.9))  # ENU, m


def _upload(port: int, xy: tuple[tuple[float, float], ...]) -> int:
    """``xy`` as one inclusion polygon to vehicle 1's GCS link; the MISSION_ACK's result."""
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                                      source_component=190)
    cfg = AutopilotConfig()
    try:
        conn.mav.mission_count_send(1, 1, len(xy), M.MAV_MISSION_TYPE_FENCE)
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            m = conn.recv_match(type=["MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True,
                                timeout=0.5)
            if m is None:
                continue
            if m.get_type() == "MISSION_ACK":
                return int(m.type)
            x, y = xy[m.seq]
            lat, lon = latlon_e7(cfg, np.array([y, x, 0.0]))  # NED offset from the origin
            conn.mav.mission_item_int_send(
                1, 1, m.seq, M.MAV_FRAME_GLOBAL_INT,
                M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 0, 1, float(len(xy)), 0, 0, 0,
                lat, lon, 0.0, M.MAV_MISSION_TYPE_FENCE)
        raise AssertionError("no MISSION_ACK for the fence upload")
    finally:
        conn.close()


def test_an_uploaded_fence_reaches_the_truth_once(sim_factory, tmp_path: Path) -> None:
    scenario = tmp_path / "cube8_fence.toml"
    scenario.write_text(Path(CUBE8).read_text() + BOX)
    off = free_port_offset()
    sim = sim_factory(["--vehicles", "1", "--swarm", "ft"], offset=off, scenario=str(scenario))
    lock = threading.Lock()
    seen: list[wire.Truth] = []

    def got(sample) -> None:
        msg = wire.decode(sample.payload.to_bytes())
        with lock:
            seen.append(msg)

    sess = open_session(connect=[f"tcp/127.0.0.1:{DEFAULT_ZENOH_PORT + off}"])
    sub = sess.declare_subscriber(wire.key_truth("ft"), got)
    try:
        assert wait_for(lambda: len(seen) > 10, 30.0), sim.text()
        with lock:  # the scenario's own fence, stored from the start: never reported
            assert not any(isinstance(t, wire.Truth) and t.fences for t in seen)
        assert _upload(vehicle_ports(1, off).gcs_local, PENTAGON) == M.MAV_MISSION_ACCEPTED
        n0 = len(seen)
        assert wait_for(lambda: len(seen) > n0 + 20, 30.0), sim.text()
    finally:
        sub.undeclare()
        sess.close()
    with lock:
        changed = [t for t in seen if isinstance(t, wire.Truth) and t.fences]
    assert len(changed) == 1, [t.step for t in changed]  # once, on the step after the upload
    xy = changed[0].fences[1].reshape(-1, 2)
    assert np.allclose(xy, PENTAGON, atol=0.02)  # the degE7 round trip: about 1 cm
