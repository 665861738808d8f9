"""What a ground station does on connect, against vehicle-sim over 127.0.0.1 UDP: every
request gets an answer, PX4's default streams arrive without asking, MAVSDK's attitude is
finite without setting a rate, and a rate set by one client ends with that client."""

from __future__ import annotations

import math
import socket
import time

import pytest
from conftest import MavClient
from mavsdk_client import mavsdk_autopilot
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from swarm_common.ports import vehicle_ports
from vehicle_sim.autopilot import mavlink_extra
from vehicle_sim.link.endpoint import PEER_TIMEOUT_S

pytestmark = pytest.mark.timeout(120)

# MAVLink id that pymavlink 2.4's common dialect does not define (QGC asks for it)
MSG_ID_COMPONENT_METADATA = 397
DEFAULT_STREAMS = (
    "ATTITUDE", "VFR_HUD", "ALTITUDE", "EXTENDED_SYS_STATE", "SYS_STATUS", "BATTERY_STATUS",
    "HOME_POSITION", "GPS_RAW_INT", "GLOBAL_POSITION_INT",
)  # fmt: skip
GCS_SYSID, GCS_COMPID = 255, 190
LOCALHOST = "127.0.0.1"


def _gcs(mav_client, sim) -> MavClient:
    """A client listening where QGroundControl listens (the GCS link's default remote)."""
    mavlink_extra.register(mavutil.mavlink)  # let mavutil's parser decode PROTOCOL_VERSION
    c = mav_client(vehicle_ports(1, sim.offset).gcs_remote)
    assert c.recv("HEARTBEAT", 10, sysid=1) is not None, sim.text()
    c.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE)
    return c


def test_qgc_like_connect_every_request_is_answered(sim_factory, mav_client):
    sim = sim_factory(["--no-zenoh", "--vehicles", "1"])
    c = _gcs(mav_client, sim)
    seen = {m.get_type() for m in _collect(c, 3.0)}
    assert set(DEFAULT_STREAMS) <= seen, seen  # nothing asked for yet
    st = c.recv("SYS_STATUS", 3, sysid=1)
    geo = M.MAV_SYS_STATUS_GEOFENCE
    assert st.onboard_control_sensors_present & st.onboard_control_sensors_health & geo

    ack = c.command(1, M.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    pv = c.recv("PROTOCOL_VERSION", 3, sysid=1)
    assert pv is not None and (pv.version, pv.min_version, pv.max_version) == (200, 100, 200)

    ack = c.command(1, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    ver = c.recv("AUTOPILOT_VERSION", 3, sysid=1)
    assert ver is not None and ver.capabilities & M.MAV_PROTOCOL_CAPABILITY_MISSION_INT

    ack = c.command(1, M.MAV_CMD_REQUEST_MESSAGE, MSG_ID_COMPONENT_METADATA)
    assert ack is not None and ack.result == M.MAV_RESULT_UNSUPPORTED  # an answer, not silence
    ack = c.command(1, M.MAV_CMD_GET_HOME_POSITION)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED

    for kind in (M.MAV_MISSION_TYPE_MISSION, M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY):
        c.mav.mission_request_list_send(1, 1, kind)
        cnt = c.recv("MISSION_COUNT", 3, sysid=1, cond=lambda m, k=kind: m.mission_type == k)
        assert cnt is not None, f"MISSION_REQUEST_LIST type {kind} not answered"
        c.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, kind)

    c.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTRA2, 10, 1)
    ds = c.recv("DATA_STREAM", 3, sysid=1)
    assert ds is not None and (ds.stream_id, ds.message_rate, ds.on_off) == (
        M.MAV_DATA_STREAM_EXTRA2, 10, 1,
    )  # fmt: skip
    c.command(1, M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_VFR_HUD)
    iv = c.recv("MESSAGE_INTERVAL", 3, sysid=1)
    assert iv is not None and iv.interval_us == 100_000  # this client's VFR_HUD: 10 Hz

    c.mav.ping_send(int(time.time() * 1e6), 77, 0, 0)
    ping = c.recv("PING", 3, sysid=1, cond=lambda m: m.seq == 77)
    assert ping is not None and (ping.target_system, ping.target_component) == (
        GCS_SYSID, GCS_COMPID,
    )  # fmt: skip

    tgt = M.MAVLINK_MSG_ID_ATTITUDE_TARGET  # off by default
    ack = c.command(1, M.MAV_CMD_SET_MESSAGE_INTERVAL, tgt, 100_000)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    assert c.recv("ATTITUDE_TARGET", 3, sysid=1) is not None

    c.mav.param_request_list_send(1, 1)
    pv0 = c.recv("PARAM_VALUE", 5, sysid=1)
    assert pv0 is not None and pv0.param_count > 0
    assert sim.stop() == 0


def _collect(c: MavClient, seconds: float) -> list:
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = c.conn.recv_match(blocking=True, timeout=0.1)
        if m is not None:
            out.append(m)
    return out


def test_mavsdk_attitude_euler_is_finite_without_setting_a_rate(sim_factory):
    pytest.importorskip("mavsdk")
    from mavsdk.plugins.telemetry import Telemetry

    sim = sim_factory(["--no-zenoh", "--vehicles", "1"])
    with mavsdk_autopilot(sim) as system:
        tel = Telemetry(system)
        end = time.monotonic() + 10.0
        e = tel.attitude_euler()
        while time.monotonic() < end and not math.isfinite(e.yaw_deg):
            time.sleep(0.05)
            e = tel.attitude_euler()
        assert all(math.isfinite(x) for x in (e.roll_deg, e.pitch_deg, e.yaw_deg)), e


class _Client:
    """A raw UDP MAVLink client bound to ``port`` (0: any), as a GCS restarted on the same
    address would be."""

    def __init__(self, port: int = 0) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind((LOCALHOST, port))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.enc = M.MAVLink(None, srcSystem=GCS_SYSID, srcComponent=GCS_COMPID)
        self.dec = M.MAVLink(None)
        self.dec.robust_parsing = True

    def send(self, dest: int, msg) -> None:
        self.sock.sendto(msg.pack(self.enc), (LOCALHOST, dest))

    def heartbeat(self, dest: int) -> None:
        hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        self.send(dest, hb)

    def command(self, dest: int, cmd: int, *params: float) -> None:
        ps = [float(x) for x in params] + [0.0] * (7 - len(params))
        self.send(dest, M.MAVLink_command_long_message(1, 1, cmd, 0, *ps))

    def wait(self, dest: int, typ: str, seconds: float, cond=None):
        """First ``typ`` message (sending a HEARTBEAT every 0.2 s meanwhile), or None."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.heartbeat(dest)
            poll_end = time.monotonic() + 0.2
            while time.monotonic() < poll_end:
                try:
                    data, _ = self.sock.recvfrom(65535)
                except TimeoutError:
                    continue
                for m in self.dec.parse_buffer(data) or []:
                    if m.get_type() == typ and (cond is None or cond(m)):
                        return m
        return None

    def close(self) -> None:
        self.sock.close()


def test_a_rate_ends_with_the_client_that_set_it(sim_factory):
    """Client A asks for ATTITUDE_QUATERNION (off in the GCS link's set, PX4's normal
    one) and falls silent; client B, bound to the very same address after A's peer
    timeout, gets the defaults."""
    sim = sim_factory(["--no-zenoh", "--vehicles", "1"])
    port = vehicle_ports(1, sim.offset).gcs_local
    tgt = M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
    a = _Client()
    try:
        a.command(port, M.MAV_CMD_SET_MESSAGE_INTERVAL, tgt, 100_000)
        ack = a.wait(
            port, "COMMAND_ACK", 3.0, lambda m: m.command == M.MAV_CMD_SET_MESSAGE_INTERVAL
        )
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert a.wait(port, "ATTITUDE_QUATERNION", 3.0) is not None
    finally:
        a.close()
    time.sleep(PEER_TIMEOUT_S + 1.5)  # A is silent: the link forgets it, and its rates
    b = _Client(a.port)
    try:
        b.command(port, M.MAV_CMD_GET_MESSAGE_INTERVAL, tgt)
        iv = b.wait(port, "MESSAGE_INTERVAL", 3.0, lambda m: m.message_id == tgt)
        assert iv is not None and iv.interval_us == -1
        assert b.wait(port, "ATTITUDE_QUATERNION", 1.5) is None
        assert b.wait(port, "ATTITUDE", 3.0) is not None  # the defaults still stream
    finally:
        b.close()
    assert sim.stop() == 0
