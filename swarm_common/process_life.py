"""Start-up and exit of the long-running processes (``offboard``, ``vehicle-sim``): the
cyclic garbage collector and the interpreter's teardown (docs/performance.md, "Issue 11,
twenty-second round").

By the end of its start-up a daemon or the simulator holds about 140 000 objects that the
collector tracks (numpy, numba and its loaded kernels, scipy, pymavlink, the scenario,
the agents) and that live until the process ends. A full collection traverses all of
them: 35–50 ms in process, up to 0.3 s in the simulator after a run, a stall of several
control periods whenever it comes during a flight, and once more in the interpreter's
teardown, where it kept a stopped simulator and each stopped daemon alive for about
1.4 s after its last line.

* :func:`freeze_startup` moves every object alive at the end of the start-up into the
  collector's permanent generation, so later collections traverse only what the run
  itself creates. Nothing is collected first: the start-up leaves almost no cyclic
  garbage (10 objects in a full collection after a cube8 run), and a collection here
  would cost the 50 ms it saves.
* :func:`frozen_while` does the same for one block of a process that runs many (the
  in-process runner's loop, in a sweep's worker or the tests): the objects alive when it
  starts are skipped by the collections inside it and returned to the collector after
  it, so a run's set-up (at 1,024 agents, millions of objects) is not traversed again and
  again, and is collected once the run drops it. In a process whose start-up is frozen
  already it changes nothing.
* :func:`exit_now` ends the process without the interpreter's teardown, once the caller
  has closed its sockets, files and Zenoh session: the log is flushed and the exit
  status kept.

* :func:`die_with_parent` asks the kernel for a signal when the parent dies (Linux
  ``PR_SET_PDEATHSIG``): a child launched by the runner (``gcs.launch``) or a daemon
  started with ``--die-with-parent`` never outlives its runner;
  :func:`outlive_parent` takes that request back.

Standard library only: ``python -m offboard`` imports this before its start-up slot
(:mod:`offboard.daemon.start_gate`).
"""

from __future__ import annotations

import ctypes
import gc
import logging
import os
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import NoReturn

PR_SET_PDEATHSIG = 1  # linux/prctl.h
# the running program's own symbols (libc's prctl among them): loaded here, never in a child
_LIBC = ctypes.CDLL(None, use_errno=True) if sys.platform.startswith("linux") else None


def freeze_startup() -> None:
    """Everything alive now is permanent for the collector (module docstring)."""
    gc.freeze()


@contextmanager
def frozen_while() -> Iterator[None]:
    """Everything alive now is permanent for the collector until the block ends, then
    back in its oldest generation (module docstring); nothing if something is frozen
    already."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def exit_now(rc: int) -> NoReturn:
    """Flush the log and the standard streams, then exit with ``rc`` without the
    interpreter's teardown (module docstring). Only for a process whose ``main`` has
    returned, everything it opened closed."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)


def die_with_parent(sig: signal.Signals, parent_pid: int) -> Callable[[], str | None]:
    """A setup for a child of ``parent_pid`` to run first (a ``preexec_fn``, a forked
    child's first step, a daemon's start): the kernel sends it ``sig`` when the thread of
    ``parent_pid`` that started it dies, however it dies (kill -9 included); if that parent
    is already gone, ``sig`` now. The setup returns None, or why it could not be set (not
    Linux, prctl refused). Only async-signal-safe work in it: a prctl call, getppid, kill."""
    prctl = None if _LIBC is None else _LIBC.prctl

    def setup() -> str | None:
        if prctl is None:
            return "PR_SET_PDEATHSIG needs Linux"
        if prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
            return f"prctl failed: {os.strerror(ctypes.get_errno())}"
        if os.getppid() != parent_pid:  # the parent died before the prctl took effect
            os.kill(os.getpid(), sig)
        return None

    return setup


def outlive_parent() -> None:
    """Take back :func:`die_with_parent`'s request (no signal at the parent's death), for a
    process that watches its parent another way from now on. Linux only; elsewhere, and
    if the kernel refuses, nothing changes."""
    if _LIBC is not None:
        _LIBC.prctl(PR_SET_PDEATHSIG, 0, 0, 0, 0)
