"""One MAVLink-over-UDP endpoint of a simulated vehicle (non-blocking, no threads).

* Binds ``(bind_host, port)``; a busy port raises :class:`LinkError` naming it.
* One pymavlink ``MAVLink`` parser per socket; every datagram is parsed on its own
  (a frame never continues into the next datagram: a leftover partial frame is counted
  as ``truncated`` and dropped, like PX4's UDP receiver).
* Peer tracking: sends go to the default remote (PX4 SITL convention) and to every
  address that has sent a valid MAVLink frame here ("answers whoever talks to it").
  Peers that stay silent for ``peer_timeout`` seconds are forgotten, at most
  ``max_peers`` are kept.
* Counters (:attr:`stats`): datagrams, messages, ``bad`` (CRC / length / flags errors),
  ``garbage`` (bytes that are not MAVLink at all, parser exceptions), ``truncated``,
  ``foreign`` (a ``target_system`` that is neither 0 nor ours: dropped here),
  send errors.
"""

from __future__ import annotations

import errno
import logging
import socket
import struct
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mavlink2

log = logging.getLogger(__name__)

MAX_DATAGRAM = 65535
RCVBUF_BYTES = 1 << 20
# what pymavlink's parser raises on pathological input (MAVError; the others defensively)
PARSE_ERRORS = (mavlink2.MAVError, struct.error, IndexError, ValueError)


class LinkError(OSError):
    """A socket could not be opened (message names the address and port)."""


@dataclass
class LinkStats:
    datagrams: int = 0
    bytes: int = 0
    messages: int = 0
    bad: int = 0
    garbage: int = 0
    truncated: int = 0
    foreign: int = 0
    sent: int = 0
    send_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class Peer:
    addr: tuple[str, int]
    last_seen: float
    sysid: int = 0
    compid: int = 0


@dataclass
class MavlinkLink:
    """A UDP MAVLink endpoint for system ``sysid``."""

    name: str
    sysid: int
    port: int
    default_remote: tuple[str, int] | None
    bind_host: str = "127.0.0.1"
    peer_timeout: float = 10.0
    max_peers: int = 8
    stats: LinkStats = field(default_factory=LinkStats)

    def __post_init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((self.bind_host, self.port))
        except OSError as exc:
            self.sock.close()
            why = "port already in use" if exc.errno == errno.EADDRINUSE else exc.strerror
            raise LinkError(
                exc.errno, f"cannot bind UDP {self.bind_host}:{self.port} ({self.name}): {why}"
            ) from None
        self.sock.setblocking(False)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        except OSError as exc:  # the default buffer works, only bursts may drop
            log.debug("%s link: SO_RCVBUF not set: %s", self.name, exc)
        self.mav = mavlink2.MAVLink(
            None, srcSystem=self.sysid, srcComponent=mavlink2.MAV_COMP_ID_AUTOPILOT1
        )
        self.mav.robust_parsing = True
        self.peers: dict[tuple[str, int], Peer] = {}

    # -- receive ------------------------------------------------------------------
    def fileno(self) -> int:
        return self.sock.fileno()

    def _reset_parser(self) -> None:
        self.mav.buf = bytearray()
        self.mav.buf_index = 0
        self.mav.expected_length = mavlink2.HEADER_LEN_V1 + 2

    def receive(self, now: float | None = None, max_datagrams: int = 1000) -> list:
        """Drain the socket; return the valid messages for us (``msg._peer`` = sender)."""
        out: list = []
        now = time.monotonic() if now is None else now
        st = self.stats
        mav = self.mav
        for _ in range(max_datagrams):
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:  # ICMP from an earlier send to a closed port
                continue
            except OSError:
                break
            st.datagrams += 1
            st.bytes += len(data)
            try:
                msgs = mav.parse_buffer(data) or []
            except PARSE_ERRORS as exc:  # counted as garbage, the parser starts afresh
                st.garbage += 1
                log.debug("%s link: unparsable datagram from %s: %r", self.name, addr, exc)
                self._reset_parser()
                continue
            if mav.buf_len() > 0:
                st.truncated += 1
                self._reset_parser()
            good = False
            for m in msgs:
                mid = m.get_msgId()
                if mid < 0:  # MAVLink_bad_data (BAD_DATA / UNKNOWN)
                    if getattr(m, "reason", "") == "Bad prefix":
                        st.garbage += 1
                    else:
                        st.bad += 1
                    continue
                tgt = getattr(m, "target_system", 0)
                if tgt not in (0, self.sysid):
                    st.foreign += 1
                    good = True  # a real MAVLink peer, just not talking to us
                    continue
                st.messages += 1
                m._peer = addr
                out.append(m)
                good = True
            if good:
                self._touch_peer(addr, now, msgs)
        return out

    def _touch_peer(self, addr: tuple[str, int], now: float, msgs: Iterable) -> None:
        p = self.peers.get(addr)
        if p is None:
            if len(self.peers) >= self.max_peers:
                oldest = min(self.peers.values(), key=lambda q: q.last_seen)
                del self.peers[oldest.addr]
            p = self.peers[addr] = Peer(addr, now)
        p.last_seen = now
        for m in msgs:
            if m.get_msgId() >= 0:
                p.sysid, p.compid = m.get_srcSystem(), m.get_srcComponent()
                break

    # -- send ---------------------------------------------------------------------
    def destinations(self, now: float) -> list[tuple[str, int]]:
        dead = [a for a, p in self.peers.items() if now - p.last_seen > self.peer_timeout]
        for a in dead:
            del self.peers[a]
        dests = list(self.peers)
        if self.default_remote is not None and self.default_remote not in self.peers:
            dests.append(self.default_remote)
        return dests

    def send_bytes(self, buf: bytes, dests: list[tuple[str, int]], addr=None) -> None:
        """Send an already packed frame to ``dests`` (or only ``addr``)."""
        for d in (addr,) if addr is not None else dests:
            try:
                self.sock.sendto(buf, d)
                self.stats.sent += 1
            except OSError:
                self.stats.send_errors += 1

    def close(self) -> None:
        try:
            self.sock.close()
        except OSError as exc:
            log.debug("%s link: close: %s", self.name, exc)
