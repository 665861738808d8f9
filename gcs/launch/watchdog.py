"""Folders removed however this process ends, kill -9 included: a run's secrets and the
fork server's socket folder.

:func:`remove_on_death` starts a watchdog process per folder; :func:`release_dir` removes a
folder now and lets its watchdog go; :func:`remove_server_dir_on_death` covers
``multiprocessing``'s temporary folder, where the fork server (:mod:`.forkserver`) puts its
socket.
"""

from __future__ import annotations

import logging
import multiprocessing.util
import shutil
import subprocess
import sys
from pathlib import Path

log = logging.getLogger(__name__)


# the watchdog of :func:`remove_on_death`: stdlib only, isolated mode (-I: no PYTHON*
# variables, no user site, no working directory on sys.path). It ignores the terminal's
# signals, waits for EOF on stdin (the runner's end of the pipe closes however the runner
# ends, kill -9 included) and removes the paths given. It removes them again while they
# come back, for up to REMOVE_FOR_S: a child of the run still dying may create an entry
# between rmtree's listing and its last rmdir (a daemon in its start-up opens its start
# gate's slot files with O_CREAT, offboard.daemon.start_gate), and rmtree then leaves the
# folder. Found under two suites' load: a kill -9 left the start gate's folder behind.
REMOVE_FOR_S = 30.0
_WATCHDOG = (
    "import os,shutil,signal,sys,time\n"
    "for s in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM):\n"
    "    signal.signal(s, signal.SIG_IGN)\n"
    "try:\n"
    "    while os.read(0, 64):\n"
    "        pass\n"
    "finally:\n"
    f"    end = time.monotonic() + {REMOVE_FOR_S!r}\n"
    "    while True:\n"
    "        for p in sys.argv[1:]:\n"
    "            shutil.rmtree(p, ignore_errors=True)\n"
    "        left = [p for p in sys.argv[1:] if os.path.lexists(p)]\n"
    "        if not left or time.monotonic() > end:\n"
    "            break\n"
    "        time.sleep(0.05)\n"
)
_watchdogs: dict[Path, subprocess.Popen[bytes]] = {}


def remove_on_death(path: Path) -> None:
    """Start a watchdog process that deletes ``path`` (a per-run secrets directory) when
    this process ends, however it ends: it holds the read end of a pipe whose only write
    end this process keeps, and EOF on it (the kernel closes the write end at our exit,
    SIGKILL included) makes it remove the directory and exit. In its own session, so a
    terminal's Ctrl-C does not end it first. :func:`release_dir` removes the directory
    now and lets the watchdog go."""
    proc = subprocess.Popen(
        [sys.executable, "-I", "-c", _WATCHDOG, str(path)], stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )
    _watchdogs[path] = proc


def remove_server_dir_on_death() -> None:
    """The fork server's socket lives in ``multiprocessing``'s temporary folder of this
    process, removed at a normal exit only: a watchdog removes it however we end (once)."""
    path = Path(multiprocessing.util.get_temp_dir())
    if path not in _watchdogs:
        remove_on_death(path)


def release_dir(path: Path | None) -> None:
    """Delete ``path`` now and end its :func:`remove_on_death` watchdog (if any)."""
    if path is None:
        return
    shutil.rmtree(path, ignore_errors=True)
    proc = _watchdogs.pop(path, None)
    if proc is not None and proc.stdin is not None:
        proc.stdin.close()  # EOF: the watchdog removes (nothing left) and exits
        try:
            proc.wait(5.0)
        except subprocess.TimeoutExpired:
            log.warning("the watchdog of %s did not exit", path)
