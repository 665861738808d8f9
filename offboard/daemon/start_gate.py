"""Start-up slots: at most K daemon processes of one run in their CPU-heavy start-up at once.

A daemon's start-up is about 3 s of CPU on the 2-core machine (the imports, numpy, numba
and Zenoh among them, then the kernels' warm-up, :mod:`offboard.daemon.warmup`). A run that starts
64 daemons on 2 cores at once gives the simulator, started just before them, about 1/65 of
the machine for a minute and a half: its vehicles' HEARTBEATs stop for longer than the
daemons' ``vehicle_lost_timeout`` and the daemons that were ready first exit ("vehicle
heartbeat lost"), so the run cannot start (docs/performance.md, twentieth round).

The runner (:class:`gcs.mission.procs.ProcessGroup`) names a directory of K lock files in
``$OFFBOARD_START_GATE`` (``K:DIRECTORY``). ``python -m offboard`` takes one of them
(``flock``, waiting while all K are held) before it imports anything heavy, and
:func:`offboard.cli.run_daemons` gives it back once the kernels are warm and the daemons
built, just before the first pass of the main loop. The kernel releases a lock when its
holder exits, however it exits, so a daemon that dies in its start-up frees its slot. A
daemon that waited :data:`MAX_WAIT_S` starts without a slot (saying so): the gate may slow
a start, never stop it. Without the variable (a daemon on a companion computer, started
by hand or by systemd) nothing changes.

Standard library only: this runs before the heavy imports it gates.
"""

from __future__ import annotations

import fcntl
import os
import sys
import time
from pathlib import Path

GATE_ENV = "OFFBOARD_START_GATE"
MAX_SLOTS = 1024
MAX_WAIT_S = 300.0  # then start without a slot
POLL_S = 0.05  # s between tries while every slot is held

_held: int | None = None  # the file descriptor of the slot this process holds


def gate_value(slots: int, directory: Path) -> str:
    """The ``$OFFBOARD_START_GATE`` value naming ``slots`` slots in ``directory``."""
    return f"{int(slots)}:{directory}"


def parse_gate(value: str) -> tuple[int, Path]:
    """``K:DIRECTORY`` -> (K, directory); ValueError (one line) unless 1 ≤ K ≤ MAX_SLOTS
    and DIRECTORY is an existing directory."""
    count, sep, directory = value.partition(":")
    if not sep or not count.isascii() or not count.isdigit():
        raise ValueError(f"{value!r}: expected K:DIRECTORY, K a number of slots")
    slots = int(count)
    if not 1 <= slots <= MAX_SLOTS:
        raise ValueError(f"{slots} slots: must be 1..{MAX_SLOTS}")
    path = Path(directory)
    if not path.is_dir():
        raise ValueError(f"{directory!r} is not a directory")
    return slots, path


def _open_slots(slots: int, directory: Path) -> list[int]:
    """Descriptors of the gate's ``slots`` lock files (created if missing)."""
    flags = os.O_RDWR | os.O_CREAT | os.O_CLOEXEC
    fds: list[int] = []
    try:
        for i in range(slots):
            fds.append(os.open(directory / f"slot-{i}.lock", flags, 0o600))
    except OSError:
        for fd in fds:
            os.close(fd)
        raise
    return fds


def _lock_one(fds: list[int]) -> int | None:
    """The first of ``fds`` this process could lock now; None if all are held."""
    for fd in fds:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            continue
        return fd
    return None


def acquire(value: str | None, max_wait_s: float = MAX_WAIT_S) -> float | None:
    """Take a slot of the gate ``value`` (``$OFFBOARD_START_GATE``; None or empty: no
    gate, returns None), waiting while every slot is held; the seconds waited. After
    ``max_wait_s`` the process goes on without one (a line on stderr). ValueError (one
    line) for a malformed value; OSError when the directory cannot be used."""
    global _held
    if not value:
        return None
    slots, directory = parse_gate(value)
    fds = _open_slots(slots, directory)  # opened once; only the flock is retried
    start = time.monotonic()
    while (fd := _lock_one(fds)) is None:
        if time.monotonic() - start >= max_wait_s:
            print(f"offboard: no start-up slot free after {max_wait_s:.0f} s; starting "
                  "without one", file=sys.stderr)
            break
        time.sleep(POLL_S)
    for other in fds:
        if other != fd:
            os.close(other)
    _held = fd
    return time.monotonic() - start


def release() -> None:
    """Give back this process's slot, if it holds one (idempotent)."""
    global _held
    if _held is not None:
        fd, _held = _held, None
        os.close(fd)  # closing the descriptor releases its flock


def holding() -> bool:
    """True while this process holds a slot."""
    return _held is not None
