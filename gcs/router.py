"""``gcs router``: a Zenoh router in a Python process (no ``zenohd`` binary is needed).

Multi-machine setup (docs/architecture.md): run ``gcs router --listen tcp/0.0.0.0:7447``
on one machine; start ``vehicle-sim --zenoh-connect tcp/<host>:7447`` and every
``offboard --zenoh-connect tcp/<host>:7447`` (client mode) elsewhere.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
from typing import Any

from swarm_common.zenoh_session import open_session

log = logging.getLogger(__name__)


def open_router(listen: list[str]) -> Any:
    """Open a router session listening on ``listen`` (raises RuntimeError, one line)."""
    return open_session(mode="router", listen=listen)


def run_router(listen: list[str]) -> int:
    try:
        session = open_router(listen)
    except (RuntimeError, ValueError) as exc:
        print(f"gcs router: {exc}", file=sys.stderr)
        return 2
    log.info("listening on %s (Ctrl-C to stop)", ", ".join(listen))
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    done.wait()
    session.close()
    return 0
