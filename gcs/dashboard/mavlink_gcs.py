"""The ground station's MAVLink link: one UDP socket on 127.0.0.1:14550+offset.

Every vehicle streams its GCS link to this port (``swarm_common.ports``); what is
received goes to a :class:`~.link_tracker.LinkTracker` (per-system-id state, events,
malformed packets counted). This module owns the socket, the reader thread, the GCS
heartbeat and the transmit side.

Commands are COMMAND_LONG sent to the address the vehicle streams from; the caller
waits for the matching COMMAND_ACK with a per-attempt timeout and retries (the
``confirmation`` field counts the retries) - one policy,
:func:`~.command_retry.command_exchange`. :meth:`MavlinkGcs.send_command` blocks;
:meth:`MavlinkGcs.command` is the ``async`` twin for an asyncio (Textual) loop.

Streams: a vehicle's GCS link starts from PX4's normal set (docs/px4/streams.md), in
which LOCAL_POSITION_NED runs at 1 Hz. When a live vehicle's position is older than
:data:`POSITION_STALE_S`, this link asks it, on its own link, for LOCAL_POSITION_NED at
:data:`POSITION_STREAM_HZ` (MAV_CMD_SET_MESSAGE_INTERVAL, per peer on the vehicle),
again at most every :data:`STREAM_REQUEST_RETRY_S` (a lost request, a restarted vehicle,
a vehicle that forgot our rate when we fell silent). A vehicle that already streams it
fast enough is never asked.

The socket runs in a daemon thread; no Textual here, so all of it is unit-testable
(:meth:`MavlinkGcs.feed` takes a datagram directly).
"""

from __future__ import annotations

import asyncio
import logging
import select
import socket
import threading
import time
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink

from swarm_common import signing
from swarm_common.ports import GCS_PORT

from .command_retry import CommandResult, PendingAck, command_exchange, drive_async, drive_blocking
from .link_tracker import (
    BODY_FRAMES,
    GCS_SIGNING_LINK_ID,
    LOCAL_FRAMES,
    LinkEvent,
    LinkTracker,
    LinkVehicle,
)
from .px4modes import CommandSpec

__all__ = [
    "BODY_FRAMES",
    "LOCAL_FRAMES",
    "CommandResult",
    "LinkEvent",
    "LinkVehicle",
    "MavlinkGcs",
]

log = logging.getLogger(__name__)

POSITION_STREAM_HZ = 10.0  # LOCAL_POSITION_NED rate asked of every vehicle
POSITION_STALE_S = 0.5  # s: a position older than this means the rate is too low
STREAM_REQUEST_RETRY_S = 5.0  # s between two stream requests to one vehicle
PARAM_RETRY_S = 2.0  # s between two parameter requests to one vehicle that lacks some


class MavlinkGcs:
    """The GCS UDP link. ``start()`` binds and starts the reader thread.

    ``signing_key`` (32 bytes): every frame sent is signed (MAVLink 2 signing, link id
    :data:`~.link_tracker.GCS_SIGNING_LINK_ID`) and only frames signed with the key are
    accepted; the others are counted in :attr:`rejected`.
    """

    def __init__(
        self,
        port_offset: int = 0,
        host: str = "127.0.0.1",
        port: int | None = None,
        heartbeat_timeout_s: float = 2.0,
        source_system: int = 255,
        source_component: int = mavlink.MAV_COMP_ID_MISSIONPLANNER,
        send_heartbeat: bool = True,
        clock: Callable[[], float] = time.monotonic,
        max_events: int = 2000,
        signing_key: bytes | None = None,
        request_streams: bool = True,
    ) -> None:
        self.host = host
        self.port = GCS_PORT + port_offset if port is None else port
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.clock = clock
        self._send_heartbeat = send_heartbeat
        self.tracker = LinkTracker(clock, source_system, source_component, max_events)
        self._tx = mavlink.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
        if signing_key is not None:
            signing.setup_signing(self._tx, signing_key, GCS_SIGNING_LINK_ID)
            self.tracker.enable_signing(signing_key)
        self._tx_lock = threading.Lock()
        self.sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._last_tick = 0.0
        self._last_gcs_hb = 0.0
        self._caught_up: float | None = None  # None: tick() callers judge up to ``now``
        self._request_streams = request_streams
        # parameters every vehicle is asked for (gcs.dashboard.view.preflight.CHECKED_PARAMS)
        self.param_names: tuple[str, ...] = ()
        self._params_requested: dict[int, float] = {}  # sysid -> clock() of the last ask
        self._stream_requested: dict[int, float] = {}  # sysid -> clock() of the last request

    def _keep_signing_time(self) -> None:
        """Signed: the outgoing signing timestamp never lags the wall clock, so a vehicle
        that (re)starts later accepts our stream (caller holds ``_tx_lock``)."""
        if self.signed:
            now = (time.time() - signing.SIGNATURE_EPOCH_UNIX_S) * signing.TIMESTAMP_UNITS_PER_S
            self._tx.signing.timestamp = max(int(self._tx.signing.timestamp), int(now))

    # -- lifecycle ---------------------------------------------------------------
    def start(self) -> MavlinkGcs:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise OSError(
                exc.errno, f"GCS link: cannot bind UDP {self.host}:{self.port}: {exc.strerror}"
            ) from None
        sock.settimeout(0.1)
        self.sock = sock
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="mavlink-gcs", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def __enter__(self) -> MavlinkGcs:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        """Read datagrams until closed; ``caught_up`` is the last time the socket was found
        empty (every datagram that had arrived was read): a link is judged silent only up
        to then (:meth:`LinkTracker.update`), so a reader that load delays sees no loss."""
        assert self.sock is not None
        sock = self.sock
        while not self._stop.is_set():
            try:
                data, addr = sock.recvfrom(65535)
            except TimeoutError:
                data = b""
                self._caught_up = self.clock()
            except OSError:
                if self._stop.is_set():
                    break
                time.sleep(0.05)
                continue
            if data:
                self.feed(data, addr)
                if not select.select([sock], [], [], 0)[0]:
                    self._caught_up = self.clock()
            now = self.clock()
            if now - self._last_tick >= 0.5:
                self.tick(now)

    # -- receive (delegated to the tracker) ----------------------------------------
    def feed(self, data: bytes, addr: tuple[str, int]) -> None:
        """Parse one datagram from ``addr`` (called by the reader thread, or tests)."""
        self.tracker.feed(data, addr)

    @property
    def packets(self) -> int:
        return self.tracker.packets

    @property
    def bad_packets(self) -> int:
        return self.tracker.bad_packets

    @property
    def rejected(self) -> int:
        """Frames dropped here for a missing, wrong or replayed signature."""
        return self.tracker.rejected

    @property
    def signed(self) -> bool:
        return self.tracker.signed

    def vehicles(self) -> dict[int, LinkVehicle]:
        """A consistent copy of every tracked vehicle."""
        return self.tracker.vehicles()

    def drain_events(self) -> list[LinkEvent]:
        return self.tracker.drain_events()

    def tick(self, now: float | None = None) -> None:
        """Update rates, detect lost links, send the GCS heartbeat (reader thread)."""
        now = self.clock() if now is None else now
        self._last_tick = now
        targets = self.tracker.update(now, self.heartbeat_timeout_s, self._caught_up)
        if self._send_heartbeat and now - self._last_gcs_hb >= 1.0 and self.sock is not None:
            self._last_gcs_hb = now
            with self._tx_lock:
                self._keep_signing_time()
                buf = self._tx.heartbeat_encode(
                    mavlink.MAV_TYPE_GCS,
                    mavlink.MAV_AUTOPILOT_INVALID,
                    0,
                    0,
                    mavlink.MAV_STATE_ACTIVE,
                ).pack(self._tx)
            for addr in set(targets):
                try:
                    self.sock.sendto(buf, addr)
                except OSError as exc:  # the vehicle's port went away: its link times out
                    log.debug("GCS heartbeat to %s: %s", addr, exc)
        if self._request_streams:
            self._request_position_streams(now)
        if self.param_names:
            self._request_params(now)

    def _request_params(self, now: float) -> None:
        """PARAM_REQUEST_READ of every name in :attr:`param_names` a live vehicle has not
        reported yet, again at most every PARAM_RETRY_S (the pre-flight check's values)."""
        for v in self.tracker.vehicles().values():
            missing = [n for n in self.param_names if n not in v.params]
            if v.lost or not missing or v.addr is None or self.sock is None:
                continue
            if now - self._params_requested.get(v.sysid, -PARAM_RETRY_S) < PARAM_RETRY_S:
                continue
            self._params_requested[v.sysid] = now
            for name in missing:
                with self._tx_lock:
                    self._keep_signing_time()
                    buf = self._tx.param_request_read_encode(
                        v.sysid, mavlink.MAV_COMP_ID_AUTOPILOT1, name.encode("ascii"), -1,
                    ).pack(self._tx)  # fmt: skip
                try:
                    self.sock.sendto(buf, v.addr)
                except OSError as exc:
                    log.debug("PARAM_REQUEST_READ to %s: %s", v.addr, exc)

    def _request_position_streams(self, now: float) -> None:
        """SET_MESSAGE_INTERVAL(LOCAL_POSITION_NED) to each live vehicle whose position is
        stale (older than POSITION_STALE_S), at most every STREAM_REQUEST_RETRY_S."""
        for v in self.tracker.vehicles().values():
            if v.lost or v.last_heartbeat is None:
                continue
            since = v.first_seen if v.pos_t is None else v.pos_t
            if now - since < POSITION_STALE_S:
                continue
            if now - self._stream_requested.get(v.sysid, -STREAM_REQUEST_RETRY_S) < (
                STREAM_REQUEST_RETRY_S
            ):
                continue
            self._stream_requested[v.sysid] = now
            interval_us = 1e6 / POSITION_STREAM_HZ
            self._send_long(
                v.sysid, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                (mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, interval_us), 0,
            )  # fmt: skip

    # -- commands ------------------------------------------------------------------
    def _send_long(self, sysid: int, command: int, params: tuple[float, ...], conf: int) -> bool:
        """Send one COMMAND_LONG (params padded to 7); False when there is no link to it."""
        addr = self.tracker.address(sysid)
        if addr is None or self.sock is None:
            return False
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        with self._tx_lock:
            self._keep_signing_time()
            buf = self._tx.command_long_encode(sysid, 1, command, conf & 0xFF, *p[:7]).pack(
                self._tx
            )
        try:
            self.sock.sendto(buf, addr)
        except OSError:
            return False
        return True

    def send_command(
        self,
        sysid: int,
        spec: CommandSpec,
        timeout_s: float = 1.0,
        retries: int = 2,
    ) -> CommandResult:
        """Send ``spec`` to ``sysid`` and block until its COMMAND_ACK (or give up)."""
        with self.tracker.awaiting_ack(sysid, spec.command) as pend:
            exchange = command_exchange(sysid, spec, pend, self.clock, timeout_s, retries)
            return drive_blocking(
                exchange,
                lambda conf: self._send_long(sysid, spec.command, spec.params, conf),
                pend.event.wait,
            )

    async def command(
        self,
        sysid: int,
        spec: CommandSpec,
        timeout_s: float = 1.0,
        retries: int = 2,
        poll_s: float = 0.02,
    ) -> CommandResult:
        """``async`` :meth:`send_command`: polls the ACK every ``poll_s`` without blocking."""
        with self.tracker.awaiting_ack(sysid, spec.command) as pend:
            exchange = command_exchange(sysid, spec, pend, self.clock, timeout_s, retries)
            return await drive_async(
                exchange,
                lambda conf: self._send_long(sysid, spec.command, spec.params, conf),
                lambda timeout: self._poll_ack(pend, timeout, poll_s),
            )

    async def _poll_ack(self, pend: PendingAck, timeout_s: float, poll_s: float) -> bool:
        """Wait up to ``timeout_s`` for ``pend`` (the ACK is set by the reader thread)."""
        deadline = self.clock() + timeout_s
        while not pend.event.is_set() and self.clock() < deadline:
            await asyncio.sleep(poll_s)
        return pend.event.is_set()
