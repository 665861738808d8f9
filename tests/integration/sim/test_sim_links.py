"""The simulator as several MAVLink instances (PX4-style): each link numbers its own
frames, and a component's HEARTBEAT on the API link reaches the GCS link's peers.

A real ``vehicle-sim`` (one vehicle, no Zenoh) over 127.0.0.1: a stand-in for the
offboard daemon sends HEARTBEATs as component 191 on the API link; a ground station on
the GCS link sees them, and sees the autopilot's frames with no sequence gap.
"""

from __future__ import annotations

import socket
import time

import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common.ports import vehicle_ports

pytestmark = pytest.mark.timeout(60)
LOCALHOST = "127.0.0.1"


def _sock(port: int) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((LOCALHOST, port))
    s.settimeout(0.05)
    return s


def test_component_heartbeat_forwarded_and_gcs_sequence_contiguous(sim_factory) -> None:
    sim = sim_factory(["--no-zenoh", "--vehicles", "1"])
    ports = vehicle_ports(1, sim.offset)
    daemon = _sock(ports.api_remote)  # where the simulator sends the API link's frames
    gcs = _sock(ports.gcs_remote)  # the default GCS remote: never throttled
    dmav = M.MAVLink(None, srcSystem=1, srcComponent=M.MAV_COMP_ID_ONBOARD_COMPUTER)
    gmav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    seqs: list[int] = []
    forwarded = 0
    try:
        end = time.monotonic() + 6.0
        next_hb = 0.0
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 0.5
                hb = dmav.heartbeat_encode(M.MAV_TYPE_ONBOARD_CONTROLLER,
                                           M.MAV_AUTOPILOT_INVALID, 0, 0, 0)  # fmt: skip
                daemon.sendto(hb.pack(dmav), (LOCALHOST, ports.api_local))
                dmav.seq = (dmav.seq + 1) % 256
                g = gmav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                gcs.sendto(g.pack(gmav), (LOCALHOST, ports.gcs_local))
            try:
                data = gcs.recv(65535)
            except TimeoutError:
                continue
            for m in parser.parse_buffer(data) or []:
                if m.get_srcComponent() == M.MAV_COMP_ID_ONBOARD_COMPUTER:
                    forwarded += m.get_type() == "HEARTBEAT"
                elif m.get_srcComponent() == M.MAV_COMP_ID_AUTOPILOT1:
                    seqs.append(m.get_seq())
    finally:
        daemon.close()
        gcs.close()
    assert forwarded >= 2  # the onboard component is visible to the ground station
    assert len(seqs) > 50
    gaps = sum((b - a) % 256 != 1 for a, b in zip(seqs, seqs[1:], strict=False))
    assert gaps == 0, seqs[:40]
    assert sim.stop() == 0


def _kinds(sock: socket.socket, parser: M.MAVLink, seconds: float) -> set[str]:
    """Message types received on ``sock`` during ``seconds``."""
    kinds: set[str] = set()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            data = sock.recv(65535)
        except TimeoutError:
            continue
        kinds.update(m.get_type() for m in parser.parse_buffer(data) or [])
    return kinds


def test_default_streams_on_contact_heartbeat_until_a_client_speaks(sim_factory) -> None:
    """``--default-streams on-contact``: a silent listener on the default remotes gets the
    HEARTBEAT (to find the vehicle) and no telemetry stream; once it speaks it gets the
    default telemetry (ATTITUDE at 15 Hz)."""
    sim = sim_factory(["--no-zenoh", "--vehicles", "1", "--default-streams", "on-contact"])
    ports = vehicle_ports(1, sim.offset)
    gcs = _sock(ports.gcs_remote)
    api = _sock(ports.api_remote)
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    gmav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    try:
        silent = _kinds(gcs, parser, 2.5) | _kinds(api, parser, 0.5)
        assert "HEARTBEAT" in silent
        assert not silent & {"ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED",
                             "VFR_HUD", "SYS_STATUS", "BATTERY_STATUS"}, silent
        got: set[str] = set()
        end = time.monotonic() + 15.0
        while "ATTITUDE" not in got and time.monotonic() < end:
            g = gmav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            gcs.sendto(g.pack(gmav), (LOCALHOST, ports.gcs_local))
            gmav.seq = (gmav.seq + 1) % 256
            got |= _kinds(gcs, parser, 0.5)
        assert "ATTITUDE" in got
    finally:
        gcs.close()
        api.close()
