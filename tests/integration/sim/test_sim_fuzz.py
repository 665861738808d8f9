"""Fuzzing: random, mutated and hostile MAVLink input never crashes the simulator,
never puts a NaN into the state, and the vehicle keeps answering."""

from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest
from conftest import CUBE8
from pymavlink.dialects.v20 import common as M

from swarm_common.ports import vehicle_ports
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.link.endpoint import PARSE_ERRORS, MavlinkLink
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.vehicle import Vehicle

pytestmark = pytest.mark.timeout(180)

WEIRD = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1.0, -1.0, 1e38, -1e38, 1e-45, 0.5, 2.0]
COMMANDS = [
    M.MAV_CMD_COMPONENT_ARM_DISARM,
    M.MAV_CMD_DO_SET_MODE,
    M.MAV_CMD_NAV_LAND,
    M.MAV_CMD_NAV_LOITER_UNLIM,
    M.MAV_CMD_DO_FLIGHTTERMINATION,
    M.MAV_CMD_SET_MESSAGE_INTERVAL,
    M.MAV_CMD_GET_MESSAGE_INTERVAL,
    M.MAV_CMD_REQUEST_MESSAGE,
    M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    M.MAV_CMD_NAV_TAKEOFF,
    0,
    65535,
]


def raw_frame(rng: np.random.Generator, seq: int) -> bytes:
    """A CRC-correct MAVLink 2 frame of a random known message with a random payload."""
    msgid = int(rng.choice(list(M.mavlink_map)))
    cls = M.mavlink_map[msgid]
    n = int(rng.integers(0, cls.unpacker.size + 1))
    payload = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
    sysid, compid = int(rng.integers(0, 256)), int(rng.integers(0, 256))
    hdr = struct.pack(
        "<BBBBBBBHB", 0xFD, n, 0, 0, seq & 0xFF, sysid, compid, msgid & 0xFFFF, msgid >> 16
    )
    crc = M.x25crc(hdr[1:] + payload)
    crc.accumulate(bytes([cls.crc_extra]))
    return hdr + payload + struct.pack("<H", crc.crc)


def weird(rng) -> float:
    return float(rng.choice(WEIRD)) if rng.random() < 0.5 else float(rng.normal(0, 100))


def hostile_message(rng: np.random.Generator, target: int):
    """A well-formed message with hostile field values."""
    k = int(rng.integers(0, 5))
    if k == 0:
        q = [weird(rng) for _ in range(4)] if rng.random() < 0.5 else list(rng.normal(size=4))
        return M.MAVLink_set_attitude_target_message(
            int(rng.integers(0, 2**32)), target, 1, int(rng.integers(0, 256)), q,
            weird(rng), weird(rng), weird(rng), weird(rng),
        )  # fmt: skip
    if k == 1:
        cmd = int(rng.choice(COMMANDS))
        params = [weird(rng) for _ in range(7)]
        if cmd == M.MAV_CMD_DO_FLIGHTTERMINATION and rng.random() > 0.02:
            params[0] = 0.0  # keep termination rare so the rest of the machine is exercised
        return M.MAVLink_command_long_message(target, int(rng.choice([0, 1, 190])), cmd, 0, *params)
    if k == 2:
        return M.MAVLink_command_int_message(
            target, 1, int(rng.integers(0, 20)), int(rng.choice(COMMANDS)), 0, 0,
            *[weird(rng) for _ in range(4)],
            int(rng.integers(-(2**31), 2**31)), int(rng.integers(-(2**31), 2**31)), weird(rng),
        )  # fmt: skip
    if k == 3:
        return M.MAVLink_set_mode_message(
            target, int(rng.integers(0, 256)), int(rng.integers(0, 2**32))
        )
    return M.MAVLink_timesync_message(int(rng.integers(0, 2**62)), int(rng.integers(0, 2**62)))


def datagrams(seed: int, n: int, target: int):
    rng = np.random.default_rng(seed)
    enc = M.MAVLink(None, srcSystem=200, srcComponent=1)
    good = M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(enc)
    for i in range(n):
        kind = i % 6
        if kind == 0:  # random bytes
            yield rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes()
        elif kind == 1:  # bit-flipped valid frame
            b = bytearray(hostile_message(rng, target).pack(enc))
            for _ in range(int(rng.integers(1, 4))):
                j = int(rng.integers(0, len(b)))
                b[j] ^= 1 << int(rng.integers(0, 8))
            yield bytes(b)
        elif kind == 2:  # truncated valid frame, or several frames glued together
            b = hostile_message(rng, target).pack(enc)
            yield b[: int(rng.integers(1, len(b)))] if rng.random() < 0.5 else b + good + b[:5]
        elif kind == 3:  # random known message, random payload, valid CRC
            yield raw_frame(rng, i)
        else:  # well-formed hostile message
            yield hostile_message(rng, target).pack(enc)


def test_vehicle_state_machine_fuzz():
    """In-process: 20 000 hostile messages straight into a Vehicle + dynamics."""
    sc = load_scenario(CUBE8)
    dyn = SwarmDynamics(sc, held=True)
    veh = [Vehicle(a, i, dyn, AutopilotConfig()) for i, a in enumerate(sc.ids)]
    parser = M.MAVLink(None, srcSystem=1, srcComponent=1)
    parser.robust_parsing = True
    t = 0.0
    for k, data in enumerate(datagrams(11, 20000, 1)):
        try:
            msgs = parser.parse_buffer(data) or []
        except PARSE_ERRORS:  # what the simulator's link counts as garbage
            msgs = []
        parser.buf = bytearray()
        parser.buf_index = 0
        for m in msgs:
            if m.get_msgId() >= 0:
                veh[k % 2].handle(m, ("api", ("127.0.0.1", 1)), t, t)
        if k % 20 == 0:
            for v in veh:
                v.update(t)
                if v.release_requested:
                    dyn.release(v.idx)
                dyn.set_command(v.idx, *v.command(0.02))
                v.periodic(t, t)
                for msg, _ in [*v.outbox, *v.stream_out]:
                    v.pack(msg)
                v.outbox.clear()
                v.stream_out.clear()
            dyn.advance(4)
            t += 0.02
        for arr in (dyn.p, dyn.v, dyn.att, dyn.thrust, dyn.cmd_att, dyn.cmd_thrust):
            assert np.all(np.isfinite(arr)), k
        for v in veh:
            assert np.all(np.isfinite(v.sp_att)) and math.isfinite(v.sp_thrust)
    assert sum(v.ctr.setpoints_rejected for v in veh) > 100


def test_link_counts_garbage():
    off = 45_700
    link = MavlinkLink("api", 1, 14580 + off, None)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        enc = M.MAVLink(None, srcSystem=9, srcComponent=1)
        good = M.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(enc)
        foreign = M.MAVLink_command_long_message(3, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(enc)
        bad_crc = bytearray(good)
        bad_crc[-1] ^= 0xFF
        for d in (b"hello world", good[:7], bytes(bad_crc), foreign, good):
            s.sendto(d, ("127.0.0.1", 14580 + off))
        got = []
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and not got:
            got = link.receive()
            time.sleep(0.01)
        st = link.stats
        assert [m.get_type() for m in got] == ["COMMAND_LONG"]
        assert st.garbage >= 1 and st.truncated == 1 and st.bad == 1 and st.foreign == 1
        assert len(link.peers) == 1
    finally:
        s.close()
        link.close()


def test_sim_survives_udp_fuzz(sim_factory, mav_client):
    sim = sim_factory(["--no-zenoh", "--vehicles", "2"])
    c = mav_client(vehicle_ports(1, sim.offset).api_remote)
    assert c.recv("HEARTBEAT", 10, sysid=1) is not None
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    targets = [
        ("127.0.0.1", vehicle_ports(1, sim.offset).api_local),
        ("127.0.0.1", vehicle_ports(1, sim.offset).gcs_local),
        ("127.0.0.1", vehicle_ports(2, sim.offset).api_local),
    ]
    n = 0
    try:
        for k, d in enumerate(datagrams(2024, 6000, 1)):
            s.sendto(d, targets[k % 3])
            n += 1
            if k % 200 == 0:
                time.sleep(0.01)  # let it breathe: this is about robustness, not load
                c.drain()
    finally:
        s.close()
    assert n == 6000
    assert sim.proc.poll() is None, sim.text()
    # still answers: heartbeat, COMMAND_ACK, and the state is finite
    c.drain()
    assert c.recv("HEARTBEAT", 5, sysid=1) is not None
    ack = c.command(1, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, timeout=5)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    for typ in ("LOCAL_POSITION_NED", "ODOMETRY", "ATTITUDE_QUATERNION", "GLOBAL_POSITION_INT"):
        c.command(1, M.MAV_CMD_SET_MESSAGE_INTERVAL, getattr(M, f"MAVLINK_MSG_ID_{typ}"), 0)
    for _ in range(5):
        lp = c.recv("LOCAL_POSITION_NED", 5, sysid=1)
        od = c.recv("ODOMETRY", 5, sysid=1)
        aq = c.recv("ATTITUDE_QUATERNION", 5, sysid=1)
        assert lp is not None and od is not None and aq is not None
        vals = [lp.x, lp.y, lp.z, lp.vx, lp.vy, lp.vz, od.x, od.y, od.z, od.vx, od.vy, od.vz]
        vals += [*od.q, aq.q1, aq.q2, aq.q3, aq.q4]
        assert all(math.isfinite(x) for x in vals)
    assert sim.stop() == 0
    summary = sim.text().splitlines()[-1]
    assert "handler_errors=0" in summary, summary
    stats = dict(kv.split("=") for kv in summary.split("stats: ")[1].split())
    assert int(stats["garbage"]) > 100 and int(stats["bad"]) > 100
    assert int(stats["setpoints_rejected"]) > 10
