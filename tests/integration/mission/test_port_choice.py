"""Free ports chosen by the run itself (no ``--port-offset``) and a forced offset on a busy
port (exit 2 before anything starts, one line naming the port), with real processes."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, HeldPorts, _claim_offset, free_port_offset

from swarm_common.ports import vehicle_ports
from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT


def gcs(*args: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def leftovers(off: int) -> bytes:
    return subprocess.run(["pgrep", "-f", f"(cli|-m offboard) .*--port-offset {off} "],
                          capture_output=True).stdout.strip()


def test_without_an_offset_the_run_chooses_free_ports(tmp_path: Path,
                                                      held_ports: HeldPorts) -> None:
    """Offset 0's agent-1 API port (UDP 14540) and Zenoh router port (TCP 7447) held: the
    run takes the next block, 1000 (claimed against the other tests, which then leave it
    alone), and flies."""
    deadline = time.monotonic() + 120
    while not _claim_offset(1000):  # another test flies at 1000: wait for its end
        assert time.monotonic() < deadline, "offset 1000 stayed claimed"
        time.sleep(1.0)
    # held here, or by another program (False): busy all the same
    held_ports.udp(vehicle_ports(1, 0).api_remote)
    held_ports.tcp(DEFAULT_ZENOH_PORT)
    r = gcs("mission", "run", CUBE8, "--method", "none", "--duration", "1", "--processes", "2",
            "--out", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr[-3000:]
    chosen = re.findall(r"port offset (\d+) chosen: at offset 0, (.+) was in use", r.stderr)
    assert len(chosen) == 1, r.stderr[-3000:]
    off, first_busy = int(chosen[0][0]), chosen[0][1]
    assert off >= 1000 and off % 1000 == 0
    assert first_busy == "tcp 7447 (127.0.0.1, Zenoh router)"  # the first port probed
    assert json.loads(r.stdout)["run"]["failed_agents"] == []
    assert (tmp_path / "metrics.json").exists()
    assert leftovers(off) == b""


@pytest.mark.parametrize("cmd", ["run", "compare"])
def test_a_forced_busy_offset_exits_2_before_anything_starts(
    tmp_path: Path, held_ports: HeldPorts, cmd: str
) -> None:
    off = free_port_offset()
    port = vehicle_ports(1, off).api_remote
    assert held_ports.udp(port)
    extra = ["--method", "none"] if cmd == "run" else []
    t0 = time.monotonic()
    r = gcs("mission", cmd, CUBE8, *extra, "--duration", "1", "--port-offset", str(off),
            "--out", str(tmp_path / "out"), timeout=60)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"gcs mission {cmd}: udp {port} (127.0.0.1, agent 1 API port) "
                               "is in use"), lines[0]
    assert "--port-offset" in lines[0]
    assert not (tmp_path / "out").exists()  # nothing started, nothing written
    assert time.monotonic() - t0 < 30  # no child was waited for
    assert leftovers(off) == b""
