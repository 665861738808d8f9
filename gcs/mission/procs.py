"""Child processes of a mission run: start, watch, stop (also on Ctrl-C or a death)."""

from __future__ import annotations

import ctypes
import logging
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from offboard.daemon.start_gate import GATE_ENV, gate_value

log = logging.getLogger(__name__)

PR_SET_PDEATHSIG = 1  # linux/prctl.h
_LIBC = ctypes.CDLL(None, use_errno=True) if sys.platform.startswith("linux") else None


def _die_with_parent(parent_pid: int) -> Callable[[], None]:
    """``preexec_fn``: the child gets SIGKILL when the runner's thread that started it
    dies, however it dies (kill -9 included); if the runner is already gone, exit now.
    Only async-signal-safe work here (a prctl call and getppid)."""
    prctl = None if _LIBC is None else _LIBC.prctl

    def setup() -> None:
        if prctl is not None:
            prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        if os.getppid() != parent_pid:
            os._exit(1)

    return setup


@dataclass
class Child:
    name: str
    proc: subprocess.Popen[bytes]
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
        if gated:
            if self._gate is None:
                self._gate = Path(tempfile.mkdtemp(prefix="swarm-start-"))
            full_env[GATE_ENV] = gate_value(start_slots(), self._gate)
        # own process group: a terminal's Ctrl-C reaches the runner only, which stops the
        # children in order; PDEATHSIG: no child outlives the runner, even after kill -9
        proc = subprocess.Popen(
            argv, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=full_env,
            process_group=0, preexec_fn=_die_with_parent(os.getpid()),
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
        if self._gate is not None:
            shutil.rmtree(self._gate, ignore_errors=True)
            self._gate = None

    def cause(self, child: Child) -> str:
        """One line on why ``child`` exited: :func:`cause_line` of its log."""
        child.log_file.flush()
        return cause_line(child.log_path, child.proc.returncode)

    def tail(self, child: Child, lines: int = 15) -> str:
        try:
            text = child.log_path.read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join(text[-lines:])


# a log line that says what went wrong (the last such line is the cause of an exit)
ERROR_MARKERS = ("Error", "error", "Errno", "Exception", "in use", "cannot", "refused",
                 "denied", "failed", "FATAL")
CAUSE_MAX_CHARS = 240  # a cause is one line of the top-level message
# a program's one-line refusal on stderr (``offboard: --signing-key: ...``, exit 2)
REFUSAL = re.compile(r"^(offboard|vehicle-sim|gcs[\w ]*): ")


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
    """argv prefix running ``module`` with this interpreter (no reliance on PATH)."""
    return [sys.executable, "-m", module]
