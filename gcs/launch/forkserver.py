"""A run's children forked from a preloaded server instead of each starting an interpreter.

Each child of a run (the simulator, every daemon) is its own process running its program
as ``python -m MODULE ARGS`` would (:data:`ENTRIES`: the function the module's
``__main__`` code calls, with ``sys.argv`` set, its exit status the process's), in its own
process group, with its own log file, environment and working directory. Only its beginning
differs. A fresh interpreter spends about 2 s of CPU on importing numpy, numba, Zenoh and
pymavlink and on loading the compiled kernels before its first step; a cube8 run starts
nine such processes, 20 s of CPU on a 2-core machine (docs/performance.md). Python's
``multiprocessing`` *forkserver* starts one server process per runner that imports those
modules and loads the kernels once (:mod:`gcs.launch.preload`), and forks each child from
it in milliseconds.

Why it is safe to fork there: the server is a fresh interpreter (spawned, not forked from
the runner), it runs one thread, and it opens no Zenoh session and no socket before it
forks; each child opens its own. What the child inherits is only imported code and loaded
machine code.

What the runner sees (:class:`ForkedProcess`) has the part of ``subprocess.Popen`` that
:class:`gcs.mission.procs.ProcessGroup` uses: ``pid``, ``poll``, ``wait``,
``send_signal``, ``kill``, ``returncode`` (negative: killed by that signal). A child's
parent is the server; it gets SIGKILL when the server dies, and the server exits when the
runner does, however the runner ends (the pipe it watches closes). ``ps`` and ``pgrep
-f`` show the child's own command line (``setproctitle``).

``SWARM_LAUNCH=exec`` in the runner's environment turns it off: every child then starts
as its own interpreter (``subprocess``), as before.
"""

from __future__ import annotations

import importlib
import io
import logging
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
from multiprocessing.connection import wait as mp_wait
from pathlib import Path

from swarm_common.process_life import die_with_parent

LAUNCH_ENV = "SWARM_LAUNCH"  # "exec": no fork server (module docstring)
PRELOAD = "gcs.launch.preload"
PARENT_ENV = "SWARM_FORKSERVER_PARENT"  # the runner's pid, for the server's start
# ``python -m MODULE`` -> (module, function) that its ``if __name__ == "__main__"`` runs
ENTRIES = {
    "offboard": ("offboard.__main__", "gated_main"),
    "offboard.cli": ("offboard.cli", "main"),
    "vehicle_sim.cli": ("vehicle_sim.cli", "main"),
}

_context: multiprocessing.context.ForkServerContext | None = None
log = logging.getLogger(__name__)


_failed: str | None = None  # why the server could not start in this process, if it failed


def enabled() -> bool:
    """Whether children are forked from the server: Linux, not ``SWARM_LAUNCH=exec``, and
    the server has not failed to start in this process (:func:`give_up`)."""
    return (sys.platform.startswith("linux") and os.environ.get(LAUNCH_ENV, "") != "exec"
            and _failed is None)


def give_up(why: str) -> None:
    """The server could not start (for one, ``multiprocessing`` puts its socket under
    ``$TMPDIR``, and a socket's path has at most 107 bytes): say so once, and start every
    later child of this process as an interpreter of its own."""
    global _failed
    if _failed is None:
        _failed = why
        log.warning("fork server unavailable (%s): each child starts its own interpreter "
                    "(slower start-up)", why)


def module_of(argv: list[str]) -> str | None:
    """``MODULE`` when ``argv`` runs ``python -m MODULE`` with this interpreter (the form of
    :func:`gcs.mission.procs.python_entry`) and MODULE is one of :data:`ENTRIES`, else None
    (started with ``subprocess``)."""
    if (len(argv) >= 4 and argv[0] == sys.executable and argv[1:3] == ["-P", "-m"]
            and argv[3] in ENTRIES):
        return argv[3]
    return None


def _context_started() -> multiprocessing.context.ForkServerContext:
    global _context
    if _context is None:
        ctx = multiprocessing.get_context("forkserver")
        # the server checks that we are still its parent (gcs.launch.preload)
        os.environ[PARENT_ENV] = str(os.getpid())
        ctx.set_forkserver_preload([PRELOAD])
        _context = ctx
    return _context


class ForkedProcess:
    """A child forked from the server, seen as :class:`subprocess.Popen` sees one.

    Thread-safe as ``Popen`` is: ``multiprocessing`` reads a child's exit status from a
    pipe, once; two threads reading it at once (a thread following a child's log while
    another waits for it) left one of them at the pipe's end, and that one's status read as
    255. Every read here is under one lock, and the child is taken off ``multiprocessing``'s
    own list of children, whose clean-up on each start would read it from yet another
    thread."""

    def __init__(self, proc: multiprocessing.process.BaseProcess, argv: list[str]) -> None:
        self._proc = proc
        self.args = argv
        pid = proc.pid
        assert pid is not None  # started
        self.pid: int = pid
        self._lock = threading.Lock()
        self._rc: int | None = None
        children = getattr(multiprocessing.process, "_children", None)
        if isinstance(children, set):
            children.discard(proc)

    @property
    def returncode(self) -> int | None:
        return self._rc

    def poll(self) -> int | None:
        with self._lock:
            if self._rc is None:
                self._rc = self._proc.exitcode
            return self._rc

    def wait(self, timeout: float | None = None) -> int:
        if self.poll() is None:
            mp_wait([self._proc.sentinel], timeout)  # readable once it has exited
        rc = self.poll()
        if rc is None:
            raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        return rc

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def start(argv: list[str], log_path: Path, env: dict[str, str],
          cwd: Path | None = None) -> ForkedProcess:
    """Fork ``python -m MODULE ARGS`` (``argv``, see :func:`module_of`) from the server,
    its stdout and stderr appended to ``log_path``, with exactly ``env`` as its
    environment, in ``cwd`` (default: this process's working directory)."""
    module = module_of(argv)
    if module is None:
        raise ValueError(f"not a 'python -P -m MODULE' command line of {sorted(ENTRIES)}: "
                         f"{argv[:4]}")
    ctx = _context_started()
    proc = ctx.Process(
        target=_child, args=(module, argv, str(log_path), env, str(cwd or os.getcwd())),
        name=module, daemon=True,
    )
    proc.start()
    return ForkedProcess(proc, argv)


def _child(module: str, argv: list[str], log_path: str, env: dict[str, str], cwd: str) -> None:
    """In the forked child: become the program ``argv`` names, then run it."""
    os.setpgid(0, 0)  # its own process group: a terminal's Ctrl-C reaches the runner only
    # the server's death, however it dies, is ours too
    die_with_parent(signal.SIGKILL, os.getppid())()
    _let_go_of_the_server()
    fd = os.open(log_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), write_through=True,
                                  line_buffering=True)
    sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), write_through=True,
                                  line_buffering=True, errors="backslashreplace")
    try:  # before the environment changes: setproctitle takes over its memory on first use
        from setproctitle import setproctitle
    except ImportError:  # pragma: no cover - a dependency; without it ps shows the server
        pass
    else:
        setproctitle(" ".join(argv))
    os.environ.clear()
    os.environ.update(env)
    os.chdir(cwd)
    sys.argv = [module, *argv[4:]]
    where, name = ENTRIES[module]
    rc = getattr(importlib.import_module(where), name)()
    from swarm_common.process_life import exit_now

    exit_now(rc)  # as the module's ``__main__`` code does


def _let_go_of_the_server() -> None:
    """Close what ``multiprocessing`` hands each forked child so that it could start
    children of its own through the same server: the write ends of the server's "a client
    is alive" pipe and of the resource tracker's pipe. A child holding the first keeps the
    server alive after the runner dies, and the server keeps the child alive (PDEATHSIG):
    no run's child must outlive its runner (tests/integration/mission/test_runner_faults.py).
    Our children start no ``multiprocessing`` children."""
    from multiprocessing import forkserver as mp_forkserver
    from multiprocessing import resource_tracker

    server = getattr(mp_forkserver, "_forkserver", None)
    tracker = getattr(resource_tracker, "_resource_tracker", None)
    for owner, attr in ((server, "_forkserver_alive_fd"), (tracker, "_fd")):
        fd = getattr(owner, attr, None)
        if isinstance(fd, int):
            try:
                os.close(fd)
            except OSError:
                pass
            setattr(owner, attr, None)
