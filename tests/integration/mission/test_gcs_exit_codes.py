"""``gcs`` exit codes: 0 success, 1 a run failed once started (a child died), 2 bad input
or a busy port, 130 Ctrl-C, 143 SIGTERM; and the progress display off a terminal."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, HeldPorts, free_port_offset

from gcs.exit_codes import EXIT_OK, EXIT_SAFETY
from swarm_common.ports import vehicle_ports
from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT

pytestmark = pytest.mark.timeout(180)

GCS = [sys.executable, "-m", "gcs.cli"]


def gcs(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*GCS, *argv], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def start_gcs(*argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen([*GCS, *argv], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_for_progress(proc: subprocess.Popen[str], timeout: float = 90.0) -> list[str]:
    """stderr lines up to the first progress line past 0 % (the run is stepping)."""
    assert proc.stderr is not None
    seen: list[str] = []
    deadline = time.monotonic() + timeout
    for line in proc.stderr:
        seen.append(line)
        if " % " in line and "  0 %" not in line:
            return seen
        assert time.monotonic() < deadline, "".join(seen)
    raise AssertionError(f"gcs exited (rc {proc.wait()}) before stepping:\n{''.join(seen)}")


def leftovers(off: int) -> bytes:
    return subprocess.run(["pgrep", "-f", f"(cli|-m offboard) .*--port-offset {off} "],
                          capture_output=True).stdout.strip()


@pytest.mark.parametrize("kind", ["udp", "tcp"])
def test_busy_port_exits_2_with_one_line(tmp_path: Path, kind: str,
                                         held_ports: HeldPorts) -> None:
    off = free_port_offset()
    if kind == "udp":
        port = vehicle_ports(2, off).api_local
        assert held_ports.udp(port)
    else:
        # bound as a server binds it: free_port_offset accepts a TIME_WAIT left there by an
        # earlier test (Zenoh binds the same way); the listener makes it busy all the same
        port = DEFAULT_ZENOH_PORT + off
        assert held_ports.tcp(port)
    r = gcs("mission", "run", CUBE8, "--duration", "1", "--port-offset", str(off),
            "--out", str(tmp_path))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{kind} {port}" in lines[0] and "--port-offset" in lines[0]
    assert leftovers(off) == b""


def test_bad_log_level_is_an_argparse_error_exit_2() -> None:
    r = gcs("--log-level", "loud", "mission", "run", CUBE8, "--inproc")
    assert r.returncode == 2
    assert "--log-level" in r.stderr.strip().splitlines()[-1] and "Traceback" not in r.stderr


def test_missing_scenario_exits_2() -> None:
    r = gcs("mission", "run", str(ROOT / "no-such.toml"), "--inproc")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


def test_inproc_progress_off_a_terminal_is_a_few_plain_lines(tmp_path: Path) -> None:
    r = gcs("--log-level", "warning", "mission", "run", CUBE8, "--inproc", "--method", "none",
            "--duration", "6", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "\r" not in r.stderr
    progress = [ln for ln in r.stderr.splitlines() if " % " in ln]
    assert 2 <= len(progress) <= 12, r.stderr  # 300 steps: deciles, not a frame per step
    assert progress[-1].startswith("[none] 100 %")
    assert len(r.stderr) < 2000


def test_ctrl_c_inproc_exits_130() -> None:
    proc = start_gcs("mission", "run", CUBE8, "--inproc", "--method", "none",
                     "--duration", "600")
    try:
        wait_for_progress(proc)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted" in err.strip().splitlines()[-1] and "Traceback" not in err


@pytest.mark.slow
def test_ctrl_c_distributed_exits_130_and_stops_every_child(tmp_path: Path) -> None:
    off = free_port_offset()
    proc = start_gcs("mission", "run", CUBE8, "--duration", "60", "--port-offset", str(off),
                     "--out", str(tmp_path))
    try:
        wait_for_progress(proc)
        assert leftovers(off) != b""  # the children are running
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted" in err.strip().splitlines()[-1]
    assert leftovers(off) == b""


@pytest.mark.slow
def test_daemon_death_mid_run_is_named_and_the_run_is_scored(tmp_path: Path) -> None:
    """A daemon killed mid-run: the runner names it, the others fly on, the run ends with
    exit status of its safety verdict (0 when safe, 3 otherwise) and its metrics list the
    agent in ``failed_agents``; nothing is left running."""
    off = free_port_offset()
    proc = start_gcs("mission", "run", CUBE8, "--duration", "6", "--port-offset", str(off),
                     "--out", str(tmp_path))
    try:
        wait_for_progress(proc)
        daemon_4 = f"offboard --scenario .*--agent 4 --port-offset {off} "
        pids = subprocess.run(["pgrep", "-f", daemon_4],
                              capture_output=True, text=True).stdout.split()
        assert len(pids) == 1
        os.kill(int(pids[0]), signal.SIGKILL)
        _, err = proc.communicate(timeout=240)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "agent 4's daemon exited" in err
    doc = json.loads((tmp_path / "metrics.json").read_text())
    # scored and finished: the exit status is the safety verdict's (gcs.exit_codes); an
    # abandoned vehicle can use up a neighbour's margin, depending on when it was killed
    safe = doc["metrics"]["safety_verdict"] == "safe"
    assert proc.returncode == (EXIT_OK if safe else EXIT_SAFETY), err
    assert doc["run"]["failed_agents"] == [4]
    assert leftovers(off) == b""


def test_sigterm_mission_exits_143() -> None:
    proc = start_gcs("mission", "run", CUBE8, "--inproc", "--method", "none",
                     "--duration", "600")
    try:
        wait_for_progress(proc)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert "Traceback" not in err
