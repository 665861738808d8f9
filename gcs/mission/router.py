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
from pathlib import Path
from typing import Any

from swarm_common.inputs import one_line
from swarm_common.scenario.model import Scenario, swarm_name_problem
from swarm_common.zenoh_session import open_session, write_swarm_security

log = logging.getLogger(__name__)


def open_router(listen: list[str], config_file: Path | None = None) -> Any:
    """Open a router session listening on ``listen`` (raises RuntimeError or ValueError,
    one line); ``config_file``: the ``router.json5`` of
    :func:`~swarm_common.zenoh_session.write_swarm_security` (authentication + ACL)."""
    return open_session(mode="router", listen=listen, config_file=config_file)


def run_router(
    listen: list[str], sc: Scenario | None = None, secure_dir: Path | None = None,
    swarm: str | None = None,
) -> int:
    """Serve until SIGINT/SIGTERM. With ``sc`` and ``secure_dir``: authenticate and apply
    the swarm's ACL; the credentials are generated into ``secure_dir`` (0700, files
    0600) unless its ``router.json5`` exists already, for the operator to copy each
    process's ``<user>.json5`` to its machine."""
    cfg: Path | None = None
    if sc is not None and secure_dir is not None:
        name = swarm or sc.name
        problem = swarm_name_problem(name)
        if problem is not None:
            print(f"gcs router: swarm name {name!r}: {problem}", file=sys.stderr)
            return 2
        cfg = secure_dir / "router.json5"
        try:
            if not cfg.exists():
                write_swarm_security(secure_dir, name, sc.ids)
                log.info("wrote credentials and ACL for swarm %s to %s/", name, secure_dir)
        except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the path
            why = exc.strerror if isinstance(exc, OSError) else "not a valid path"
            print(one_line(f"gcs router: {secure_dir}: {why}"), file=sys.stderr)
            return 2
    else:
        log.warning("no --scenario/--secure-dir: anyone who reaches %s may publish",
                    ", ".join(listen))
    try:
        session = open_router(listen, cfg)
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
