"""The offboard daemon's MAVLink link to its own vehicle (the companion-computer side).

Listens where the vehicle streams its API link (``udpin:127.0.0.1:<api_remote>``, PX4's
14540 for vehicle 1), talks as system = agent id, component 191 (onboard computer): its own
HEARTBEAT once a second (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID) and one
sequence number per packet sent (docs/px4/offboard-component.md; the sending half:
:class:`offboard.daemon.mavlink.sending.LinkSender`).

Link hygiene (docs/security.md, "Offboard daemon: link hygiene and failsafes"):

* **lock**: the first valid HEARTBEAT from system = agent id, component 1
  (MAV_COMP_ID_AUTOPILOT1) locks the link to that sender's address; from then on
  datagrams from any other address are dropped unparsed and frames from any other
  system/component are dropped; everything sent goes to the locked address only;
* **ODOMETRY**: non-finite or out-of-range fields, duplicate, non-monotonic and
  implausibly far stamps are dropped (:class:`offboard.daemon.link_guard.StampGuard`);
* **commands** never block: :attr:`VehicleLink.commands` queues a COMMAND_LONG, (re)sends
  it on ``tick`` and the ACK completes it (:mod:`offboard.daemon.mavlink.commands`);
* **fence**: :attr:`VehicleLink.fence` downloads the vehicle's stored geofence whenever
  MISSION_CURRENT's ``fence_id`` changes (:mod:`offboard.daemon.mavlink.fence_download`);
  :attr:`VehicleLink.origin` keeps the vehicle's GPS_GLOBAL_ORIGIN (one out of range is
  dropped and counted), about which the fence is read;
* **signing** (optional key): outgoing frames signed, unsigned or wrongly signed frames
  dropped and counted (``bad signature``); replayed frames (a stream's timestamp not
  above its last, a new stream older than 60 s) and reflected ones (claiming the daemon's
  own system id and component, as its own frames forwarded by the vehicle do) dropped
  and counted as ``replayed`` (:mod:`swarm_common.signing`). Before the lock they are
  verified like any frame; after it a stranger's datagram is dropped unparsed
  (``foreign address``) and nothing is ever sent to it. With signing the lock also needs
  a frame signed after the daemon's start and an address that answered a TIMESYNC
  challenge (:mod:`offboard.daemon.mavlink.lock_gate`).
* **unread telemetry**: a datagram made only of messages the daemon does not read is
  dropped from the frames' headers, undecoded and unverified
  (:mod:`offboard.daemon.mavlink.frame_peek`),
  unless a ``.tlog`` is kept.

Fault injection (docs/faults.md): with a ``[faults]`` plan for this agent's ``mavlink``
link, every datagram sent goes through a seeded :class:`swarm_common.faults.FaultInjector`
(drop, delay, duplicate, reorder; the ``.tlog`` records what the daemon sent, before the
faults) and received datagrams may be discarded (``drop_in``); without one nothing changes.

Every drop is counted by reason in :attr:`VehicleLink.drops` and logged rate-limited.
Every accepted and sent message is appended to a ``.tlog`` when one is given (8-byte
big-endian µs timestamp + the raw packet: pymavlink's tools read it).
"""

from __future__ import annotations

import errno
import logging
import math
import os
import select
import socket
import struct
import time
from collections.abc import Callable
from typing import Any, BinaryIO

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.link_guard import DropLog, StampGuard  # noqa: E402
from offboard.daemon.mavlink.commands import VehicleCommands  # noqa: E402
from offboard.daemon.mavlink.fence_download import FenceDownload  # noqa: E402
from offboard.daemon.mavlink.frame_peek import unread_frames  # noqa: E402
from offboard.daemon.mavlink.lock_gate import LockGate  # noqa: E402
from offboard.daemon.mavlink.odometry import Odometry, read_odometry  # noqa: E402
from offboard.daemon.mavlink.sending import LinkSender  # noqa: E402
from offboard.daemon.mavlink.stream_trim import StreamTrim, stop_streams_message  # noqa: E402
from offboard.daemon.mavlink.url import parse_udpin  # noqa: E402
from offboard.daemon.output_burst import OutputBurst  # noqa: E402
from swarm_common import faults as fault_plan  # noqa: E402
from swarm_common import px4  # noqa: E402
from swarm_common.faults import FaultInjector  # noqa: E402
from swarm_common.signing import (  # noqa: E402
    INVALID_SIGNATURE_REASON,
    REPLAY_REASONS,
    setup_signing,
)
from swarm_common.world import geodesy  # noqa: E402

mavlink = mavutil.mavlink
log = logging.getLogger(__name__)

COMP_ONBOARD = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
COMP_AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1
MAX_DATAGRAM = 65535
PARSE_ERRORS: tuple[type[Exception], ...] = (
    mavlink.MAVError, struct.error, ValueError, IndexError, TypeError,
)

# the mission-protocol messages of the fence download (offboard.daemon.mavlink.fence_download)
FENCE_KINDS: dict[str, Callable[[FenceDownload, Any, float], None]] = {
    "MISSION_CURRENT": FenceDownload.on_current, "MISSION_COUNT": FenceDownload.on_count,
    "MISSION_ITEM_INT": FenceDownload.on_item, "MISSION_ACK": FenceDownload.on_ack,
}
HEARTBEAT_ASK_S = 0.5  # s between two requests for the vehicle's HEARTBEAT before the lock


class VehicleLink(LinkSender):
    """MAVLink connection of one offboard daemon to its vehicle."""

    def __init__(
        self,
        url: str,
        agent_id: int,
        control_hz: float,
        lockstep: bool,
        tlog: str | None = None,
        signing_key: bytes | None = None,
        faults: FaultInjector | None = None,
        trim_streams: bool = True,
    ) -> None:
        """``faults``: injected faults (docs/faults.md); None: the plan of the scenario this
        process loaded (:func:`swarm_common.faults.injector_for`). ``trim_streams``: ask
        the vehicle to stop the telemetry the daemon does not read
        (:mod:`offboard.daemon.mavlink.stream_trim`)."""
        self.agent_id = agent_id
        self.url = url
        self.conn: Any = None
        self.sock: socket.socket | None = None
        where = parse_udpin(url)
        if where is None:  # udpout/tcp: pymavlink's transport, locked by system id only
            self.conn = mavutil.mavlink_connection(
                url, source_system=agent_id, source_component=COMP_ONBOARD, autoreconnect=True
            )
            self.mav = self.conn.mav
        else:  # own socket: no SO_REUSEADDR, replies to the locked address only
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind(where)
            self.sock.setblocking(False)
            self.mav = mavlink.MAVLink(None, agent_id, COMP_ONBOARD)
        self.mav.robust_parsing = True
        self.signed = signing_key is not None
        if signing_key is not None:
            setup_signing(self.mav, signing_key, link_id=agent_id & 0xFF)
        self._tlog: BinaryIO | None = open(tlog, "wb") if tlog else None  # noqa: SIM115
        self.peer: tuple[str, int] | None = None  # the locked vehicle address
        self.locked = False
        self.heartbeat: Any = None
        self.heartbeat_time = 0.0
        self.odometry: Odometry | None = None
        self.stamps = StampGuard(control_hz, lockstep)
        self.drops = DropLog(f"agent {agent_id}: MAVLink")
        self.gate = LockGate(agent_id, self.drops, self.signed, challenge=self.sock is not None)
        self.commands = VehicleCommands(agent_id, self._send)  # COMMAND_LONG, ACK, retry
        self.fence = FenceDownload(agent_id, self._send)  # the vehicle's stored geofence
        # the vehicle's GPS_GLOBAL_ORIGIN (lat, lon in degrees): the geodetic point of its
        # local frame, about which its fence is read (offboard.daemon.fence_sync)
        self.origin: geodesy.Origin | None = None
        self.statustexts: list[str] = []
        self.failsafe_texts = 0  # STATUSTEXTs of the vehicle that say "failsafe"
        self.offboard_lost_texts = 0  # ... that say "failsafe" and "offboard"
        self.sent = 0
        self.heartbeat_sent_at = -math.inf  # monotonic time of our own last HEARTBEAT
        self.heartbeat_asked_at = -math.inf  # ... of our last request for the vehicle's
        self.custom_mode = 0
        self.critical = False  # the vehicle's HEARTBEAT says a failsafe is active
        self.armed = False
        # latched by every HEARTBEAT that says OFFBOARD, also one read in a backlog that
        # the main loop never samples (a daemon stopped while its vehicle was in OFFBOARD)
        self.offboard_reported = False
        # a packed lockstep process's burst: sends held until the end of its pass
        self.burst: OutputBurst | None = None
        self.faults = faults or fault_plan.injector_for(fault_plan.MAVLINK, agent_id, "offboard")
        self.trim = StreamTrim(trim_streams)

    # -- receive ------------------------------------------------------------------------
    def fileno(self) -> int | None:
        """The socket a ``select`` may wait on (``udpin``); None for pymavlink transports."""
        return None if self.sock is None else self.sock.fileno()

    def poll(self, timeout: float = 0.0) -> None:
        """Read every pending datagram (waiting up to ``timeout`` for the first)."""
        if self.sock is None:
            self._poll_mavutil(timeout)
            return
        if timeout > 0 and not select.select([self.sock], [], [], timeout)[0]:
            return
        while True:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except BlockingIOError:
                return
            except OSError as exc:  # ICMP errors surface here on some kernels
                if exc.errno in (errno.ECONNREFUSED, errno.EINTR):
                    continue
                raise
            self._datagram(data, addr)

    def _reset_parser(self) -> None:
        """One UDP datagram holds whole frames: never carry bytes from one to the next."""
        self.mav.buf = bytearray()
        self.mav.buf_index = 0
        self.mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        self.mav.have_prefix_error = False

    def _datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        if self.faults is not None and self.faults.drop_inbound():
            return
        now = time.monotonic()
        if self.peer is not None and addr != self.peer:
            self.drops.drop("foreign address", f"datagram from {addr[0]}:{addr[1]}", now)
            return
        unread = None if self._tlog is not None else unread_frames(data)
        if unread is not None:  # nothing the daemon reads: dropped undecoded (frame_peek)
            for sysid, compid, kind in unread:
                self._drop_unread(sysid, compid, kind, now)
            return
        self._reset_parser()
        try:
            msgs = self.mav.parse_buffer(data) or []
        except PARSE_ERRORS as exc:
            self.drops.drop("malformed", f"{type(exc).__name__} from {addr}", now)
            return
        for msg in msgs:
            self._accept(msg, addr, now)

    def _poll_mavutil(self, timeout: float) -> None:
        if timeout > 0 and not self.conn.select(timeout):
            return
        while True:
            try:
                msg = self.conn.recv_msg()
            except PARSE_ERRORS as exc:
                self.drops.drop("malformed", type(exc).__name__, time.monotonic())
                continue
            if msg is None:
                return
            self._accept(msg, None, time.monotonic())

    def _accept(self, msg: Any, addr: tuple[str, int] | None, now: float) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            reason = str(getattr(msg, "reason", "bad data"))
            why = "bad data"
            if reason.startswith(INVALID_SIGNATURE_REASON):
                why = "replayed" if reason.endswith(REPLAY_REASONS) else "bad signature"
            self.drops.drop(why, reason, now)
            return
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        claim = not self.locked and (sysid, compid) == (self.agent_id, COMP_AUTOPILOT)
        if claim and not self.gate.fresh(msg, addr):
            return  # signed before the daemon's start: nothing goes back (lock_gate)
        if not self._admit(sysid, compid, kind, now):
            if claim:
                self._ask_heartbeat(addr, now, self.gate.answered(msg, addr))
            return
        if claim and not self.gate.may_lock(addr):  # no answer to the challenge yet
            self._ask_heartbeat(addr, now)
            return
        if not self.locked:  # this HEARTBEAT locks the link
            self.locked = True
            self.peer = addr
            where = f"{addr[0]}:{addr[1]}" if addr else self.url
            log.info("agent %d: link locked to vehicle %d/%d at %s",
                     self.agent_id, self.agent_id, COMP_AUTOPILOT, where)
        self._log(msg.get_msgbuf())
        self._handle(msg, kind, now)
        if self.trim.on_message(kind, now):
            self._send(stop_streams_message(self.agent_id))

    def _admit(self, sysid: int, compid: int, kind: str, now: float) -> bool:
        """False (and counted) unless the message comes from this link's vehicle and, before
        the lock, is a HEARTBEAT."""
        if sysid != self.agent_id or compid != COMP_AUTOPILOT:
            self.drops.drop("foreign system", f"{kind} from {sysid}/{compid}", now)
            return False
        if not self.locked and kind != "HEARTBEAT":
            self.drops.counts["before lock"] = self.drops.counts.get("before lock", 0) + 1
            return False
        return True

    def _ask_heartbeat(self, addr: tuple[str, int] | None, now: float, now_proven: bool = False
                       ) -> None:
        """Before the lock, a decoded (and, with signing, verified) frame of this link's
        vehicle names its address: ask it for its HEARTBEAT at once
        (MAV_CMD_REQUEST_MESSAGE) instead of waiting for its 1 Hz stream, which cost
        every run's start up to a second (docs/performance.md, twenty-second round). At
        most every HEARTBEAT_ASK_S (at once when ``addr`` has ``now_proven`` itself); the
        lock itself still takes the HEARTBEAT. A signed link sends its lock challenge first
        (:mod:`offboard.daemon.mavlink.lock_gate`)."""
        if self.sock is None or addr is None or (
                not now_proven and now - self.heartbeat_asked_at < HEARTBEAT_ASK_S):
            return
        self.heartbeat_asked_at = now
        challenge = self.gate.challenge(addr)
        if challenge is not None:
            self._send(challenge, addr)
        ask = mavlink.MAVLink_command_long_message(
            self.agent_id, COMP_AUTOPILOT, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
            mavlink.MAVLINK_MSG_ID_HEARTBEAT, 0, 0, 0, 0, 0, 0)
        self._send(ask, addr)

    def _drop_unread(self, sysid: int, compid: int, kind: str, now: float) -> None:
        """What :meth:`_accept` does with a message the daemon does not read, from the
        frame's header (:mod:`offboard.daemon.mavlink.frame_peek`): counted, and the stop-streams
        request
        sent again when it is due."""
        if self._admit(sysid, compid, kind, now) and self.trim.on_message(kind, now):
            self._send(stop_streams_message(self.agent_id))

    def _handle(self, msg: Any, kind: str, now: float) -> None:
        if kind == "HEARTBEAT":
            self.heartbeat = msg
            self.heartbeat_time = now
            self.custom_mode = int(msg.custom_mode)
            self.critical = int(msg.system_status) == mavlink.MAV_STATE_CRITICAL
            self.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            self.offboard_reported = self.offboard_reported or self.in_offboard
        elif kind == "ODOMETRY":
            self._odometry(msg, now)
        elif kind == "COMMAND_ACK":
            self.commands.on_ack(msg, now)
        elif kind in FENCE_KINDS:
            FENCE_KINDS[kind](self.fence, msg, now)
        elif kind == "GPS_GLOBAL_ORIGIN":
            got = geodesy.origin_of_e7(int(msg.latitude), int(msg.longitude))
            if isinstance(got, str):
                self.drops.drop(got, "GPS_GLOBAL_ORIGIN", now)
            else:
                self.origin = got
        elif kind == "STATUSTEXT":
            text = str(msg.text)
            self.statustexts = [*self.statustexts[-31:], text]
            low = text.lower()
            if "failsafe" in low:
                self.failsafe_texts += 1
                self.offboard_lost_texts += "offboard" in low

    def _odometry(self, msg: Any, now: float) -> None:
        got = read_odometry(msg, self.stamps, now)
        if isinstance(got, Odometry):
            self.odometry = got
        elif got != "duplicate stamp":
            self.drops.drop(got, f"ODOMETRY time_usec={int(msg.time_usec)}", now)

    def wait_lock(self, timeout: float, stopped: Callable[[], bool], say_every: float) -> bool:
        """Wait for the vehicle's first heartbeat (the link lock), saying what it waits for
        every ``say_every`` s; False on timeout or once ``stopped()``."""
        start = said = time.monotonic()
        while not stopped() and not self.locked:
            self.send_heartbeat()  # udpout/tcp: the vehicle learns of us (udpin: no peer yet)
            self.poll(0.1)
            now = time.monotonic()
            if now - start > timeout:
                return False
            if now - said >= say_every:
                said = now
                log.info("agent %d: waiting for the HEARTBEAT of vehicle %d on %s (%.0f s)",
                         self.agent_id, self.agent_id, self.url, now - start)
        return self.locked

    @property
    def in_offboard(self) -> bool:
        return px4.split_mode(self.custom_mode)[0] == px4.MAIN_OFFBOARD

    def close(self) -> None:
        if self.faults is not None:
            self.faults.close()
        try:
            if self.sock is not None:
                self.sock.close()
            else:
                self.conn.close()
        finally:
            if self._tlog is not None:
                self._tlog.close()
                self._tlog = None
