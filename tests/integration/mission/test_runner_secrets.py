"""Secrets never outlive a run, and the children run the runner's code (issue 42).

* ``kill -9`` of ``gcs mission run`` mid-run: its secure directory (signing key, Zenoh
  passwords) is deleted by the watchdog (:func:`gcs.launch.watchdog.remove_on_death`) and no
  child is left.
* A child started from inside another checkout imports the runner's packages, not that
  checkout's (``python -P`` and the runner's root on ``PYTHONPATH``).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, free_port_offset

import gcs
from gcs.launch import watchdog
from gcs.launch.watchdog import release_dir, remove_on_death
from gcs.mission.procs import ProcessGroup, python_entry

pytestmark = pytest.mark.timeout(180)

GONE_WITHIN_S = 5.0  # the watchdog and PDEATHSIG act at once; 5 s for a loaded machine


def _alive(pid: int) -> bool:
    """True while ``pid`` exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _children_of(pid: int) -> list[int]:
    """Pids of the live descendants of ``pid`` (from /proc): its children, theirs, ... (a
    run's simulator and daemons are children of its fork server, gcs.launch.forkserver)."""
    parent: dict[int, int] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if stat[0] != "Z":
            parent[int(d.name)] = int(stat[1])
    out: list[int] = []
    frontier = [pid]
    while frontier:
        kids = [c for c, p in parent.items() if p in frontier]
        out += kids
        frontier = kids
    return out


def _wait(cond: object, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():  # type: ignore[operator]
            return True
        time.sleep(0.1)
    return bool(cond())  # type: ignore[operator]


def test_kill_9_of_the_runner_leaves_no_secret_and_no_child(tmp_path: Path) -> None:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    off = free_port_offset()
    env = {**os.environ, "TMPDIR": str(tmp)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "gcs.cli", "mission", "run", CUBE8, "--duration", "30",
         "--port-offset", str(off), "--out", str(tmp_path / "run")],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        # the secure dir holds the key and the passwords once the daemons are started
        def ready() -> bool:
            dirs = list(tmp.glob("swarm-secure-*"))
            return bool(dirs) and any(dirs[0].iterdir()) and len(_children_of(proc.pid)) >= 3

        assert _wait(ready, 60.0), "the runner never wrote its secure dir and started"
        secure = list(tmp.glob("swarm-secure-*"))
        assert len(secure) == 1
        assert (secure[0] / "mavlink.key").exists()
        kids = _children_of(proc.pid)
        assert len(kids) >= 3  # the watchdog(s), the fork server, the simulator, daemons
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        assert _wait(lambda: not secure[0].exists(), GONE_WITHIN_S), f"{secure[0]} left"
        assert _wait(lambda: not any(_alive(k) for k in kids), GONE_WITHIN_S), (
            f"children left: {[k for k in kids if _alive(k)]}")
        # the start gate's folder and the fork server's too (gcs.launch.forkserver), each
        # removed by its own watchdog
        assert _wait(lambda: list(tmp.iterdir()) == [], GONE_WITHIN_S), list(tmp.iterdir())
    finally:
        if proc.poll() is None:
            proc.kill()


def test_release_dir_removes_now_and_ends_the_watchdog(tmp_path: Path) -> None:
    d = tmp_path / "secret"
    d.mkdir()
    (d / "k").write_text("x")
    remove_on_death(d)

    dog = watchdog._watchdogs[d]
    assert dog.poll() is None  # waiting while we live
    release_dir(d)
    assert not d.exists()
    assert dog.wait(5.0) == 0


# a dying child of the run: it keeps creating files in the folder (O_CREAT, as a daemon's
# start gate opens its slot files) for a while after the runner is gone, then ends
_WRITER = (
    "import os,sys,time\n"
    "end = time.monotonic() + float(sys.argv[2])\n"
    "i = 0\n"
    "while time.monotonic() < end:\n"
    "    try:\n"
    "        os.close(os.open(os.path.join(sys.argv[1], f'slot-{i % 8}.lock'),\n"
    "                         os.O_RDWR | os.O_CREAT, 0o600))\n"
    "    except OSError:\n"
    "        pass\n"
    "    i += 1\n"
)


def test_the_watchdog_removes_a_folder_a_dying_child_still_writes_to(tmp_path: Path) -> None:
    """The runner's end of the pipe closes (as at kill -9) while a child still creates
    entries in the folder: the watchdog removes it again until it stays gone."""
    d = tmp_path / "gate"
    d.mkdir()
    remove_on_death(d)
    dog = watchdog._watchdogs.pop(d)
    writer = subprocess.Popen([sys.executable, "-c", _WRITER, str(d), "1.5"])
    try:
        time.sleep(0.3)  # the writer is creating files
        assert dog.stdin is not None
        dog.stdin.close()  # EOF: what the runner's death gives the watchdog
        assert writer.wait(30.0) == 0
        assert dog.wait(watchdog.REMOVE_FOR_S + 30.0) == 0
        assert not d.exists(), sorted(p.name for p in d.iterdir())
    finally:
        writer.kill()
        dog.kill()


def test_a_child_runs_the_runners_code_not_the_callers_checkout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    clone = tmp_path / "clone"
    (clone / "gcs").mkdir(parents=True)
    (clone / "gcs" / "__init__.py").write_text("")
    probe = "import gcs; print(gcs.__file__)"
    monkeypatch.chdir(clone)
    monkeypatch.delenv("PYTHONPATH", raising=False)
    # the set-up shadows: a plain ``python`` started here imports the clone's gcs
    plain = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                           check=True).stdout.strip()
    assert Path(plain).resolve() == (clone / "gcs" / "__init__.py").resolve()
    group = ProcessGroup(tmp_path)
    child = group.start("probe", [*python_entry("x")[:2], "-c", probe])
    assert child.proc.wait(30) == 0
    group.stop()
    seen = Path((tmp_path / "probe.log").read_text().strip())
    assert seen.resolve() == Path(gcs.__file__).resolve()


# a client of the fork server: it asks for a daemon (the first request starts the server,
# which then imports and warms up for a second or more) and prints the server's pid
_CLIENT = (
    "import sys, threading, time\n"
    "from pathlib import Path\n"
    "from gcs.mission.procs import ProcessGroup, python_entry\n"
    "from multiprocessing import forkserver\n"
    "group = ProcessGroup(Path(sys.argv[1]))\n"
    "threading.Thread(target=group.start, daemon=True, args=('offboard-1',\n"
    "    [*python_entry('offboard'), '--scenario', sys.argv[2], '--agent', '99']),\n"
    "    kwargs={'gated': True}).start()\n"
    "end = time.monotonic() + 60.0\n"
    "while forkserver._forkserver._forkserver_pid is None and time.monotonic() < end:\n"
    "    time.sleep(0.001)\n"
    "print(forkserver._forkserver._forkserver_pid, flush=True)\n"
    "time.sleep(600)\n"
)


@pytest.mark.parametrize("after_s", [0.0, 0.3])
def test_the_fork_server_dies_with_a_runner_killed_during_its_start(
        tmp_path: Path, after_s: float) -> None:
    """``kill -9`` of the runner while its fork server is still importing and warming up
    (before ``multiprocessing`` watches the runner's pipe): the server goes at once
    (gcs.launch.preload), however far it got."""
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    client = subprocess.Popen([sys.executable, "-c", _CLIENT, str(tmp_path), CUBE8],
                              cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert client.stdout is not None
        line = client.stdout.readline()  # the client gives up after 60 s: "None"
        assert line.strip().isdecimal(), f"no fork server started: {line!r}"
        server = int(line)
        time.sleep(after_s)
        client.send_signal(signal.SIGKILL)
        client.wait(10)
        assert _wait(lambda: not _alive(server), GONE_WITHIN_S), "the fork server outlived it"
    finally:
        if client.poll() is None:
            client.kill()
