"""Raw UDP sockets on 127.0.0.1 for the replay tests: bind one (non-blocking) and drain
what it has received, datagram by datagram, without decoding anything."""

from __future__ import annotations

import socket

LOCALHOST = "127.0.0.1"


def udp_socket(port: int = 0) -> socket.socket:
    """A non-blocking UDP socket bound to ``port`` on 127.0.0.1 (0: any free port)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((LOCALHOST, port))
    s.setblocking(False)
    return s


def drain(sock: socket.socket) -> list[bytes]:
    """Every datagram waiting on ``sock``, in arrival order."""
    out: list[bytes] = []
    while True:
        try:
            out.append(sock.recv(65535))
        except BlockingIOError:
            return out
