"""A run's children forked from the preloaded server (gcs.launch.forkserver) are processes
of their own: their program's exit status, their own argv in /proc, their own process
group and environment, a signal's death reported as Popen reports it; and
``SWARM_LAUNCH=exec`` starts them as interpreters instead."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, free_port_offset

from gcs.launch.forkserver import LAUNCH_ENV, ForkedProcess
from gcs.mission.procs import ProcessGroup, python_entry
from offboard.daemon.start_gate import GATE_ENV

pytestmark = pytest.mark.timeout(120)


def _wait_log(path: Path, text: str, timeout: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in path.read_text(errors="replace"):
            return True
        time.sleep(0.05)
    return False


def test_a_forked_daemon_refusing_its_flags_exits_2_with_its_one_line(tmp_path: Path) -> None:
    group = ProcessGroup(tmp_path)
    try:
        child = group.start("offboard-1", [*python_entry("offboard"), "--scenario", CUBE8,
                                           "--agent", "99"], gated=True)
        assert isinstance(child.proc, ForkedProcess)
        assert child.proc.wait(60.0) == 2
        lines = [ln for ln in child.log_path.read_text().splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("offboard: "), lines
        assert "99" in lines[0]
    finally:
        group.stop()


def test_a_forked_simulator_is_its_own_process_and_dies_by_its_signal(tmp_path: Path) -> None:
    off = free_port_offset()
    argv = [*python_entry("vehicle_sim.cli"), "--scenario", CUBE8, "--no-zenoh",
            "--port-offset", str(off)]
    group = ProcessGroup(tmp_path)
    try:
        child = group.start("vehicle-sim", argv)
        assert isinstance(child.proc, ForkedProcess)
        assert _wait_log(child.log_path, "port map"), child.log_path.read_text()
        pid = child.proc.pid
        assert pid != os.getpid() and child.proc.poll() is None
        # its own command line (ps, pgrep -f) and process group
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().decode()
        assert f"-m vehicle_sim.cli --scenario {CUBE8} --no-zenoh --port-offset {off}" in cmdline
        assert os.getpgid(pid) == pid
        child.proc.send_signal(signal.SIGKILL)
        assert child.proc.wait(10.0) == -signal.SIGKILL
        assert "killed by SIGKILL" in group.fault(child)
    finally:
        group.stop()


def test_a_forked_child_runs_with_the_environment_it_was_given(tmp_path: Path) -> None:
    """The daemon's entry reads its start gate from the environment before anything else
    (offboard.__main__): a malformed value given to this child only is refused."""
    group = ProcessGroup(tmp_path)
    try:
        child = group.start("offboard-1", [*python_entry("offboard"), "--scenario", CUBE8,
                                           "--agent", "1"], env={GATE_ENV: "no-such-gate"})
        assert isinstance(child.proc, ForkedProcess)
        assert child.proc.wait(60.0) == 2
        assert f"offboard: ${GATE_ENV}: " in child.log_path.read_text()
        assert GATE_ENV not in os.environ  # this process's own is untouched
    finally:
        group.stop()


def test_swarm_launch_exec_starts_an_interpreter(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(LAUNCH_ENV, "exec")
    group = ProcessGroup(tmp_path)
    try:
        child = group.start("offboard-1", [*python_entry("offboard"), "--scenario", CUBE8,
                                           "--agent", "99"])
        assert isinstance(child.proc, subprocess.Popen)
        assert child.proc.wait(60.0) == 2
        assert "offboard: " in child.log_path.read_text()
    finally:
        group.stop()


PROBE = """
import sys
import threading
from pathlib import Path
from gcs.mission.procs import ProcessGroup, python_entry
group = ProcessGroup(Path(sys.argv[1]))
child = group.start("offboard-1", [*python_entry("offboard"), "--scenario", sys.argv[2],
                                   "--agent", "99"])
print(type(child.proc).__name__, child.proc.wait(60.0), flush=True)
group.stop()
"""


def test_a_server_that_cannot_start_gives_interpreters_and_one_warning(tmp_path: Path) -> None:
    """multiprocessing puts the server's socket under $TMPDIR; past a socket path's 107
    bytes it cannot bind: the run says so once and starts its children as interpreters."""
    deep = tmp_path / ("t" * 100)
    deep.mkdir()
    r = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path), CUBE8], cwd=ROOT,
                       env={**os.environ, "TMPDIR": str(deep)}, capture_output=True,
                       text=True, timeout=120)
    assert r.stdout.split() == ["Popen", "2"], (r.stdout, r.stderr)
    assert r.stderr.count("fork server unavailable") == 1, r.stderr
    assert "AF_UNIX path too long" in r.stderr


def test_every_thread_reads_the_same_exit_status(tmp_path: Path) -> None:
    """A child's exit status is read once from multiprocessing's pipe: threads polling it
    while another waits (a log follower and a stop) must all get the real status, not the
    255 that a second read at the pipe's end gave."""
    group = ProcessGroup(tmp_path)
    try:
        for n in range(3):
            child = group.start(f"offboard-{n}", [*python_entry("offboard"), "--scenario",
                                                  CUBE8, "--agent", "99"])
            seen: list[int | None] = []
            stop = threading.Event()

            def hammer(proc=child.proc, stop=stop, seen=seen) -> None:
                while not stop.is_set():
                    rc = proc.poll()
                    if rc is not None:
                        seen.append(rc)
                        return

            threads = [threading.Thread(target=hammer) for _ in range(4)]
            for t in threads:
                t.start()
            try:
                assert child.proc.wait(60.0) == 2
                for t in threads:  # each ends once it has read the status, however late
                    t.join(30.0)
            finally:
                stop.set()  # only a safety net: a thread stopped here has read nothing
                for t in threads:
                    t.join(10.0)
            assert seen == [2] * len(threads) and child.proc.returncode == 2
    finally:
        group.stop()
