"""Open a Zenoh 1.x session the way every process of the project does (docs/conventions.md).

Defaults (docs/conventions.md, Zenoh): ``peer`` mode, explicit ``listen``/``connect`` endpoints on
127.0.0.1, multicast scouting off, gossip off, so nothing leaves the machine and nothing
is discovered by accident. ``mode="router"`` turns the session into a router (there is no
``zenohd`` binary here); ``mode="client"`` connects to a router.

    sess = open_session(listen=["tcp/127.0.0.1:7447"])                 # the simulator
    sess = open_session(connect=["tcp/127.0.0.1:7447"])                # a peer that dials it
    sess = open_session(mode="router", listen=["tcp/127.0.0.1:7447"])

A peer that only *connects* still reaches every publisher the endpoint it dials knows
about only when that endpoint is a peer that listens (or a router); with a router in the
middle, run the others as ``client`` or as peers that also listen.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import zenoh

DEFAULT_ZENOH_PORT = 7447


def default_endpoint(offset: int = 0, host: str = "127.0.0.1") -> str:
    """``tcp/127.0.0.1:7447+offset``: where the simulator's session listens by default."""
    return f"tcp/{host}:{DEFAULT_ZENOH_PORT + offset}"


def make_config(
    mode: str = "peer",
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    multicast: bool = False,
) -> zenoh.Config:
    """A ``zenoh.Config`` with the project's defaults."""
    import zenoh

    if mode not in ("peer", "router", "client"):
        raise ValueError(f"zenoh mode {mode!r}: must be one of 'peer', 'router', 'client'")
    for ep in [*listen, *connect]:
        if "/" not in ep:
            raise ValueError(f"zenoh endpoint {ep!r}: must look like tcp/127.0.0.1:7447")
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("listen/endpoints", json.dumps(list(listen)))
    cfg.insert_json5("connect/endpoints", json.dumps(list(connect)))
    cfg.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast)))
    if mode == "peer":
        cfg.insert_json5("scouting/gossip/enabled", "false")
    # Keep retrying a connect endpoint that is not up yet (processes start in any order).
    if connect:
        cfg.insert_json5("connect/timeout_ms", "-1" if mode == "client" else "0")
        cfg.insert_json5("connect/exit_on_failure", "false")
    return cfg


def open_session(
    mode: str = "peer",
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    multicast: bool = False,
) -> zenoh.Session:
    """Open and return a ``zenoh.Session``. Raises ``RuntimeError`` with one line on failure
    (for example a listen port already in use)."""
    import zenoh

    cfg = make_config(mode, listen, connect, multicast)
    try:
        return zenoh.open(cfg)
    except zenoh.ZError as exc:
        where = ", ".join([*listen, *connect]) or "no endpoints"
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RuntimeError(f"cannot open zenoh {mode} session ({where}): {msg}") from None
