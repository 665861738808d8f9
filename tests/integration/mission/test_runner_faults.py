"""``gcs mission run`` under faults: SIGTERM and SIGKILL of the runner leave no process
behind; a daemon's death does not abort the run; aborted runs keep their metrics."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, free_port_offset

from gcs.exit_codes import EXIT_OK, EXIT_SAFETY

pytestmark = pytest.mark.timeout(300)

GCS = [sys.executable, "-m", "gcs.cli"]


def leftovers(off: int) -> list[str]:
    """Command lines of the swarm's processes still alive (unique port offset)."""
    r = subprocess.run(["pgrep", "-af", f"(cli|-m offboard) .*--port-offset {off} "],
                       capture_output=True, text=True)
    return [ln for ln in r.stdout.splitlines() if ln.strip()]


def wait_gone(off: int, timeout: float = 5.0) -> list[str]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not leftovers(off):
            return []
        time.sleep(0.2)
    return leftovers(off)


def start_run(out: Path, off: int, duration: str = "30") -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*GCS, "mission", "run", CUBE8, "--duration", duration, "--port-offset", str(off),
         "--out", str(out)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def wait_stepping(proc: subprocess.Popen[str], past_s: float = 0.5) -> None:
    """Read the runner's progress lines until simulated time passes ``past_s``."""
    assert proc.stderr is not None
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if "s sim" in line:
            done = float(line.split("%", 1)[1].split("/", 1)[0])
            if done >= past_s:
                return
    raise AssertionError(f"runner exited (rc {proc.wait()}) before stepping:\n{''.join(seen)}")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_every_child_and_keeps_an_aborted_run(tmp_path: Path, sig: int) -> None:
    off = free_port_offset()
    out = tmp_path / "run"
    proc = start_run(out, off)
    try:
        wait_stepping(proc)
        proc.send_signal(sig)
        rc = proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert rc == (143 if sig == signal.SIGTERM else 130)
    assert wait_gone(off) == []
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["aborted"] is True and doc["run"]["abort_reason"]
    assert doc["metrics"]["collisions"] == 0
    assert (out / "series.npz").exists()


def test_kill_9_of_the_runner_leaves_no_process(tmp_path: Path) -> None:
    """PDEATHSIG: the simulator and every daemon die with the runner, so nothing flies on
    frozen data (the orphans used to live about 50 s)."""
    off = free_port_offset()
    proc = start_run(tmp_path / "run", off)
    try:
        wait_stepping(proc)
        children = [ln for ln in leftovers(off) if not ln.startswith(f"{proc.pid} ")]
        assert len(children) == 9, children  # vehicle-sim + 8 daemons
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert wait_gone(off) == []


def test_dead_daemon_does_not_abort_the_run(tmp_path: Path) -> None:
    off = free_port_offset()
    out = tmp_path / "run"
    r = subprocess.run(
        [*GCS, "mission", "run", CUBE8, "--duration", "2", "--port-offset", str(off),
         "--out", str(out), "--kill-agent", "5", "--kill-at", "0.5", "--json"],
        cwd=ROOT, capture_output=True, text=True, timeout=240,
    )
    doc = json.loads(r.stdout)
    # scored and finished: the exit status is the safety verdict's (gcs.exit_codes)
    safe = doc["metrics"]["safety_verdict"] == "safe"
    assert r.returncode == (EXIT_OK if safe else EXIT_SAFETY), r.stderr[-2000:]
    assert doc["run"]["failed_agents"] == [5]
    assert doc["aborted"] is False
    on_disk = json.loads((out / "metrics.json").read_text())
    assert on_disk["run"]["failed_agents"] == [5] and "min_distance_m" in on_disk["metrics"]
    assert leftovers(off) == []
