"""A child's fault is named for what it is (issue 42): stopped (state T), killed by a
signal, exited with a code, each with its last log lines; never a bare heading."""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

from gcs.mission.procs import (
    ProcessGroup,
    exit_how,
    last_lines,
    proc_state,
    role_of,
    stall_cause,
)

TALK = "import sys,time\nfor i in range(5): print('line', i, flush=True)\ntime.sleep(60)"


def _started(group: ProcessGroup, name: str) -> None:
    child = group.start(name, [sys.executable, "-c", TALK])
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and "line 4" not in child.log_path.read_text():
        time.sleep(0.05)


def test_a_stopped_child_is_named_stopped_with_its_last_lines(tmp_path: Path) -> None:
    group = ProcessGroup(tmp_path)
    try:
        _started(group, "offboard-3")
        child = group.children[0]
        assert group.stopped() == []
        child.proc.send_signal(signal.SIGSTOP)
        deadline = time.monotonic() + 5.0
        while proc_state(child.proc.pid) != "T" and time.monotonic() < deadline:
            time.sleep(0.02)
        assert group.stopped() == [child]
        fault = group.fault(child)
        assert "offboard-3" in fault and "is stopped (state T" in fault
        assert fault.endswith("last log lines of offboard-3.log: line 2 | line 3 | line 4")
        assert "too slow" not in stall_cause(group)
        assert stall_cause(group).startswith("the daemon offboard-3: offboard-3 (pid")
    finally:
        group.stop()  # SIGTERM stays pending on a stopped process: stop() kills it


def test_a_killed_child_is_named_with_its_signal_and_last_lines(tmp_path: Path) -> None:
    group = ProcessGroup(tmp_path)
    try:
        _started(group, "vehicle-sim")
        child = group.children[0]
        child.proc.kill()
        child.proc.wait(5.0)
        fault = group.fault(child)
        assert "vehicle-sim" in fault and "killed by SIGKILL (signal 9)" in fault
        assert fault.endswith("line 2 | line 3 | line 4")
        assert role_of("vehicle-sim") == "the simulator (vehicle-sim)"
        assert stall_cause(group).startswith("the simulator (vehicle-sim): vehicle-sim")
    finally:
        group.stop()


def test_nothing_stopped_or_dead_is_said_so() -> None:
    group = ProcessGroup(Path("/nonexistent"))
    assert "none is stopped" in stall_cause(group)


def test_last_lines_is_never_a_bare_heading(tmp_path: Path) -> None:
    empty = tmp_path / "a.log"
    empty.write_text("\n\n")
    assert last_lines(empty) == f"its log {empty} is empty"
    assert last_lines(tmp_path / "none.log").startswith("no log at ")
    assert exit_how(-15) == "killed by SIGTERM (signal 15)"
    assert exit_how(3) == "exited with code 3"
    assert proc_state(2**22 + 7) is None  # above pid_max's default: no such process
