"""What the fork server (:mod:`gcs.launch.forkserver`) holds before it forks a child.

Imported once, in the server: the daemon's and the simulator's programs with everything
they import, also what their ``main`` imports only once its flags are checked (each CLI's
``RUNTIME_MODULES``), then their compiled kernels loaded by the same warm-ups each program runs
before its first step (:func:`offboard.daemon.warmup.warm_kernels` for every safety
method, :func:`vehicle_sim.server.load_kernels`) on cube8. A child forked afterwards finds
them in memory; a kernel that cube8 does not reach loads in the child, as it would have.

BLAS is held to one thread before numpy loads, as each child's environment asks
(:meth:`gcs.mission.procs.ProcessGroup.start`), so the server forks with one thread.
A warm-up that fails is logged and skipped: each child then loads its own kernels.

The server never outlives the runner by more than an instant (a run's children die with
it, ``PR_SET_PDEATHSIG``, so they wait for it):

* **during this import** it does not yet watch the runner's pipe (``multiprocessing``
  reads it only once the preload is done), and a fresh checkout compiles every kernel
  here, tens of seconds on a loaded machine: the kernel kills it if the runner dies
  meanwhile. The request is taken back at the end, since afterwards the runner's thread
  that started the server may end while the runner lives on.
* **at its exit**, when the pipe reports the runner gone, it skips the interpreter's
  teardown (:func:`_exit_at_once`): with numpy, numba, scipy and Zenoh loaded that
  teardown took 0.55 s on an idle machine and several seconds under a test suite's load.
"""

from __future__ import annotations

import atexit
import os
import signal
import sys

from gcs.launch.forkserver import PARENT_ENV
from swarm_common.process_life import die_with_parent, outlive_parent

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")


def _runner_pid() -> int:
    """The runner that started this server (``SWARM_FORKSERVER_PARENT``, set by
    :mod:`.forkserver`); the parent now if that is unset or not a pid. When the runner
    died before this line, the parent now is another process and the check below ends
    the server at once."""
    text = os.environ.get(PARENT_ENV, "")
    return int(text) if text.isdecimal() and 0 < len(text) < 11 else os.getppid()


_SERVER_PID = os.getpid()
die_with_parent(signal.SIGKILL, _runner_pid())()

import importlib  # noqa: E402 - after the BLAS settings above
import logging  # noqa: E402
from pathlib import Path  # noqa: E402

import offboard.__main__  # noqa: E402, F401 - the daemon's entry and the modules it imports
import offboard.cli  # noqa: E402, F401
import vehicle_sim.cli  # noqa: E402, F401
from offboard.daemon.warmup import warm_kernels  # noqa: E402
from offboard.estimation.bearing import formation_from_scenario  # noqa: E402
from swarm_common.enums import Method  # noqa: E402
from swarm_common.scenario.model import load_scenario  # noqa: E402
from vehicle_sim.server import load_kernels  # noqa: E402

for _module in (*offboard.cli.RUNTIME_MODULES, *vehicle_sim.cli.RUNTIME_MODULES):
    importlib.import_module(_module)

log = logging.getLogger(__name__)
SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "cube8.toml"


def _warm() -> None:
    try:
        sc = load_scenario(SCENARIO)
        form = formation_from_scenario(sc)
        for method in Method:
            warm_kernels(sc, str(method), form)
        load_kernels(sc)
    except Exception as exc:  # noqa: BLE001 - an optimisation: never stop the server
        log.warning("fork server: kernel warm-up skipped (%s: %s)", type(exc).__name__, exc)


_warm()
outlive_parent()


def _exit_at_once() -> None:
    """The server's last step once ``multiprocessing``'s loop has ended (module docstring):
    exit now, skipping the teardown. A forked child inherits this hook but never runs it
    (it ends with ``os._exit``); the pid test makes sure."""
    if os.getpid() == _SERVER_PID:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError, AttributeError):
                pass
        os._exit(0)


atexit.register(_exit_at_once)
