"""Telemetry that real clients get from a real ``vehicle-sim`` over 127.0.0.1.

* a plain pymavlink client (udpout to a vehicle's own GCS port, as MAVProxy does) gets
  ATTITUDE at PX4's normal 15 Hz: counted over >= 3 s of wall time, asserted >= 10 Hz;
* the same client, unsigned and read-only, on the GCS link of a signed simulator run
  with ``--unsigned-gcs-link``;
* unmodified MAVProxy (``mavproxy.py``, commands on stdin) lists mission, fence and rally
  and reports the counts the vehicle holds;
* eight vehicles stream to one GCS port: a client there gets every vehicle's
  MISSION_COUNT for mission, fence and rally, no ODOMETRY, and its socket drops nothing
  (the kernel's ``drops`` column of /proc/net/udp for the socket's inode).

Only design guarantees are asserted, with generous timeouts (a loaded 2-core machine).
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common.ports import vehicle_ports

pytestmark = pytest.mark.timeout(180)
LOCALHOST = "127.0.0.1"
MIN_ATTITUDE_HZ = 10.0  # against PX4's nominal 15 Hz
WINDOW_S = 4.0  # wall time over which ATTITUDE frames are counted
HOME = (47.397742, 8.545594)
MAVPROXY = Path(sys.executable).with_name("mavproxy.py")
GROUND8 = Path(__file__).resolve().parents[3] / "scenarios" / "ground8.toml"
TYPES = (M.MAV_MISSION_TYPE_MISSION, M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY)


class Client:
    """A pymavlink client on an ephemeral UDP port (or ``port``), no signing."""

    def __init__(self, port: int = 0, rcvbuf: int | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if rcvbuf is not None:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.bind((LOCALHOST, port))
        self.sock.settimeout(0.05)
        self.enc = M.MAVLink(None, srcSystem=255, srcComponent=190)
        self.dec = M.MAVLink(None)
        self.dec.robust_parsing = True
        self.bytes_in = 0

    def send(self, port: int, msg) -> None:
        self.sock.sendto(msg.pack(self.enc), (LOCALHOST, port))

    def heartbeat(self, port: int) -> None:
        self.send(port, M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, 8, 0, 0, 0, 3))

    def poll(self, seconds: float) -> list:
        out: list = []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                data = self.sock.recv(65535)
            except TimeoutError:
                continue
            self.bytes_in += len(data)
            out += [m for m in self.dec.parse_buffer(data) or [] if m.get_msgId() >= 0]
        return out

    def wait(self, typ: str, seconds: float, cond=None, keepalive: int | None = None):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if keepalive is not None:
                self.heartbeat(keepalive)
            for m in self.poll(0.3):
                if m.get_type() == typ and (cond is None or cond(m)):
                    return m
        return None

    def close(self) -> None:
        self.sock.close()


def _attitude_hz(cli: Client, port: int) -> float:
    """ATTITUDE frames per second of wall time, counted over WINDOW_S once they flow
    (a HEARTBEAT a second keeps the client a live peer)."""
    assert cli.wait("ATTITUDE", 20.0, keepalive=port) is not None
    n, start = 0, time.monotonic()
    next_hb = start
    while (now := time.monotonic()) - start < WINDOW_S:
        if now >= next_hb:
            cli.heartbeat(port)
            next_hb = now + 1.0
        n += sum(m.get_type() == "ATTITUDE" for m in cli.poll(0.1))
    return n / (time.monotonic() - start)


def test_plain_client_on_a_vehicles_own_port_gets_attitude(sim_factory) -> None:
    sim = sim_factory(["--no-zenoh", "--vehicles", "1"])
    port = vehicle_ports(1, sim.offset).gcs_local
    cli = Client()
    try:
        assert _attitude_hz(cli, port) >= MIN_ATTITUDE_HZ
    finally:
        cli.close()
    assert sim.stop() == 0


def test_unsigned_read_only_client_gets_full_rate(sim_factory, tmp_path) -> None:
    from swarm_common.signing import generate_key

    key = tmp_path / "swarm.key"
    generate_key(key)
    sim = sim_factory(["--no-zenoh", "--vehicles", "1", "--signing-key", str(key),
                       "--unsigned-gcs-link"])  # fmt: skip
    port = vehicle_ports(1, sim.offset).gcs_local
    cli = Client()
    try:
        assert _attitude_hz(cli, port) >= MIN_ATTITUDE_HZ
        # still read-only: arming is refused
        cli.send(port, M.MAVLink_command_long_message(
            1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))  # fmt: skip
        ack = cli.wait("COMMAND_ACK", 5.0, lambda m: m.command == M.MAV_CMD_COMPONENT_ARM_DISARM)
        assert ack is not None and ack.result == M.MAV_RESULT_DENIED
    finally:
        cli.close()
    assert sim.stop() == 0


def _item(seq: int, mt: int, cmd: int, lat: float, lon: float):
    return M.MAVLink_mission_item_int_message(
        1, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1, 0, 0, 0, 0,
        int(lat * 1e7), int(lon * 1e7), 10.0, mt,
    )  # fmt: skip


def _upload(cli: Client, port: int, mt: int, items: list) -> None:
    """The MAVLink mission upload protocol (MISSION_COUNT, requests, items, ACK)."""
    cli.send(port, M.MAVLink_mission_count_message(1, 1, len(items), mt))
    end = time.monotonic() + 20.0
    while time.monotonic() < end:
        for m in cli.poll(0.2):
            if m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                cli.send(port, items[m.seq])
            elif m.get_type() == "MISSION_ACK" and m.mission_type == mt:
                assert m.type == M.MAV_MISSION_ACCEPTED, m
                return
    raise AssertionError(f"upload of mission type {mt}: no MISSION_ACK")


def _count(cli: Client, port: int, mt: int, sysid: int = 1) -> int | None:
    cli.send(port, M.MAVLink_mission_request_list_message(sysid, 1, mt))
    got = cli.wait("MISSION_COUNT", 5.0,
                   lambda m: m.get_srcSystem() == sysid and m.mission_type == mt)  # fmt: skip
    if got is not None:  # end the download the way a client does
        cli.send(port, M.MAVLink_mission_ack_message(sysid, 1, 0, mt))
    return None if got is None else int(got.count)


def _mavproxy(port: int, state_dir: Path, commands: list[str], expect: list[str]) -> str:
    """Run unmodified MAVProxy on udpout:PORT, type ``commands`` once the vehicle is
    online and return its output once every ``expect`` text appeared (or 60 s)."""
    proc = subprocess.Popen(
        [sys.executable, str(MAVPROXY), f"--master=udpout:{LOCALHOST}:{port}",
         f"--state-basedir={state_dir}", "--default-modules=wp,fence,rally,mode,param,arm,cmdlong",
         # MAVProxy asks for 4 Hz streams by default (REQUEST_DATA_STREAM), which the
         # vehicle honours; -1 asks for nothing, so the vehicle's own set is what is measured
         "--streamrate=-1"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        bufsize=1, cwd=state_dir, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    out: list[str] = []
    reader = threading.Thread(target=lambda: out.extend(proc.stdout or []), daemon=True)
    reader.start()
    try:
        end = time.monotonic() + 60.0
        while time.monotonic() < end and "online system" not in "".join(out):
            time.sleep(0.2)
        assert proc.stdin is not None
        for c in commands:
            proc.stdin.write(c + "\n")
            proc.stdin.flush()
            time.sleep(1.0)
        while time.monotonic() < end and not all(e in "".join(out) for e in expect):
            time.sleep(0.2)
    finally:
        proc.kill()
        proc.wait(10)
        reader.join(5)
    return "".join(out)


def test_mavproxy_lists_mission_fence_and_rally(sim_factory, tmp_path) -> None:
    sim = sim_factory(["--no-zenoh", "--vehicles", "1"])
    port = vehicle_ports(1, sim.offset).gcs_local
    cli = Client()
    lat, lon = HOME
    try:
        cli.heartbeat(port)
        wps = [_item(i, 0, M.MAV_CMD_NAV_WAYPOINT, lat + 1e-4 * i, lon) for i in range(3)]
        _upload(cli, port, M.MAV_MISSION_TYPE_MISSION, wps)
        rally = [_item(i, 2, M.MAV_CMD_NAV_RALLY_POINT, lat, lon + 1e-4 * i) for i in range(2)]
        _upload(cli, port, M.MAV_MISSION_TYPE_RALLY, rally)
        n_fence = _count(cli, port, M.MAV_MISSION_TYPE_FENCE)
        assert n_fence is not None
    finally:
        cli.close()
    expect = ["Requesting 3 waypoints", f"Requesting {n_fence} fence items",
              "Requesting 2 rally items"]  # fmt: skip
    text = _mavproxy(port, tmp_path, ["wp list", "fence list", "rally list"], expect)
    for e in expect:
        assert e in text, text[-3000:]
    assert sim.stop() == 0
    # what MAVProxy itself received, from its own telemetry log (pymavlink's tlog reader)
    assert _tlog_rate(tmp_path / "mav.tlog", "ATTITUDE") >= MIN_ATTITUDE_HZ


def _tlog_rate(path: Path, typ: str) -> float:
    """Messages of ``typ`` per second in a MAVLink telemetry log, over the span between
    its first and last one (the tlog's own receive timestamps)."""
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(path))
    stamps = []
    while (m := log.recv_match(type=typ)) is not None:
        stamps.append(m._timestamp)
    assert len(stamps) > 10, f"{len(stamps)} {typ} in {path}"
    return (len(stamps) - 1) / (stamps[-1] - stamps[0])


def _udp_drops(sock: socket.socket) -> int:
    """The kernel's drop count of ``sock`` (/proc/net/udp, matched by inode)."""
    inode = os.fstat(sock.fileno()).st_ino
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        cols = line.split()
        if int(cols[9]) == inode:
            return int(cols[12])
    raise AssertionError(f"socket inode {inode} not in /proc/net/udp")


@pytest.mark.skipif(not Path("/proc/net/udp").exists(), reason="needs Linux /proc/net/udp")
def test_eight_vehicles_on_one_gcs_port(sim_factory) -> None:
    sim = sim_factory(["--no-zenoh", "--vehicles", "8"])
    gcs_port = vehicle_ports(1, sim.offset).gcs_remote
    cli = Client(gcs_port)  # the shared GCS port, default socket buffer
    counts: dict[tuple[int, int], int] = {}
    try:
        kinds: set[str] = set()
        t0, b0 = time.monotonic(), cli.bytes_in
        kinds |= {m.get_type() for m in cli.poll(3.0)}
        rate = (cli.bytes_in - b0) / (time.monotonic() - t0)
        for sysid in range(1, 9):
            port = vehicle_ports(sysid, sim.offset).gcs_local
            for mt in TYPES:
                n = None
                for _ in range(3):  # a reply lost under load is asked again
                    n = _count(cli, port, mt, sysid)
                    if n is not None:
                        break
                assert n is not None, (sysid, mt)
                counts[(sysid, mt)] = n
        drops = _udp_drops(cli.sock)
    finally:
        cli.close()
    assert len(counts) == 8 * len(TYPES)
    assert "ODOMETRY" not in kinds and "ATTITUDE" in kinds  # PX4's normal set there
    # the normal set is ~1.5 kB/s a vehicle; the old 50 Hz ODOMETRY alone was ~12 kB/s
    assert rate < 8 * 5_000, rate
    assert drops == 0
    assert sim.stop() == 0


def test_mavproxy_takeoff_climbs_to_the_minimum(sim_factory, tmp_path) -> None:
    """MAVProxy's ``takeoff 5`` is COMMAND_LONG NAV_TAKEOFF with p7 = 5 m AMSL, far under
    home; PX4 raises it to home + MIS_TAKEOFF_ALT (docs/px4/modes.md, "Take-off altitude").
    A ground start (ground8): the vehicle stands on its pad."""
    sim = sim_factory(["--no-zenoh", "--vehicles", "1"], scenario=str(GROUND8))
    port = vehicle_ports(1, sim.offset).gcs_local
    text = _mavproxy(port, tmp_path, ["arm throttle", "takeoff 5"],
                     ["minimum takeoff altitude"])
    assert "minimum takeoff altitude" in text, text[-3000:]
    cli = Client()
    try:
        mis = None
        cli.heartbeat(port)
        cli.send(port, M.MAVLink_param_request_read_message(1, 1, b"MIS_TAKEOFF_ALT", -1))
        got = cli.wait("PARAM_VALUE", 10.0, lambda m: m.param_id == "MIS_TAKEOFF_ALT",
                       keepalive=port)  # fmt: skip
        assert got is not None
        mis = float(got.param_value)

        def settled(m) -> bool:  # at the take-off altitude, no longer climbing
            return abs(m.relative_alt / 1000.0 - mis) < 0.3 and abs(m.vz) < 20

        seen: list[tuple[float, float]] = []

        def watch(m) -> bool:
            seen.append((m.relative_alt / 1000.0, m.vz / 100.0))
            return settled(m)

        pos = cli.wait("GLOBAL_POSITION_INT", 30.0, watch, keepalive=port)
        assert pos is not None, f"never settled at {mis} m above home: {seen[::10]}"
    finally:
        cli.close()
    assert sim.stop() == 0
