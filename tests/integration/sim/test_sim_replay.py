"""Replayed and reflected signed frames (issue 42; docs/security.md "Replayed and reflected
frames"): a stranger without the key binds the ground-station port 14550+offset and the
API port of a vehicle that has no daemon, records what a signed ``vehicle-sim`` (two
vehicles) and a signed daemon link (vehicle 1's, :class:`VehicleLink`, locked to the
simulator) send there, and sends every recorded datagram back from another socket to
every port of the simulator and to the daemon's port. Nothing comes back to it, and the
simulator counts every replayed frame as a replay (its ``stats:`` line and its
"rejected ..." STATUSTEXT report)."""

from __future__ import annotations

import logging
import re
import time

import pytest
from pymavlink.dialects.v20 import common as M
from udp_capture import LOCALHOST, drain, udp_socket

from offboard.daemon.mavlink.link import VehicleLink
from swarm_common.ports import vehicle_ports
from swarm_common.signing import frame_stream, generate_key

pytestmark = pytest.mark.timeout(120)

CAPTURE_S = 1.5  # s of recording
LISTEN_S = 2.5  # s the stranger listens after replaying (the issue asks >= 2 s)
REPORT_RE = re.compile(r"rejected (\d+) unsigned (\d+) badsig (\d+) replay")


def _frames(datagram: bytes) -> list[bytes]:
    """The whole MAVLink 2 frames of one datagram (every one the simulator sends is signed)."""
    out, i = [], 0
    while i + 12 <= len(datagram) and datagram[i] == 0xFD:
        n = 10 + datagram[i + 1] + 2 + (13 if datagram[i + 2] & 1 else 0)
        out.append(datagram[i : i + n])
        i += n
    assert i == len(datagram), "not a sequence of MAVLink 2 frames"
    return out


def _stats(text: str) -> dict[str, int]:
    line = text.splitlines()[-1]
    assert "stats: " in line, line
    return {k: int(v) for k, v in (kv.split("=") for kv in line.split("stats: ")[1].split())}


def test_replayed_signed_frames_get_nothing_back(sim_factory, tmp_path, caplog) -> None:
    caplog.set_level(logging.WARNING, logger="offboard.daemon.link_guard")
    path = tmp_path / "swarm.key"
    key = generate_key(path)
    sim = sim_factory(["--no-zenoh", "--vehicles", "2", "--signing-key", str(path)])
    p1, p2 = vehicle_ports(1, sim.offset), vehicle_ports(2, sim.offset)
    gcs_port = udp_socket(p1.gcs_remote)  # 14550+offset: nothing binds it in a mission run
    api2 = udp_socket(p2.api_remote)  # vehicle 2's daemon port, no daemon there
    daemon = VehicleLink(f"udpin:{LOCALHOST}:{p1.api_remote}", 1, 50.0, lockstep=False,
                         signing_key=key)  # fmt: skip
    stranger = udp_socket()
    try:
        assert daemon.wait_lock(20.0, lambda: False, 5.0), sim.text()
        captured: list[bytes] = []
        end = time.monotonic() + CAPTURE_S
        while time.monotonic() < end:  # the daemon runs; its HEARTBEAT is forwarded
            daemon.send_heartbeat()
            daemon.poll(0.02)
            captured += drain(gcs_port) + drain(api2)
        frames = [f for d in captured for f in _frames(d)]
        streams = {frame_stream(f)[0] for f in frames}  # type: ignore[index]
        assert all(frame_stream(f) is not None for f in frames)  # all signed
        assert (0, 1, 1) in streams or (1, 1, 1) in streams  # vehicle 1's own frames
        assert any(s[1:] == (2, 1) for s in streams)  # vehicle 2's
        assert any(s[1:] == (1, M.MAV_COMP_ID_ONBOARD_COMPUTER) for s in streams), streams
        sim_ports = [p1.api_local, p1.gcs_local, p2.api_local, p2.gcs_local]
        daemon_drops = daemon.drops.total
        for port in [*sim_ports, p1.api_remote]:
            for i, d in enumerate(captured):
                stranger.sendto(d, (LOCALHOST, port))
                if i % 16 == 15:  # paced: no datagram lost in a full receive buffer
                    daemon.poll(0.0)
                    time.sleep(0.002)
        got = 0
        end = time.monotonic() + LISTEN_S
        while time.monotonic() < end:
            daemon.poll(0.02)
            daemon.send_heartbeat()
            got += sum(len(d) for d in drain(stranger))
        assert got == 0  # 0 bytes back from any port, over LISTEN_S
        assert daemon.locked and daemon.peer != stranger.getsockname()
        # the daemon drops the stranger's datagrams unparsed (its log says so)
        assert daemon.drops.counts.get("foreign address", 0) == len(captured)
        assert daemon.drops.total - daemon_drops == len(captured)
        assert "foreign address" in caplog.text
        # the simulator's own report, "rejected U unsigned B badsig R replay", to the GCS
        report = None
        end = time.monotonic() + 8.0
        while report is None and time.monotonic() < end:
            for d in drain(gcs_port):
                for m in M.MAVLink(None).parse_buffer(d) or []:
                    if m.get_type() == "STATUSTEXT" and REPORT_RE.match(m.text):
                        report = REPORT_RE.match(m.text)
            time.sleep(0.05)
        assert report is not None
        assert int(report.group(1)) == 0 and int(report.group(2)) == 0
        assert int(report.group(3)) > 0
    finally:
        daemon.close()
        for s in (gcs_port, api2, stranger):
            s.close()
    assert sim.stop() == 0
    st = _stats(sim.text())
    # every replayed frame, at each of the four simulator ports, counted as a replay
    assert st["rejected_replay"] == 4 * len(frames), (st, len(frames))
    assert st["rejected_unsigned"] == 0 and st["rejected_bad_signature"] == 0
    assert st["handler_errors"] == 0
