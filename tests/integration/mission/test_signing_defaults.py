"""Security defaults of ``gcs mission run`` (docs/security.md, "Defaults"): MAVLink 2
signing is on with a fresh per-run key, our own processes are never rejected, and a
stranger's unsigned commands sent to the vehicles during the run have no effect."""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from conftest import CUBE8, ROOT, free_port_offset  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from swarm_common.ports import vehicle_ports  # noqa: E402

pytestmark = pytest.mark.timeout(300)
REJECTS = ("rejected_unsigned", "rejected_bad_signature", "rejected_replay")
FORCE_DISARM = 21196.0  # MAV_CMD_COMPONENT_ARM_DISARM param2: disarm even in flight


def _run(tmp_path: Path, *extra: str) -> subprocess.Popen[str]:
    argv = [sys.executable, "-m", "gcs.cli", "mission", "run", CUBE8, "--out",
            str(tmp_path / "run"), "--json", "--processes", "2", *extra]  # fmt: skip
    return subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip


def test_default_run_is_signed_and_our_daemons_are_never_rejected(tmp_path: Path) -> None:
    proc = _run(tmp_path, "--duration", "2", "--port-offset", str(free_port_offset()))
    out, err = proc.communicate(timeout=240)
    assert proc.returncode == 0, err[-2000:]
    doc = json.loads(out)
    run = doc["run"]
    assert run["mavlink_signing"] == "per-run key"
    sim = run["simulator"]
    assert sim["signing"] is True
    assert {k: sim["links"][k] for k in REJECTS} == dict.fromkeys(REJECTS, 0)
    assert doc["metrics"]["collisions"] == 0
    assert run["failed_agents"] == []
    sim_log = (tmp_path / "run" / "vehicle-sim.log").read_text()
    assert not re.search(r"rejected \d+ unsigned", sim_log)  # no "rejected" STATUSTEXT


def test_unsigned_stranger_cannot_command_a_default_run(tmp_path: Path) -> None:
    """While a default (signed, lockstep) run flies, a stranger sends unsigned arm, forced
    disarm, flight termination and LAND commands to every vehicle's GCS and API port: it
    receives nothing, the simulator rejects and reports the frames, and none of them has
    an effect (no disarm, termination or mode change to LAND; the run completes)."""
    offset = free_port_offset()
    sc_ids = range(1, 9)
    proc = _run(tmp_path, "--duration", "4", "--port-offset", str(offset))
    mav = mavlink.MAVLink(None, srcSystem=77, srcComponent=190)
    frames: list[tuple[int, bytes]] = []
    for i in sc_ids:
        cmds = [
            (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0),
            (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, FORCE_DISARM),
            (mavlink.MAV_CMD_DO_FLIGHTTERMINATION, 1.0, 0.0),
            (mavlink.MAV_CMD_NAV_LAND, 0.0, 0.0),
        ]
        for cmd, p1, p2 in cmds:
            buf = mav.command_long_encode(i, 1, cmd, 0, p1, p2, 0, 0, 0, 0, 0).pack(mav)
            ports = vehicle_ports(i, offset)
            frames += [(ports.gcs_local, bytes(buf)), (ports.api_local, bytes(buf))]
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.bind(("127.0.0.1", 0))
    stranger.setblocking(False)
    received = 0
    try:
        deadline = time.monotonic() + 240
        while proc.poll() is None and time.monotonic() < deadline:
            for port, buf in frames:
                stranger.sendto(buf, ("127.0.0.1", port))
            time.sleep(0.2)
            try:
                while True:
                    received += len(stranger.recv(65535))
            except (BlockingIOError, ConnectionRefusedError):
                pass
        out, err = proc.communicate(timeout=30)
    finally:
        stranger.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err[-2000:]
    assert received == 0  # not even an acknowledgement
    doc = json.loads(out)
    sim = doc["run"]["simulator"]
    assert sim["signing"] is True
    assert sim["links"]["rejected_unsigned"] > 0
    assert "commands_unsigned_refused=0" in sim["summary"]  # no unsigned GCS link by default
    sim_log = (tmp_path / "run" / "vehicle-sim.log").read_text()
    assert re.search(r"rejected [1-9]\d* unsigned", sim_log), sim_log[-2000:]
    for effect in ("disarmed", "FLIGHT TERMINATION", "LAND"):
        assert effect not in sim_log, effect
    assert doc["metrics"]["collisions"] == 0
    assert doc["run"]["failed_agents"] == []
