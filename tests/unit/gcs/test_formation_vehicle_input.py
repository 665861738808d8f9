"""The formation vehicle refuses what the leaders could not fly, on MAVLink, and sends
nothing for it (gcs.formation.vehicle): real UDP on 127.0.0.1, no swarm (the truth is
handed in)."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from gcs.formation.vehicle import FORMATION_SYSID, FormationVehicle
from swarm_common import frames
from swarm_common.scenario.mission_check import mission_shape
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics import geo

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def fv():
    sc = load_scenario(ROOT / "scenarios" / "course8.toml")
    sent: list = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    v = FormationVehicle(sc, sent.append, port)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(0.05)
    enc = M.MAVLink(None, srcSystem=245, srcComponent=190)
    p = mission_shape(sc)
    yield v, client, enc, port, sent, p
    client.close()
    v.close()


def exchange(v, client, enc, port, p, msg, want: str, t: float = 12.0):
    """Send ``msg``, serve, return the first reply of type ``want`` (or None)."""
    client.sendto(msg.pack(enc), ("127.0.0.1", port))
    dec = M.MAVLink(None)
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        v.serve(t, p, np.zeros_like(p))
        try:
            data = client.recv(4096)
        except TimeoutError:
            continue
        for m in dec.parse_buffer(data) or []:
            if m.get_type() == want:
                return m
    return None


def item(seq, e, n, u, command=M.MAV_CMD_NAV_WAYPOINT, param2=0.0):
    lat, lon = geo.latlon_e7(AutopilotConfig(), frames.enu_to_ned(np.array([e, n, u])))
    return M.MAVLink_mission_item_int_message(
        FORMATION_SYSID, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, command, 0, 1, 0.0,
        param2, 0.0, float("nan"), lat, lon, u, M.MAV_MISSION_TYPE_MISSION)


def upload(fv, items) -> int | None:
    v, client, enc, port, _, p = fv
    m = M.MAVLink_mission_count_message(FORMATION_SYSID, 1, len(items),
                                        M.MAV_MISSION_TYPE_MISSION)
    reply = exchange(v, client, enc, port, p, m, "MISSION_REQUEST_INT")
    for it in items:
        kind = "MISSION_ACK" if it.seq == len(items) - 1 else "MISSION_REQUEST_INT"
        reply = exchange(v, client, enc, port, p, it, kind)
        if reply is not None and reply.get_type() == "MISSION_ACK":
            return int(reply.type)
    return None if reply is None else getattr(reply, "type", None)


def test_bad_uploads_are_refused_and_send_nothing(fv):
    v, client, enc, port, sent, p = fv
    huge = M.MAVLink_mission_count_message(FORMATION_SYSID, 1, 65535,  # the most a count holds
                                           M.MAV_MISSION_TYPE_MISSION)
    ack = exchange(v, client, enc, port, p, huge, "MISSION_ACK")
    assert ack is not None and ack.type == M.MAV_MISSION_NO_SPACE
    assert upload(fv, [item(0, 6.0, 2.0, 0.3)]) == M.MAV_MISSION_INVALID  # under the floor
    assert upload(fv, [item(0, 6.0, 2.0, 4.0, command=M.MAV_CMD_NAV_LAND)]) == \
        M.MAV_MISSION_INVALID  # not a formation waypoint
    assert upload(fv, [item(0, 6.0, 2.0, 4.0, command=M.MAV_CMD_DO_CHANGE_SPEED, param2=99.0),
                       item(1, 6.0, 2.0, 4.0)]) == M.MAV_MISSION_INVALID  # too fast
    assert v.transfer.stores[M.MAV_MISSION_TYPE_MISSION] == []  # nothing kept
    start = M.MAVLink_command_long_message(FORMATION_SYSID, 1, M.MAV_CMD_MISSION_START, 0,
                                           0, 0, 0, 0, 0, 0, 0)
    ack = exchange(v, client, enc, port, p, start, "COMMAND_ACK")
    assert ack is not None and ack.result == M.MAV_RESULT_DENIED  # no mission to start
    assert sent == []


def test_bad_commands_are_denied_and_send_nothing(fv):
    v, client, enc, port, sent, p = fv
    speed = M.MAVLink_command_long_message(FORMATION_SYSID, 1, M.MAV_CMD_DO_CHANGE_SPEED, 0,
                                           1, 50.0, -1, 0, 0, 0, 0)
    ack = exchange(v, client, enc, port, p, speed, "COMMAND_ACK")
    assert ack is not None and ack.result == M.MAV_RESULT_DENIED
    nan_goto = M.MAVLink_command_long_message(FORMATION_SYSID, 1, M.MAV_CMD_DO_REPOSITION, 0,
                                              -1, 0, 0, float("nan"), float("nan"), 8.0, 5.0)
    ack = exchange(v, client, enc, port, p, nan_goto, "COMMAND_ACK")
    assert ack is not None and ack.result == M.MAV_RESULT_DENIED
    scale = M.MAVLink_param_set_message(FORMATION_SYSID, 1, b"FORM_SCALE", 0.05,
                                        M.MAV_PARAM_TYPE_REAL32)
    val = exchange(v, client, enc, port, p, scale, "PARAM_VALUE")
    assert val is not None and val.param_value == pytest.approx(1.0)  # refused: unchanged
    client.sendto(b"\xfd\x09garbage-not-mavlink", ("127.0.0.1", port))
    v.serve(12.0, p, np.zeros_like(p))
    assert v.bad_frames >= 1
    assert sent == []
    # and a good go-to is sent, once checked
    lat, lon = geo.latlon_e7(AutopilotConfig(), frames.enu_to_ned(np.array([6.0, 2.0, 4.0])))
    goto = M.MAVLink_command_int_message(FORMATION_SYSID, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                         M.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0, 0,
                                         float("nan"), lat, lon, 4.0)
    ack = exchange(v, client, enc, port, p, goto, "COMMAND_ACK")
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    assert [c.kind for c in sent] == ["mission"] and sent[0].at_s == pytest.approx(13.0)
