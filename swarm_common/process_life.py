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
* :func:`exit_now` ends the process without the interpreter's teardown, once the caller
  has closed its sockets, files and Zenoh session: the log is flushed and the exit
  status kept.

Standard library only: ``python -m offboard`` imports this before its start-up slot
(:mod:`offboard.daemon.start_gate`).
"""

from __future__ import annotations

import gc
import logging
import os
import sys
from typing import NoReturn


def freeze_startup() -> None:
    """Everything alive now is permanent for the collector (module docstring)."""
    gc.freeze()


def exit_now(rc: int) -> NoReturn:
    """Flush the log and the standard streams, then exit with ``rc`` without the
    interpreter's teardown (module docstring). Only for a process whose ``main`` has
    returned, everything it opened closed."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)
