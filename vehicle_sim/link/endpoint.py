"""One MAVLink-over-UDP endpoint of a simulated vehicle (non-blocking, no threads).

* Binds ``(bind_host, port)``; a busy port raises :class:`LinkError` naming it.
* One pymavlink ``MAVLink`` parser per socket; every datagram is parsed on its own
  (a frame never continues into the next datagram: a leftover partial frame is counted
  as ``truncated`` and dropped, like PX4's UDP receiver).
* Signing (``key`` set, :mod:`swarm_common.signing`): a frame that is unsigned, wrongly
  signed, replayed or reflected is rejected and counted per reason (``rejected_unsigned``,
  ``rejected_bad_signature``, ``rejected_replay``; a reflection counts as a replay). A
  reflection is a frame of a stream this process emits: it claims the system id and
  component of one of the simulator's vehicles (every link registers its vehicle in the
  process's :data:`PROCESS_LEDGER`), or it is a frame the simulator forwarded
  (:meth:`MavlinkLink.forward_bytes`). A rejected frame never admits or refreshes a peer.
  On an ``unsigned_ok`` link an unsigned
  HEARTBEAT, TIMESYNC, COMMAND_LONG/INT, PING, REQUEST_DATA_STREAM or parameter / mission
  protocol message is let through marked ``_restricted``: the vehicle answers only
  telemetry requests and reads (parameters, mission download) from it, and refuses its
  writes (docs/security.md).
* Peer hygiene (docs/security.md): sends go to the default remote (PX4 SITL convention)
  and to every address that has sent an accepted frame here within ``peer_timeout``
  seconds. At most ``max_peers`` such peers: a newcomer is refused (``peers_refused``,
  its frames dropped) while the table is full of peers that still speak, it never evicts
  one. The default remote is always admitted and never counted.
* Amplification bound (docs/security.md): a peer that is neither the default remote nor
  authenticated by a valid signature gets streams only while it speaks (within
  ``peer_timeout``) and within a byte budget of its own, a token bucket of
  ``budget_bytes_per_s`` (default :data:`BUDGET_BYTES_PER_S`, 64 kB/s) holding at most
  ``budget_burst_bytes`` (:data:`BUDGET_BURST_BYTES`); a stream datagram the bucket
  cannot pay for is withheld and counted (:meth:`MavlinkLink.stream_allowed`). PX4's
  normal set is about 1.5 kB/s, so a ground station, even one that asks for a few
  streams at 50-100 Hz, never reaches it; a spoofed source earns at most
  ``peer_timeout`` seconds of it per datagram.
* Counters (:attr:`stats`): datagrams, messages, ``bad`` (CRC / length / flags errors),
  ``garbage`` (bytes that are not MAVLink at all, parser exceptions), ``truncated``,
  ``foreign`` (a ``target_system`` that is neither 0 nor ours: dropped here),
  send errors, the signing rejects, ``peers_refused``, ``throttled`` (stream datagrams
  withheld by the amplification bound).
* Fault injection (docs/faults.md): with a ``[faults]`` plan for this vehicle's
  ``mavlink`` link, every outgoing datagram goes through a seeded
  :class:`swarm_common.faults.FaultInjector` (drop, delay, duplicate, reorder) and received
  datagrams may be discarded (``drop_in``) before they are counted; without one nothing
  changes.
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

from swarm_common import faults as fault_plan
from swarm_common import signing
from swarm_common.faults import FaultInjector

log = logging.getLogger(__name__)

MAX_DATAGRAM = 65535
RCVBUF_BYTES = 1 << 20
# what pymavlink's parser raises on pathological input (MAVError; the others defensively)
PARSE_ERRORS = (mavlink2.MAVError, struct.error, IndexError, ValueError)
PEER_TIMEOUT_S = 5.0  # a peer silent this long gets no more streams and is forgotten
MAX_PEERS = 4  # peers per link besides the default remote
# per-peer stream byte budget of unauthenticated peers (token bucket)
BUDGET_BYTES_PER_S = 64_000.0  # refill rate, bytes/s
BUDGET_BURST_BYTES = 32_000.0  # bucket size (and a newcomer's start), bytes
LIVENESS_FREE_S = 1.0  # one HEARTBEAT per second reaches a peer out of credit
SIGNING_LINK_ID = 0  # link id of the simulator's outgoing signed streams
# what an unsigned client may send on an ``unsigned_ok`` link (commands checked later)
# (the services refuse the writes among them: PARAM_SET, mission upload/clear/current)
UNSIGNED_MSG_IDS = frozenset({
    mavlink2.MAVLINK_MSG_ID_HEARTBEAT,
    mavlink2.MAVLINK_MSG_ID_TIMESYNC,
    mavlink2.MAVLINK_MSG_ID_COMMAND_LONG,
    mavlink2.MAVLINK_MSG_ID_COMMAND_INT,
    mavlink2.MAVLINK_MSG_ID_PING,
    mavlink2.MAVLINK_MSG_ID_REQUEST_DATA_STREAM,
    mavlink2.MAVLINK_MSG_ID_PARAM_REQUEST_LIST,
    mavlink2.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
    mavlink2.MAVLINK_MSG_ID_PARAM_SET,
    mavlink2.MAVLINK_MSG_ID_MISSION_REQUEST_LIST,
    mavlink2.MAVLINK_MSG_ID_MISSION_REQUEST_INT,
    mavlink2.MAVLINK_MSG_ID_MISSION_REQUEST,
    mavlink2.MAVLINK_MSG_ID_MISSION_ACK,
    mavlink2.MAVLINK_MSG_ID_MISSION_COUNT,
    mavlink2.MAVLINK_MSG_ID_MISSION_ITEM_INT,
    mavlink2.MAVLINK_MSG_ID_MISSION_ITEM,
    mavlink2.MAVLINK_MSG_ID_MISSION_CLEAR_ALL,
    mavlink2.MAVLINK_MSG_ID_MISSION_SET_CURRENT,
})  # fmt: skip
_REJECT_PREFIX = signing.INVALID_SIGNATURE_REASON + ": "
# the signed streams this process emits: every signing link's vehicle, forwarded frames
PROCESS_LEDGER = signing.StreamLedger()


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
    rejected_unsigned: int = 0
    rejected_bad_signature: int = 0
    rejected_replay: int = 0
    peers_refused: int = 0
    throttled: int = 0

    @property
    def rejected(self) -> int:
        return self.rejected_unsigned + self.rejected_bad_signature + self.rejected_replay

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class Peer:
    addr: tuple[str, int]
    last_seen: float
    sysid: int = 0
    compid: int = 0
    authenticated: bool = False  # has sent a frame with a valid signature
    tokens: float = BUDGET_BURST_BYTES  # stream bytes it may still be sent now
    refilled_at: float = 0.0  # when ``tokens`` was last brought up to date (monotonic s)
    free_liveness_at: float = -1e9  # when it last got a HEARTBEAT without credit


@dataclass
class MavlinkLink:
    """A UDP MAVLink endpoint for system ``sysid``."""

    name: str
    sysid: int
    port: int
    default_remote: tuple[str, int] | None
    bind_host: str = "127.0.0.1"
    peer_timeout: float = PEER_TIMEOUT_S
    max_peers: int = MAX_PEERS
    key: bytes | None = None
    unsigned_ok: bool = False
    budget_bytes_per_s: float = BUDGET_BYTES_PER_S
    budget_burst_bytes: float = BUDGET_BURST_BYTES
    stats: LinkStats = field(default_factory=LinkStats)
    # injected faults (docs/faults.md); None: the plan of the scenario this process loaded
    faults: FaultInjector | None = None
    # streams this process emits, refused coming back; None: :data:`PROCESS_LEDGER`
    ledger: signing.StreamLedger | None = None

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
        self._identity: tuple[int, int] | None = None
        if self.key is not None:
            allow = self._allow_unsigned if self.unsigned_ok else None
            if self.ledger is None:
                self.ledger = PROCESS_LEDGER
            self._identity = (self.sysid, mavlink2.MAV_COMP_ID_AUTOPILOT1)
            self.ledger.add_identity(*self._identity)
            signing.setup_signing(self.mav, self.key, SIGNING_LINK_ID, allow, self.ledger)
        self.peers: dict[tuple[str, int], Peer] = {}
        if self.faults is None:
            self.faults = fault_plan.injector_for(
                fault_plan.MAVLINK, self.sysid, f"vehicle.{self.name}"
            )

    @staticmethod
    def _allow_unsigned(_mav: object, msg_id: int) -> bool:
        return msg_id in UNSIGNED_MSG_IDS

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
            if self.faults is not None and self.faults.drop_inbound():
                continue
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
            good, signed, accepted = False, False, []
            for m in msgs:
                mid = m.get_msgId()
                if mid < 0:  # MAVLink_bad_data (BAD_DATA / UNKNOWN)
                    self._count_bad(m)
                    continue
                good = True  # a real MAVLink peer (perhaps not talking to us)
                tgt = getattr(m, "target_system", 0)
                if tgt not in (0, self.sysid):
                    st.foreign += 1
                    continue
                m._peer = addr
                m._restricted = self.key is not None and not m.get_signed()
                signed = signed or (self.key is not None and m.get_signed())
                accepted.append(m)
            if good and self._admit(addr, now, msgs, signed):
                st.messages += len(accepted)
                out.extend(accepted)
        return out

    def _count_bad(self, m: object) -> None:
        reason = str(getattr(m, "reason", ""))
        st = self.stats
        if reason == "Bad prefix":
            st.garbage += 1
        elif reason.startswith(_REJECT_PREFIX):
            why = reason[len(_REJECT_PREFIX) :]
            if why == signing.REJECT_UNSIGNED:
                st.rejected_unsigned += 1
            elif why in signing.REPLAY_REASONS:
                st.rejected_replay += 1
            else:
                st.rejected_bad_signature += 1
        else:
            st.bad += 1

    def _admit(self, addr: tuple[str, int], now: float, msgs: Iterable, signed: bool) -> bool:
        """Track the sender of an accepted datagram; False (frames dropped) for a newcomer
        while ``max_peers`` peers that still speak fill the table."""
        p = self.peers.get(addr)
        if p is None:
            self._forget_silent(now)
            counted = [a for a in self.peers if a != self.default_remote]
            if addr != self.default_remote and len(counted) >= self.max_peers:
                self.stats.peers_refused += 1
                return False
            p = self.peers[addr] = Peer(addr, now, tokens=self.budget_burst_bytes,
                                        refilled_at=now)  # fmt: skip
        p.last_seen = now
        p.authenticated = p.authenticated or signed
        for m in msgs:
            if m.get_msgId() >= 0:
                p.sysid, p.compid = m.get_srcSystem(), m.get_srcComponent()
                break
        return True

    def _forget_silent(self, now: float) -> None:
        dead = [a for a, p in self.peers.items() if now - p.last_seen > self.peer_timeout]
        for a in dead:
            del self.peers[a]

    # -- send ---------------------------------------------------------------------
    def destinations(self, now: float) -> list[tuple[str, int]]:
        """The default remote and every peer that has spoken within ``peer_timeout``."""
        self._forget_silent(now)
        dests = list(self.peers)
        if self.default_remote is not None and self.default_remote not in self.peers:
            dests.append(self.default_remote)
        return dests

    def send_bytes(self, buf: bytes, dests: list[tuple[str, int]], addr=None) -> None:
        """Send an already packed frame to ``dests`` (or only ``addr``)."""
        for d in (addr,) if addr is not None else dests:
            if self.faults is None:
                self._sendto((buf, d))
            else:
                self.faults.send((buf, d), self._sendto)

    def forward_bytes(self, buf: bytes, dests: list[tuple[str, int]]) -> None:
        """Send a frame another system signed (a forwarded HEARTBEAT) to ``dests``; its
        stream is recorded in the ledger so that the frame never comes back in on any link
        of this process (a reflection)."""
        if self.ledger is not None:
            self.ledger.note_forwarded(buf)
        self.send_bytes(buf, dests)

    def _sendto(self, frame: tuple[bytes, tuple[str, int]]) -> None:
        try:
            self.sock.sendto(frame[0], frame[1])
            self.stats.sent += 1
        except OSError:
            self.stats.send_errors += 1

    def stream_allowed(
        self, addr: tuple[str, int], nbytes: int, now: float, liveness: bool = False
    ) -> bool:
        """Whether a stream datagram of ``nbytes`` may go to ``addr`` at ``now``
        (monotonic s), and pay for it: always for the default remote and authenticated
        peers; for any other peer only while it speaks (within ``peer_timeout``) and
        when its token bucket (refilled at ``budget_bytes_per_s`` up to
        ``budget_burst_bytes``) holds ``nbytes``, else it is counted in ``throttled``. A
        ``liveness`` datagram (HEARTBEAT) goes once per ``LIVENESS_FREE_S`` even from an
        empty bucket. An address the link no longer knows gets nothing."""
        if addr == self.default_remote:
            return True
        p = self.peers.get(addr)
        if p is None or now - p.last_seen > self.peer_timeout:
            return False
        if p.authenticated:
            return True
        if now > p.refilled_at:
            p.tokens = min(
                self.budget_burst_bytes, p.tokens + (now - p.refilled_at) * self.budget_bytes_per_s
            )
            p.refilled_at = now
        if p.tokens >= nbytes:
            p.tokens -= nbytes
            return True
        if liveness and now - p.free_liveness_at >= LIVENESS_FREE_S:
            p.free_liveness_at = now
            return True
        self.stats.throttled += 1
        return False

    def close(self) -> None:
        if self._identity is not None and self.ledger is not None:
            self.ledger.remove_identity(*self._identity)
            self._identity = None
        if self.faults is not None:
            self.faults.close()
        try:
            self.sock.close()
        except OSError as exc:
            log.debug("%s link: close: %s", self.name, exc)
