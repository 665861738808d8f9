"""Per-link stream sets, per-peer schedules and the per-peer byte budget (no simulator
process: schedules sampled on a simulated wall clock, one real UDP socket for the link).

Rates are measured by counting what ``due`` returns over a long simulated window with
irregular call times (jitter up to 4 ms, as a busy loop sees); tolerances are stated per
assertion.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from gcs.dashboard.link_tracker import LinkTracker
from gcs.dashboard.mavlink_gcs import POSITION_STREAM_HZ, STREAM_REQUEST_RETRY_S, MavlinkGcs
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot import telemetry
from vehicle_sim.autopilot.config import DEFAULT_RATES, GCS_RATES, AutopilotConfig
from vehicle_sim.autopilot.streams import PeerStreams
from vehicle_sim.link.endpoint import BUDGET_BURST_BYTES, BUDGET_BYTES_PER_S, MavlinkLink
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
ATT, ODOM, LPN = (
    M.MAVLINK_MSG_ID_ATTITUDE,
    M.MAVLINK_MSG_ID_ODOMETRY,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
)
PEER = ("gcs", ("127.0.0.1", 40000))
LOCALHOST = "127.0.0.1"


def _count(s: PeerStreams, seconds: float, seed: int = 1) -> dict[tuple, int]:
    """(destination, message id) -> number of times due over ``seconds`` of jittery calls."""
    rng = np.random.default_rng(seed)
    counts: dict[tuple, int] = {}
    t = 100.0
    end = t + seconds
    while t < end:
        for key, mid in s.due(t):
            counts[(key, mid)] = counts.get((key, mid), 0) + 1
        t += 0.001 + float(rng.uniform(0.0, 0.004))
    return counts


def test_sets_hold_only_messages_the_simulator_builds() -> None:
    for rates in (DEFAULT_RATES, GCS_RATES):
        assert set(rates) <= set(telemetry.BUILDERS)
    # PX4 MAVLINK_MODE_NORMAL values (mavlink_main.cpp), and nothing at 50 Hz there
    assert GCS_RATES[ATT] == 15.0 and GCS_RATES[LPN] == 1.0
    assert GCS_RATES[M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT] == 5.0
    assert GCS_RATES[M.MAVLINK_MSG_ID_VFR_HUD] == 4.0
    assert GCS_RATES.get(ODOM, 0.0) == 0.0
    assert max(GCS_RATES.values()) <= 15.0


def test_each_link_streams_its_own_set() -> None:
    s = PeerStreams(DEFAULT_RATES, 50.0)
    seconds = 20.0
    c = _count(s, seconds)
    api, gcs = ("api", None), ("gcs", None)
    # phase-keeping schedule: at most one frame off the nominal count over the window
    assert abs(c[(api, ODOM)] - 50.0 * seconds) <= 1
    assert (gcs, ODOM) not in c  # no 50 Hz ODOMETRY on the shared GCS port
    assert abs(c[(gcs, ATT)] - 15.0 * seconds) <= 1
    assert abs(c[(gcs, LPN)] - 1.0 * seconds) <= 1
    assert abs(c[(api, LPN)] - DEFAULT_RATES[LPN] * seconds) <= 1
    assert (gcs, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION) not in c
    # both links know every stream, so either may be asked for any of them
    for mid in set(DEFAULT_RATES) | set(GCS_RATES):
        assert mid in s


def test_a_requested_rate_is_delivered_to_that_peer_only() -> None:
    s = PeerStreams(DEFAULT_RATES, 50.0)
    sched = s.for_peer(PEER, create=True)
    assert sched.interval_us(ATT) == 66_667  # the GCS set is its start, not the API one
    sched.set_interval(ODOM, 20_000, 100.0)  # ODOMETRY at 50 Hz on the GCS link
    sched.set_interval(LPN, 100_000, 100.0)
    seconds = 20.0
    c = _count(s, seconds, seed=2)
    assert abs(c[(PEER, ODOM)] - 50.0 * seconds) <= 1
    assert abs(c[(PEER, LPN)] - 10.0 * seconds) <= 1
    assert abs(c[(PEER, ATT)] - 15.0 * seconds) <= 1
    assert (("gcs", None), ODOM) not in c  # everyone else on the link: still none


def test_periodic_builds_once_and_addresses_each_link() -> None:
    v = Vehicle(1, 0, SwarmDynamics(load_scenario(CUBE8), held=True), AutopilotConfig())
    v.periodic(50.0, 1.0)
    keys = {(k, m.get_msgId()) for m, k in v.stream_out}
    assert (("api", None), ODOM) in keys and (("gcs", None), ODOM) not in keys
    assert (("api", None), ATT) in keys and (("gcs", None), ATT) in keys
    atts = [m for m, _ in v.stream_out if m.get_msgId() == ATT]
    assert len(atts) == 2 and atts[0] is atts[1]  # built once for both links


@pytest.fixture
def link_and_client():
    link = MavlinkLink("gcs", 1, 0, None, faults=None)
    link.port = link.sock.getsockname()[1]
    cli = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    cli.bind((LOCALHOST, 0))
    yield link, cli
    cli.close()
    link.close()


def _speak(link: MavlinkLink, cli: socket.socket, now: float) -> tuple[str, int]:
    mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, 8, 0, 0, 0, 3).pack(mav)
    cli.sendto(hb, (LOCALHOST, link.port))
    for _ in range(200):  # the datagram is on loopback: a few ms at most
        if link.receive(now):
            break
        time.sleep(0.005)
    addr = cli.getsockname()
    assert addr in link.peers
    return addr


def test_budget_is_a_token_bucket_in_bytes(link_and_client) -> None:
    link, cli = link_and_client
    addr = _speak(link, cli, 0.0)
    # demand 200 kB/s (200 B every ms) for 4 s, within the peer timeout
    size, dt, seconds = 200, 0.001, 4.0
    sent = 0
    for k in range(int(seconds / dt)):
        if link.stream_allowed(addr, size, k * dt):
            sent += size
    expected = BUDGET_BURST_BYTES + BUDGET_BYTES_PER_S * (seconds - dt)
    assert abs(sent - expected) <= 2 * size  # the bucket: burst + rate x time, to a frame
    assert link.stats.throttled > 0


def test_ordinary_ground_station_traffic_never_throttled(link_and_client) -> None:
    link, cli = link_and_client
    addr = _speak(link, cli, 0.0)
    # PX4's normal set (~35 frames/s) plus ODOMETRY and ATTITUDE asked at 100 Hz each:
    # 235 frames/s of the largest frame (ODOMETRY, 244 B with header) is 57 kB/s < budget
    per_s, size = 235, 244
    t = 0.0
    for k in range(int(4.0 * per_s)):
        t = k / per_s
        assert link.stream_allowed(addr, size, t)
    assert link.stats.throttled == 0


def test_budget_needs_a_speaking_peer_and_spares_the_default_remote(link_and_client) -> None:
    link, cli = link_and_client
    addr = _speak(link, cli, 0.0)
    assert link.stream_allowed(addr, 100, link.peer_timeout - 0.01)
    assert not link.stream_allowed(addr, 100, link.peer_timeout + 0.01)  # silent too long
    link.default_remote = ("127.0.0.1", 1)
    assert all(link.stream_allowed(link.default_remote, 60_000, 0.0) for _ in range(100))
    # HEARTBEAT keeps an exhausted peer alive once per second
    addr = _speak(link, cli, 10.0)
    while link.stream_allowed(addr, 1000, 10.0):
        pass
    assert link.stream_allowed(addr, 21, 10.0, liveness=True)
    assert not link.stream_allowed(addr, 10_000, 10.0, liveness=True)


def test_link_tracker_attitude_euler_matches_the_quaternion() -> None:
    """ATTITUDE (PX4's GCS set) gives the same orientation as ATTITUDE_QUATERNION."""
    v = Vehicle(1, 0, SwarmDynamics(load_scenario(CUBE8), held=True), AutopilotConfig())
    rng = np.random.default_rng(3)
    enc = M.MAVLink(None, srcSystem=1, srcComponent=1)
    for _ in range(20):
        r, p, y = rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(-3.1, 3.1)
        v.dyn.att[0] = [r, p, y]
        tr = LinkTracker(lambda: 0.0, 255, 190)
        tr.feed(telemetry.attitude(v, 0.0).pack(enc), ("127.0.0.1", 1))
        q_e = np.array(tr.vehicles()[1].q_ned)
        tr.feed(telemetry.attitude_quaternion(v, 0.0).pack(enc), ("127.0.0.1", 1))
        q_q = np.array(tr.vehicles()[1].q_ned)
        # float32 on the wire: 1e-5 in each component, sign of the quaternion free
        assert min(np.abs(q_e - q_q).max(), np.abs(q_e + q_q).max()) < 1e-5


def test_dashboard_asks_for_position_only_when_stale() -> None:
    now = [0.0]
    gcs = MavlinkGcs(port=0, clock=lambda: now[0])
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((LOCALHOST, 0))
    veh = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    veh.bind((LOCALHOST, 0))
    veh.settimeout(0.5)
    gcs.sock = sock  # no reader thread: ticks driven here
    enc = M.MAVLink(None, srcSystem=1, srcComponent=1)
    addr = veh.getsockname()

    def feed(msg) -> None:
        gcs.feed(msg.pack(enc), addr)

    def commands() -> list:
        out = []
        veh.settimeout(0.05)
        while True:
            try:
                data = veh.recv(65535)
            except TimeoutError:
                return out
            out += [m for m in M.MAVLink(None).parse_buffer(data) or []
                    if m.get_type() == "COMMAND_LONG"]  # fmt: skip

    try:
        hb = M.MAVLink_heartbeat_message(2, 12, 1, 0, 4, 3)
        lpn = M.MAVLink_local_position_ned_message(0, 1.0, 2.0, -3.0, 0, 0, 0)
        for k in range(10):  # 10 Hz positions: never asked
            now[0] = k * 0.1
            feed(hb)
            feed(lpn)
            gcs.tick(now[0])
        assert commands() == []
        now[0] = 2.0  # 1 Hz positions (PX4's normal set): asked once, then not for a while
        feed(hb)
        gcs.tick(now[0])
        (cmd,) = commands()
        assert cmd.command == M.MAV_CMD_SET_MESSAGE_INTERVAL and cmd.param1 == LPN
        assert cmd.param2 == pytest.approx(1e6 / POSITION_STREAM_HZ)
        now[0] = 2.0 + STREAM_REQUEST_RETRY_S / 2
        feed(hb)
        gcs.tick(now[0])
        assert commands() == []
        now[0] = 2.0 + STREAM_REQUEST_RETRY_S + 0.1  # still stale: asked again
        feed(hb)
        gcs.tick(now[0])
        assert len(commands()) == 1
    finally:
        gcs.sock = None
        sock.close()
        veh.close()
