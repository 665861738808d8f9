"""The daemon's ``--mavlink`` URL: ``SCHEME:HOST:PORT``, checked before anything opens."""

from __future__ import annotations

MAVLINK_SCHEMES = ("udpin", "udpout", "udp", "tcp", "tcpin")


def mavlink_url_problem(url: str) -> str | None:
    """Why ``url`` is not a usable ``SCHEME:HOST:PORT`` MAVLink URL (one line), or None.
    Schemes: :data:`MAVLINK_SCHEMES`; HOST not empty; PORT a decimal 1..65535."""
    scheme, sep, rest = url.partition(":")
    if not sep or scheme not in MAVLINK_SCHEMES:
        return f"unknown scheme {scheme!r}: use one of {', '.join(MAVLINK_SCHEMES)}"
    host, sep, port = rest.rpartition(":")
    if not sep or not host:
        return f"expected {scheme}:HOST:PORT (e.g. udpin:127.0.0.1:14540)"
    if not port.isascii() or not port.isdigit():
        return f"port {port!r} is not a number"
    if not 0 < int(port) < 65536:
        return f"port {int(port)} out of range 1..65535"
    return None


def parse_udpin(url: str) -> tuple[str, int] | None:
    """``udpin:HOST:PORT`` -> (host, port); None for any other scheme (ValueError, one
    line, for a malformed ``udpin`` URL)."""
    if not url.startswith("udpin:"):
        return None
    if (why := mavlink_url_problem(url)) is not None:
        raise ValueError(f"MAVLink URL {url!r}: {why}")
    host, _, port = url[len("udpin:"):].rpartition(":")
    return host, int(port)
