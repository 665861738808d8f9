"""Run a command line's ``main(argv)`` in the test process: :func:`run_cli`.

A fresh ``python -m gcs.cli`` imports numpy, numba, scipy and Zenoh (about 1.5 s of CPU)
before it can refuse a bad flag; the test suite is CPU-bound on two cores, so a test of a
refusal calls the command's ``main`` here instead, on the imports this process already
holds, and sees what a process would: the exit code, stdout and stderr (log lines
included).

Use it for **validation errors that end before anything starts**: a bad flag, value or
file refused with one line and exit 2, argparse's refusals, ``--help``.

Do not use it for:

* anything that starts processes, opens sockets or sessions that must be closed, or
  runs a mission: a run would run inside the xdist worker, and a hang would hang it;
* anything that may block or read without bound (a FIFO with no writer, ``/dev/zero``, a
  huge file): those need a process that can be killed and measured alone;
* the real exit status of the console script (``exit_now``, the interpreter's exit):
  keep one real subprocess per console script for that
  (``tests/integration/mission/test_cli_exit_status.py``).

A regression that lets bad input past the checks then runs in this process: the test
still fails (the exit code), bounded by the file's pytest-timeout.

What the call changes in the process is put back afterwards: the root and every other
logger's handlers, level, propagation and ``disabled`` flag (``configure_logging``
attaches a handler to the captured stderr; handlers added during the call are removed and
closed), ``logging.disable``, every signal's Python handler, the warnings filters, the
environment variables that were set and those the commands set (:data:`COMMAND_ENV`), and
the working directory. What a module imported during the call leaves for good stays, as
the module does: a logger it made, with its handlers (but one bound to the captured
streams), and an ``os.environ.setdefault`` (``threadpoolctl`` sets one for OpenMP).
``faulthandler.register`` (``offboard`` registers SIGUSR1) is a no-op during the call: a
registration cannot be queried, so one made before the call could not be restored.
``os._exit`` (``exit_now``) called from the test's thread during the call raises
:class:`ProcessExitAttempted` instead of ending the worker; no ``main`` reaches it today
(``exit_now`` is only in the modules' ``__main__`` blocks, which ``run_cli`` bypasses).
Flags whose effect outlives the call in the whole process (``offboard
--die-with-parent``: a prctl on the test process) are refused with ``ValueError``.
"""

from __future__ import annotations

import contextlib
import faulthandler
import importlib
import logging
import os
import signal
import sys
import tempfile
import threading
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import IO, Any

# prog -> module whose main(argv) -> int is the console script (pyproject [project.scripts])
MAINS = {"gcs": "gcs.cli", "offboard": "offboard.cli", "vehicle-sim": "vehicle_sim.cli"}
# flags that change the whole test process for good: run these in a subprocess
PROCESS_WIDE_FLAGS = {"offboard": ("--die-with-parent",)}
# environment variables the commands set (vehicle-sim --zenoh-config, for its Zenoh
# session: swarm_common.zenoh_session.ZENOH_CONFIG_ENV)
COMMAND_ENV = ("SWARM_ZENOH_CONFIG",)


@dataclass(frozen=True)
class CliResult:
    """What the command line gave: its exit code and everything it wrote."""

    returncode: int
    stdout: str
    stderr: str


class ProcessExitAttempted(AssertionError):
    """The command called ``os._exit`` (``exit_now``) in the test process."""


def run_cli(prog: str, argv: list[str]) -> CliResult:
    """``prog`` ("gcs", "offboard" or "vehicle-sim") run as ``prog argv...`` in this
    process (module docstring: when to use it). ``SystemExit(code)`` is the exit code, as
    for a process (None is 0; a message is printed to stderr and is 1); any other
    exception propagates with the captured output attached as notes."""
    if prog not in MAINS:
        raise ValueError(f"run_cli: unknown prog {prog!r} (one of {sorted(MAINS)})")
    for flag in PROCESS_WIDE_FLAGS.get(prog, ()):
        if any(_abbreviates(arg, flag) for arg in argv):
            raise ValueError(f"run_cli: {prog} {flag} changes the whole process: run it in "
                             "a subprocess")
    main: Callable[[list[str]], Any] = importlib.import_module(MAINS[prog]).main
    with _captured() as (out, err):
        with _process_state_restored(out, err):
            try:
                code: object = main(list(argv))
            except SystemExit as exc:
                code = exc.code
            except BaseException as exc:
                exc.add_note(f"run_cli {prog} {argv}: stdout {_read(out)!r}, "
                             f"stderr {_read(err)!r}")
                raise
            if code is not None and not isinstance(code, int):  # as the interpreter does
                print(code, file=sys.stderr)
                code = 1
        return CliResult(0 if code is None else int(code), _read(out), _read(err))


def _abbreviates(arg: str, flag: str) -> bool:
    """``arg`` is ``flag`` or an abbreviation of it (``--die-with``): the commands' parsers
    refuse abbreviations (``OneLineParser``), but a regression there must not reach the
    flag in the test process."""
    name = arg.split("=", 1)[0]
    return name.startswith("--") and len(name) > 2 and flag.startswith(name)


def _read(stream: IO[str]) -> str:
    stream.flush()
    stream.seek(0)
    return stream.read()


@contextlib.contextmanager
def _captured() -> Iterator[tuple[IO[str], IO[str]]]:
    """``sys.stdout`` and ``sys.stderr`` replaced by real files (as a process's: with a file
    descriptor), put back afterwards."""
    with (
        tempfile.TemporaryFile("w+", encoding="utf-8", errors="backslashreplace") as out,
        tempfile.TemporaryFile("w+", encoding="utf-8", errors="backslashreplace") as err,
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(err),
    ):
        yield out, err


@dataclass
class _LoggerState:
    level: int
    handlers: list[logging.Handler]
    propagate: bool
    disabled: bool


def _loggers() -> dict[str, logging.Logger]:
    found = {name: lg for name, lg in logging.root.manager.loggerDict.items()
             if isinstance(lg, logging.Logger)}
    found[""] = logging.getLogger()
    return found


def _signal_handlers() -> dict[int, Any]:
    handlers: dict[int, Any] = {}
    for sig in signal.valid_signals():
        with contextlib.suppress(ValueError, OSError):
            handlers[sig] = signal.getsignal(sig)
    return handlers


@contextlib.contextmanager
def _process_state_restored(out: IO[str], err: IO[str]) -> Iterator[None]:
    """Everything the module docstring lists, put back when the block ends; ``out`` and
    ``err``: the captured streams (a handler writing to them is removed)."""
    loggers = {name: _LoggerState(lg.level, list(lg.handlers), lg.propagate, lg.disabled)
               for name, lg in _loggers().items()}
    disable = logging.root.manager.disable
    handlers = _signal_handlers()
    environ = dict(os.environ)
    cwd = os.getcwd()
    real_exit, real_register = os._exit, faulthandler.register
    pid, thread = os.getpid(), threading.get_ident()

    def guarded_exit(code: int) -> Any:
        if os.getpid() == pid and threading.get_ident() == thread:
            raise ProcessExitAttempted(f"os._exit({code}) called in the test process")
        real_exit(code)  # a forked child, or another thread: as usual

    def no_register(signum: int, *args: Any, **kwargs: Any) -> None:
        """faulthandler.register during the call: nothing (module docstring)."""

    os._exit = guarded_exit  # type: ignore[assignment]
    faulthandler.register = no_register
    try:
        with warnings.catch_warnings():
            yield
    finally:
        os._exit, faulthandler.register = real_exit, real_register
        _restore_loggers(loggers, (out, err))
        logging.disable(disable)
        _restore_signals(handlers)
        _restore_environ(environ)
        if os.getcwd() != cwd:
            os.chdir(cwd)


def _restore_loggers(before: dict[str, _LoggerState], captured: tuple[IO[str], ...]) -> None:
    for name, lg in _loggers().items():
        old = before.get(name)
        if old is None:  # made during the call (an import): it loses only the handlers
            # bound to the captured streams, closed with the call
            lg.handlers = [h for h in lg.handlers if getattr(h, "stream", None) not in captured]
            continue
        for h in lg.handlers:
            if h not in old.handlers:
                h.close()
        lg.handlers = list(old.handlers)
        lg.propagate, lg.disabled = old.propagate, old.disabled
        lg.setLevel(old.level)  # also clears the loggers' cached levels


def _restore_signals(before: dict[int, Any]) -> None:
    for sig, handler in before.items():
        if signal.getsignal(sig) is handler:
            continue
        if handler is None:  # set outside Python: cannot be put back
            raise RuntimeError(f"run_cli: the call changed the handler of signal {sig}, "
                               "which Python did not install")
        signal.signal(sig, handler)


def _restore_environ(before: dict[str, str]) -> None:
    """Every variable that was set is put back; of those added during the call, the ones
    the commands set (:data:`COMMAND_ENV`) are removed. The others were added by a module
    imported during the call (``os.environ.setdefault``, as ``threadpoolctl`` does for
    OpenMP) and must outlive it, as the module does."""
    for key in COMMAND_ENV:
        if key not in before:
            os.environ.pop(key, None)
    for key, value in before.items():
        if os.environ.get(key) != value:
            os.environ[key] = value
