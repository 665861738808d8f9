"""Ground truth on Zenoh: one ``wire.Truth`` per control step on ``wire.key_truth(swarm)``.

The simulator's session listens on ``tcp/127.0.0.1:7447+offset`` by default
(docs/conventions.md §Zenoh). A failing put is logged and counted, never fatal.
"""

from __future__ import annotations

import logging
from typing import Any

from swarm_common import wire
from vehicle_sim.options import SimOptions

log = logging.getLogger(__name__)

ERRORS_LOGGED = 10  # failed puts logged before only counting them


def zenoh_errors() -> tuple[type[BaseException], ...]:
    """What a Zenoh put/undeclare/close can raise (zenoh.ZError; RuntimeError once the
    session is closed)."""
    import zenoh

    return (zenoh.ZError, RuntimeError)


class TruthPublisher:
    """The Zenoh session and publisher of one simulator (``open`` raises RuntimeError with
    one line, e.g. a busy listen port)."""

    def __init__(self) -> None:
        self.session: Any = None
        self.pub: Any = None
        self.published = 0
        self.errors = 0

    def open(self, o: SimOptions) -> str:
        """Open the session and declare the publisher; returns a line describing it."""
        from swarm_common.zenoh_session import default_endpoint, open_session

        listen = list(o.zenoh_listen)
        if not listen and not o.zenoh_connect and o.zenoh_mode != "client":
            listen = [default_endpoint(o.port_offset)]
        self.session = open_session(o.zenoh_mode, listen=listen, connect=o.zenoh_connect)
        self.pub = self.session.declare_publisher(wire.key_truth(o.swarm))
        return f"zenoh {o.zenoh_mode} listen={listen} connect={o.zenoh_connect}"

    @property
    def active(self) -> bool:
        return self.pub is not None

    def put(self, truth: wire.Truth) -> None:
        if self.pub is None:
            return
        try:
            self.pub.put(wire.encode(truth))
            self.published += 1
        except zenoh_errors() as exc:  # never let Zenoh kill the simulation
            self.errors += 1
            if self.errors <= ERRORS_LOGGED:
                log.warning("zenoh put failed: %s", exc)

    def close(self) -> None:
        """Undeclare and close; safe to call twice."""
        if self.pub is not None:
            try:
                self.pub.undeclare()
            except zenoh_errors() as exc:
                log.debug("zenoh undeclare: %r", exc)
            self.pub = None
        if self.session is not None:
            try:
                self.session.close()
            except zenoh_errors() as exc:
                log.debug("zenoh close: %r", exc)
            self.session = None
