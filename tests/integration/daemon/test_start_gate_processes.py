"""Start-up slots (offboard.daemon.start_gate) between real processes: never more holders than
slots, a holder killed with SIGKILL frees its slot, and a real daemon started as
``python -m offboard`` waits for a slot before its imports and gives it back once started.

Every assertion is what ``flock`` guarantees, not a timing: a process that cannot hold a
slot has not got past it, however loaded the machine is."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, free_port_offset, stop_processes, wait_for

from offboard.daemon import start_gate
from swarm_common.zenoh_session import default_endpoint, open_session

pytestmark = pytest.mark.timeout(180)

# a holder: takes a slot, appends "in <pid> <t>", holds it HOLD_S, appends "out <pid> <t>"
HOLDER = """
import os, sys, time
from offboard.daemon import start_gate
start_gate.acquire(os.environ[start_gate.GATE_ENV])
log = sys.argv[1]
def mark(what):
    fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
    os.write(fd, f"{what} {os.getpid()} {time.monotonic()!r}\\n".encode())
    os.close(fd)
mark("in")
time.sleep(float(sys.argv[2]))
mark("out")
"""


def _holders(n: int, gate: str, log: Path, hold_s: float) -> list[subprocess.Popen[bytes]]:
    env = {**os.environ, start_gate.GATE_ENV: gate}
    return [subprocess.Popen([sys.executable, "-c", HOLDER, str(log), str(hold_s)], cwd=ROOT,
                             env=env) for _ in range(n)]


def _intervals(log: Path) -> list[tuple[float, float]]:
    got: dict[str, dict[str, float]] = {}
    for line in log.read_text().splitlines():
        what, pid, t = line.split()
        got.setdefault(pid, {})[what] = float(t)
    return [(v["in"], v["out"]) for v in got.values()]


@pytest.mark.parametrize("slots", [1, 2])
def test_never_more_holders_than_slots(tmp_path: Path, slots: int) -> None:
    log = tmp_path / "holders.log"
    procs = _holders(5, start_gate.gate_value(slots, tmp_path), log, 0.3)
    for p in procs:
        assert p.wait(120) == 0
    spans = _intervals(log)
    assert len(spans) == 5
    # at any holder's entry, how many holders were inside (itself included)
    most = max(sum(1 for a, b in spans if a <= t0 < b) for t0, _ in spans)
    assert most <= slots, spans


def test_a_killed_holder_frees_its_slot(tmp_path: Path) -> None:
    log = tmp_path / "holders.log"
    gate = start_gate.gate_value(1, tmp_path)
    (first,) = _holders(1, gate, log, 3600.0)
    try:
        assert wait_for(lambda: log.exists() and "in" in log.read_text(), 60.0)
        (second,) = _holders(1, gate, log, 0.0)
        time.sleep(1.0)
        assert log.read_text().count("in ") == 1  # the only slot is held: it waits
        os.kill(first.pid, signal.SIGKILL)
        assert second.wait(60) == 0
        assert log.read_text().count("in ") == 2
    finally:
        first.kill()
        first.wait(10)


def test_a_gated_daemon_waits_for_a_slot_and_gives_it_back_once_started(
    tmp_path: Path,
) -> None:
    off = free_port_offset(1)
    router = open_session(mode="router", listen=[default_endpoint(off)])
    gate_dir = tmp_path / "gate"
    gate_dir.mkdir()
    gate = start_gate.gate_value(1, gate_dir)
    assert start_gate.acquire(gate) is not None  # the test holds the only slot
    log = tmp_path / "daemon.log"
    with log.open("w") as out:
        daemon = subprocess.Popen(
            [sys.executable, "-m", "offboard", "--scenario", CUBE8, "--agent", "1",
             "--port-offset", str(off), "--realtime", "--zenoh-connect",
             default_endpoint(off)],
            cwd=ROOT, env={**os.environ, start_gate.GATE_ENV: gate},
            stdout=subprocess.DEVNULL, stderr=out,
        )
    try:
        time.sleep(2.0)
        # waiting in the gate, before its imports: alive, and not a line logged yet
        assert daemon.poll() is None and log.read_text() == ""
        start_gate.release()
        # it takes the slot, warms its kernels, builds its agent, gives the slot back and
        # waits for its vehicle (there is none), saying so every few seconds
        assert wait_for(lambda: "waiting for the HEARTBEAT" in log.read_text()
                        or daemon.poll() is not None, 150.0), log.read_text()[-2000:]
        assert daemon.poll() is None, log.read_text()[-2000:]
        # so the slot is free while it runs
        assert start_gate.acquire(gate, max_wait_s=0.0) is not None
        assert start_gate.holding()
    finally:
        start_gate.release()
        stop_processes([daemon], grace_s=30.0)
        router.close()


def test_a_malformed_gate_is_exit_2_and_one_line(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "offboard", "--scenario", CUBE8, "--agent", "1"], cwd=ROOT,
        env={**os.environ, start_gate.GATE_ENV: f"0:{tmp_path}"}, capture_output=True,
        text=True, timeout=60,
    )
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and start_gate.GATE_ENV in lines[0], out.stderr
