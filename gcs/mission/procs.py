"""Child processes of a mission run: start, watch, stop (also on Ctrl-C or a death)."""

from __future__ import annotations

import logging
import multiprocessing
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Protocol

from gcs.launch import forkserver
from gcs.launch.watchdog import release_dir, remove_on_death, remove_server_dir_on_death
from offboard.daemon.start_gate import GATE_ENV, gate_value
from swarm_common.logsetup import configure_logging
from swarm_common.process_life import die_with_parent

log = logging.getLogger(__name__)

class ChildProcess(Protocol):
    """What a run needs of a child process: :class:`subprocess.Popen`, or one forked from
    the preloaded server (:class:`gcs.launch.forkserver.ForkedProcess`)."""

    pid: int

    @property
    def returncode(self) -> int | None: ...

    def poll(self) -> int | None: ...

    def wait(self, timeout: float | None = None) -> int: ...

    def send_signal(self, sig: int) -> None: ...

    def kill(self) -> None: ...


@dataclass
class Child:
    name: str
    proc: ChildProcess
    log_path: Path
    log_file: IO[bytes]


class ProcessGroup:
    """Processes started by one run. ``dead()`` names any that exited unexpectedly.
    Gated children (the daemons) take one of :func:`start_slots` start-up slots
    (:mod:`offboard.daemon.start_gate`)."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.children: list[Child] = []
        self._gate: Path | None = None  # the slots' directory, made on the first gated start

    def start(
        self, name: str, argv: list[str], env: dict[str, str] | None = None,
        gated: bool = False,
    ) -> Child:
        """Start child ``name``; ``gated``: it takes a start-up slot of this group's gate
        (a daemon started as ``python -m offboard``)."""
        log_path = self.log_dir / f"{name}.log"
        f = open(log_path, "wb")  # noqa: SIM115 - closed in stop()
        full_env = dict(os.environ)
        full_env.setdefault("PYTHONUNBUFFERED", "1")
        # small-matrix numpy: BLAS worker threads only burn CPU the other processes need
        full_env.setdefault("OPENBLAS_NUM_THREADS", "1")
        full_env.setdefault("OMP_NUM_THREADS", "1")
        if env:
            full_env.update(env)
        # the runner's code, not the caller's directory's (python_entry runs with -P)
        full_env["PYTHONPATH"] = child_pythonpath(full_env.get("PYTHONPATH"))
        if gated:
            if self._gate is None:
                self._gate = Path(tempfile.mkdtemp(prefix="swarm-start-"))
                remove_on_death(self._gate)
            full_env[GATE_ENV] = gate_value(start_slots(), self._gate)
        proc: ChildProcess | None = None
        if forkserver.enabled() and forkserver.module_of(argv) is not None:
            # ``python -m MODULE``: forked from the preloaded server (gcs.launch.forkserver),
            # in its own process group too, and killed with the server, which ends with us
            try:
                remove_server_dir_on_death()  # before the server makes its socket there
                proc = forkserver.start(argv, log_path, full_env)
            except OSError as exc:  # the server could not start: an interpreter instead
                forkserver.give_up(str(exc))
        if proc is None:
            # own process group: a terminal's Ctrl-C reaches the runner only, which stops
            # the children in order; PDEATHSIG: no child outlives the runner, even after
            # kill -9
            proc = subprocess.Popen(
                argv, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env=full_env, process_group=0,
                preexec_fn=die_with_parent(signal.SIGKILL, os.getpid()),
            )
        child = Child(name, proc, log_path, f)
        self.children.append(child)
        return child

    def usage(self) -> dict[str, dict[str, float]]:
        """CPU seconds (user+sys) and peak RSS (MiB) of each live child, from /proc."""
        out: dict[str, dict[str, float]] = {}
        tick = os.sysconf("SC_CLK_TCK")
        for c in self.children:
            try:
                stat = Path(f"/proc/{c.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
                cpu = (int(stat[11]) + int(stat[12])) / tick
                rss = 0.0
                for line in Path(f"/proc/{c.proc.pid}/status").read_text().splitlines():
                    if line.startswith("VmHWM:"):
                        rss = int(line.split()[1]) / 1024.0
                out[c.name] = {"cpu_s": cpu, "peak_rss_mib": rss}
            except (OSError, IndexError, ValueError):
                continue
        return out

    def dead(self) -> list[Child]:
        return [c for c in self.children if c.proc.poll() is not None]

    def kill(self, name: str) -> None:
        for c in self.children:
            if c.name == name and c.proc.poll() is None:
                c.proc.kill()

    def stop(self, timeout: float = 5.0) -> None:
        """SIGTERM everyone, wait, SIGKILL the rest, close logs."""
        for c in self.children:
            if c.proc.poll() is None:
                try:
                    c.proc.send_signal(signal.SIGTERM)
                    c.proc.send_signal(signal.SIGCONT)  # a stopped child acts on it
                except OSError as exc:  # exited between poll() and the signal
                    log.debug("SIGTERM %s: %s", c.name, exc)
        deadline = time.monotonic() + timeout
        for c in self.children:
            remaining = max(0.0, deadline - time.monotonic())
            try:
                c.proc.wait(remaining)
            except subprocess.TimeoutExpired:
                c.proc.kill()
                c.proc.wait(2.0)
        for c in self.children:
            c.log_file.close()
        release_dir(self._gate)
        self._gate = None

    def cause(self, child: Child) -> str:
        """One line on why ``child`` exited: :func:`cause_line` of its log."""
        child.log_file.flush()
        return cause_line(child.log_path, child.proc.returncode)

    def stopped(self) -> list[Child]:
        """Live children the kernel has stopped (state T or t in /proc/PID/stat: SIGSTOP,
        Ctrl-Z, a debugger): they answer nothing, however fast the machine."""
        return [c for c in self.children
                if c.proc.poll() is None and proc_state(c.proc.pid) in STOPPED_STATES]

    def warn_stopped(self, facts: dict[str, Any], t: float) -> None:
        """Name every child newly stopped by the kernel (SIGSTOP, Ctrl-Z, a debugger) once:
        a warning with its last log lines, and ``facts["stopped_processes"]`` (name, pid,
        t_s: mission time, s). A stopped daemon is not slow: the simulator steps on
        without its answers."""
        seen: list[dict[str, Any]] = facts.setdefault("stopped_processes", [])
        for child in self.stopped():
            if any(s["name"] == child.name for s in seen):
                continue
            seen.append({"name": child.name, "pid": child.proc.pid, "t_s": round(t, 3)})
            log.warning("%s at t = %.2f s: %s", role_of(child.name), t, self.fault(child))

    def fault(self, child: Child) -> str:
        """One line naming what happened to ``child``: stopped (alive, state T), or dead
        with its signal or exit code and the cause line of its log (:func:`cause_line`),
        then its last log lines (:func:`last_lines`)."""
        child.log_file.flush()
        pid = child.proc.pid
        rc = child.proc.poll()
        if rc is None:
            state = proc_state(pid)
            if state in STOPPED_STATES:
                what = (f"{child.name} (pid {pid}) is stopped (state {state} in /proc: "
                        "SIGSTOP, Ctrl-Z or a debugger), not slow")
            else:
                what = f"{child.name} (pid {pid}) is alive (state {state}) but silent"
        else:
            what = f"{child.name} (pid {pid}) {exit_how(rc)}"
            cause = cause_line(child.log_path, rc)
            # an error line of its log; not cause_line's fallback (said above already)
            if not cause.startswith(("killed by", "exit code")):
                what += f": {cause}"
        return f"{what}; {last_lines(child.log_path)}"

    def tail(self, child: Child, lines: int = 15) -> str:
        try:
            text = child.log_path.read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join(text[-lines:])


def role_of(name: str) -> str:
    """What child ``name`` is, in words: ``the simulator (vehicle-sim)``, ``the daemon
    offboard-3``."""
    if name.startswith("offboard-"):
        return f"the daemon {name}"
    return f"the simulator ({name})" if "sim" in name else name


def stall_cause(group: ProcessGroup) -> str:
    """Why a run stalls, in one line: the stopped or dead children with their last log
    lines, or that none is stopped or dead (every process alive and running)."""
    bad = group.stopped() + group.dead()
    if not bad:
        return ("every process is alive and none is stopped (the simulator waits for an "
                "answer that does not come)")
    return "; ".join(f"{role_of(c.name)}: {group.fault(c)}" for c in bad)


# a log line that says what went wrong (the last such line is the cause of an exit)
ERROR_MARKERS = ("Error", "error", "Errno", "Exception", "in use", "cannot", "refused",
                 "denied", "failed", "FATAL")
CAUSE_MAX_CHARS = 240  # a cause is one line of the top-level message
# a program's one-line refusal on stderr (``offboard: --signing-key: ...``, exit 2)
REFUSAL = re.compile(r"^(offboard|vehicle-sim|gcs[\w ]*): ")


STOPPED_STATES = ("T", "t")  # /proc/PID/stat: stopped by a signal, stopped by a tracer
LAST_LINES = 3  # log lines quoted in a fault's one line


def proc_state(pid: int) -> str | None:
    """The state letter of process ``pid`` (field 3 of /proc/PID/stat: R running, S
    sleeping, D disk wait, T stopped, t traced, Z zombie), or None when it is gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return None


def exit_how(returncode: int) -> str:
    """``killed by SIGKILL (signal 9)`` for a negative Popen return code, else
    ``exited with code N``."""
    if returncode < 0:
        try:
            return f"killed by {signal.Signals(-returncode).name} (signal {-returncode})"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exited with code {returncode}"


def last_lines(log_path: Path, n: int = LAST_LINES) -> str:
    """``last log lines: a | b | c`` (the last ``n`` non-empty lines of ``log_path``, each
    cut to :data:`CAUSE_MAX_CHARS`), or ``its log is empty`` / ``no log``: never a bare
    heading."""
    try:
        text = log_path.read_text(errors="replace").splitlines()
    except OSError:
        return f"no log at {log_path}"
    lines = [ln.strip()[:CAUSE_MAX_CHARS] for ln in text if ln.strip()][-n:]
    if not lines:
        return f"its log {log_path} is empty"
    return f"last log lines of {log_path.name}: " + " | ".join(lines)


def cause_line(log_path: Path, returncode: int | None) -> str:
    """Why a child exited, as one line: the last line of its log that reads as an error
    (an exception, an ``OSError``'s ``[Errno 98] Address already in use``, a program's
    one-line refusal), else its signal or exit code and its log's last line."""
    try:
        lines = [ln.strip() for ln in log_path.read_text(errors="replace").splitlines()]
    except OSError:
        lines = []
    lines = [ln for ln in lines if ln and not ln.startswith(("Traceback", "File ", "^"))]
    for ln in reversed(lines):
        if any(m in ln for m in ERROR_MARKERS) or REFUSAL.match(ln):
            return ln[:CAUSE_MAX_CHARS]
    if returncode is not None and returncode < 0:
        try:
            how = f"killed by {signal.Signals(-returncode).name}"
        except ValueError:
            how = f"killed by signal {-returncode}"
    else:
        how = f"exit code {returncode}"
    return how + (f"; last log line: {lines[-1][:CAUSE_MAX_CHARS]}" if lines else
                  "; its log is empty")


# daemons that may start at once whatever the number of CPUs: a cube8 run starts its 8
# together, as it always has. Fewer slots would cost a real-time run its start: on a
# machine busy with other work, 2 slots gave the run's daemons 2 shares of the CPU
# instead of 8, and half of them were not up before a 10 s real-time run ended
MIN_START_SLOTS = 8


def start_slots() -> int:
    """Daemons allowed in their start-up at once (:mod:`offboard.daemon.start_gate`): the CPUs
    this process may run on, and at least :data:`MIN_START_SLOTS`."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cpus = os.cpu_count() or 1
    return max(MIN_START_SLOTS, cpus)


def python_entry(module: str) -> list[str]:
    """argv prefix running ``module`` with this interpreter (no reliance on PATH), in
    safe-path mode (``-P``): the caller's working directory is not put on ``sys.path``, so
    a run started inside a clone does not run the clone's packages in its children while
    the runner runs the installed ones (:func:`code_root` goes on ``PYTHONPATH`` instead)."""
    return [sys.executable, "-P", "-m", module]


def code_root() -> Path:
    """The directory the runner imported its packages from (the one holding ``gcs/``):
    first on every child's ``PYTHONPATH``, so the children import the runner's code."""
    return Path(__file__).resolve().parents[2]


def child_pythonpath(current: str | None) -> str:
    """``PYTHONPATH`` for a child: :func:`code_root` first, then ``current`` (the caller's,
    if any) without a repeat of the root."""
    root = str(code_root())
    rest = [p for p in (current or "").split(os.pathsep) if p and p != root]
    return os.pathsep.join([root, *rest])


def child_log_level() -> str:
    """This process's logging level as a child's ``configure_logging`` takes it (a level
    it does not name: warning)."""
    level = logging.getLevelName(logging.getLogger().getEffectiveLevel()).lower()
    return level if level in ("debug", "info", "warning", "error") else "warning"


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of ``workers`` fresh interpreters (``spawn``), each logging as this process does.

    Never ``fork``: a caller with threads (a test runner's, a dashboard's, Zenoh's) may hold
    a lock at the moment of the fork, and the child then waits on it for ever."""
    level = child_log_level()
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=configure_logging, initargs=(level,))
