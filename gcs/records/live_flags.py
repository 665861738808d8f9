"""The live view's command-line flags, apart from its server (:mod:`gcs.records.live`):
``gcs`` builds its parser from this module without importing Foxglove, numba or the record
channels, so a bad flag or file is refused before those load.

* :func:`add_live_flags` - ``--foxglove``, ``--foxglove-host``, ``--foxglove-port``.
* :func:`live_endpoint` - the (host, port) they ask for, or None.
"""

from __future__ import annotations

import argparse
import ipaddress

from swarm_common.inputs import int_in

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765  # Foxglove's default WebSocket port
MAX_PORT = 65535


def ip_address(text: str) -> str:
    """argparse ``type=``: an IPv4 or IPv6 address (no host name: the server binds it)."""
    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: must be an IP address (IPv4 or IPv6)") from None


def add_live_flags(p: argparse.ArgumentParser) -> None:
    """``--foxglove``, ``--foxglove-host``, ``--foxglove-port`` (docs/records.md)."""
    g = p.add_argument_group("live view in Foxglove (docs/records.md, \"Live view\")")
    g.add_argument("--foxglove", action="store_true",
                   help="serve the record's topics live on a Foxglove WebSocket server")
    g.add_argument("--foxglove-host", type=ip_address, default=None, metavar="IP",
                   help=f"the address it binds (default {DEFAULT_HOST}: this machine only)")
    g.add_argument("--foxglove-port", type=int_in(0, MAX_PORT, "a TCP port"), default=None,
                   metavar="PORT", help=f"its TCP port (default {DEFAULT_PORT}; 0: any free one)")


def live_endpoint(args: argparse.Namespace) -> tuple[str, int] | None:
    """(host, port) of ``--foxglove``, None without it; ``ValueError`` (one line) for
    ``--foxglove-host`` or ``--foxglove-port`` without ``--foxglove``."""
    host, port = getattr(args, "foxglove_host", None), getattr(args, "foxglove_port", None)
    if not getattr(args, "foxglove", False):
        if host is not None or port is not None:
            flag = "--foxglove-host" if host is not None else "--foxglove-port"
            raise ValueError(f"{flag} needs --foxglove")
        return None
    return (DEFAULT_HOST if host is None else host), (DEFAULT_PORT if port is None else port)


def ws_url(host: str, port: int) -> str:
    """The address to open in Foxglove (an IPv6 host in brackets)."""
    return f"ws://[{host}]:{port}" if ":" in host else f"ws://{host}:{port}"
