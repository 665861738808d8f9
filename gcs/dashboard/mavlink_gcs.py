"""The ground station's MAVLink link: one UDP socket on 127.0.0.1:14550+offset.

Every vehicle streams its GCS link to this port (``swarm_common.ports``); vehicles are
told apart by the MAVLink system id (= agent id). One pymavlink ``MAVLink`` parser
object reads every datagram (MAVLink 2, common dialect). Per system id the link
tracks heartbeat age, message rate, PX4 mode, armed state, position and velocity
(converted NED -> ENU), STATUSTEXT and mode/arming changes as events. Malformed
packets are counted, never raised.

Commands are COMMAND_LONG sent to the address the vehicle streams from; the caller
waits for the matching COMMAND_ACK with a per-attempt timeout and retries (the
``confirmation`` field counts the retries). :meth:`MavlinkGcs.send_command` blocks;
:meth:`MavlinkGcs.command` is the ``async`` twin for an asyncio (Textual) loop.

The socket runs in a daemon thread; no Textual here, so all of it is unit-testable
(:meth:`MavlinkGcs.feed` takes a datagram directly).
"""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from swarm_common.frames import ned_to_enu, rotm_from_quat
from swarm_common.ports import GCS_PORT

from .px4modes import MAV_RESULT_NAMES, CommandSpec, decode_px4_mode

log = logging.getLogger(__name__)

LOCAL_FRAMES = (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD)
BODY_FRAMES = (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED)
# what a well-formed message with absurd field values can raise in _handle
_CONTENT_ERRORS = (ArithmeticError, LookupError, TypeError, ValueError, AttributeError)


@dataclass
class LinkVehicle:
    """What the link knows about one system id (a copy is handed out by snapshots)."""

    sysid: int
    addr: tuple[str, int] | None = None
    first_seen: float = 0.0
    last_msg: float = 0.0
    last_heartbeat: float | None = None
    msg_count: int = 0
    rate_hz: float = 0.0
    mode: str = "?"
    custom_mode: int = -1
    base_mode: int = 0
    armed: bool = False
    system_status: int = 0
    autopilot: int = 0
    pos_enu: tuple[float, float, float] | None = None
    vel_enu: tuple[float, float, float] | None = None
    q_ned: tuple[float, float, float, float] | None = None
    time_boot_ms: int = 0
    sensors_ok: bool | None = None
    battery_pct: int = -1
    lost: bool = False
    statustexts: int = 0
    last_statustext: str = ""
    # rate bookkeeping
    _rate_t: float = 0.0
    _rate_n: int = 0

    def heartbeat_age(self, now: float) -> float | None:
        return None if self.last_heartbeat is None else max(0.0, now - self.last_heartbeat)


@dataclass(frozen=True)
class LinkEvent:
    """Something the operator should read: STATUSTEXT, mode/arming change, link loss."""

    t: float  # clock() time
    sysid: int
    kind: str  # statustext | mode | armed | link | ack
    text: str
    severity: int = mavlink.MAV_SEVERITY_INFO  # MAV_SEVERITY (0 emergency .. 7 debug)


@dataclass(frozen=True)
class CommandResult:
    """Outcome of one COMMAND_LONG: ``result`` is MAV_RESULT or None (no ACK / no link)."""

    sysid: int
    command: int
    label: str
    result: int | None
    attempts: int
    elapsed_s: float
    note: str = ""

    @property
    def ok(self) -> bool:
        return self.result == mavlink.MAV_RESULT_ACCEPTED

    @property
    def result_name(self) -> str:
        if self.result is None:
            return self.note or "TIMEOUT"
        return MAV_RESULT_NAMES.get(self.result, str(self.result))

    def describe(self) -> str:
        tries = "1 try" if self.attempts == 1 else f"{self.attempts} tries"
        return f"#{self.sysid} {self.label}: {self.result_name} ({tries})"


@dataclass
class _Pending:
    event: threading.Event = field(default_factory=threading.Event)
    result: int | None = None
    progress: float = 0.0


class MavlinkGcs:
    """The GCS UDP link. ``start()`` binds and starts the reader thread."""

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
    ) -> None:
        self.host = host
        self.port = GCS_PORT + port_offset if port is None else port
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.clock = clock
        self._send_heartbeat = send_heartbeat
        self._rx = mavlink.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
        self._rx.robust_parsing = True
        self._tx = mavlink.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
        self._tx_lock = threading.Lock()
        self._lock = threading.Lock()
        self._vehicles: dict[int, LinkVehicle] = {}
        self._events: deque[LinkEvent] = deque(maxlen=max_events)
        self._pending: dict[tuple[int, int], _Pending] = {}
        self.bad_packets = 0
        self.packets = 0
        self.sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._last_tick = 0.0
        self._last_gcs_hb = 0.0

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
        assert self.sock is not None
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65535)
            except TimeoutError:
                data = b""
            except OSError:
                if self._stop.is_set():
                    break
                time.sleep(0.05)
                continue
            if data:
                self.feed(data, addr)
            now = self.clock()
            if now - self._last_tick >= 0.5:
                self.tick(now)

    # -- receive -----------------------------------------------------------------
    def feed(self, data: bytes, addr: tuple[str, int]) -> None:
        """Parse one datagram from ``addr`` (called by the reader thread, or tests)."""
        rx = self._rx
        try:
            msgs = rx.parse_buffer(data) or []
        except mavlink.MAVError as exc:  # pymavlink raises on some input even when robust
            msgs = []
            self.bad_packets += 1
            log.debug("bad MAVLink datagram from %s: %s", addr, exc)
        if rx.buf_len() > 0:  # a datagram holds whole packets: leftovers are a truncation
            self.bad_packets += 1
            rx.buf = bytearray()
            rx.buf_index = 0
            rx.expected_length = mavlink.HEADER_LEN_V1 + 2
        if not msgs:
            return
        now = self.clock()
        with self._lock:
            for msg in msgs:
                if msg.get_type() == "BAD_DATA":
                    self.bad_packets += 1
                    continue
                self.packets += 1
                try:
                    self._handle(msg, addr, now)
                except _CONTENT_ERRORS as exc:  # a well-formed packet with absurd content
                    self.bad_packets += 1
                    log.debug("bad %s from %s: %r", msg.get_type(), addr, exc)

    def _vehicle(self, sysid: int, addr: tuple[str, int], now: float) -> LinkVehicle:
        v = self._vehicles.get(sysid)
        if v is None:
            v = LinkVehicle(sysid=sysid, first_seen=now, _rate_t=now)
            self._vehicles[sysid] = v
        v.addr = addr
        return v

    def _event(
        self,
        now: float,
        sysid: int,
        kind: str,
        text: str,
        severity: int = mavlink.MAV_SEVERITY_INFO,
    ) -> None:
        self._events.append(LinkEvent(now, sysid, kind, text, severity))

    def _handle(self, msg: object, addr: tuple[str, int], now: float) -> None:
        sysid = msg.get_srcSystem()  # type: ignore[attr-defined]
        mtype = msg.get_type()  # type: ignore[attr-defined]
        comp = msg.get_srcComponent()  # type: ignore[attr-defined]
        if comp != mavlink.MAV_COMP_ID_AUTOPILOT1 and mtype != "COMMAND_ACK":
            return
        v = self._vehicle(sysid, addr, now)
        v.last_msg = now
        v.msg_count += 1
        if mtype == "HEARTBEAT":
            if msg.type == mavlink.MAV_TYPE_GCS:  # type: ignore[attr-defined]
                return
            v.last_heartbeat = now
            if v.lost:
                v.lost = False
                self._event(now, sysid, "link", "link regained", mavlink.MAV_SEVERITY_NOTICE)
            v.base_mode = msg.base_mode  # type: ignore[attr-defined]
            v.autopilot = msg.autopilot  # type: ignore[attr-defined]
            v.system_status = msg.system_status  # type: ignore[attr-defined]
            mode = decode_px4_mode(msg.custom_mode, msg.base_mode)  # type: ignore[attr-defined]
            if mode != v.mode:
                if v.mode != "?":
                    text = f"mode {v.mode} -> {mode}"
                    self._event(now, sysid, "mode", text, mavlink.MAV_SEVERITY_NOTICE)
                v.mode = mode
            v.custom_mode = msg.custom_mode  # type: ignore[attr-defined]
            base_mode: int = msg.base_mode  # type: ignore[attr-defined]
            armed = bool(base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            if armed != v.armed:
                text = "armed" if armed else "disarmed"
                self._event(now, sysid, "armed", text, mavlink.MAV_SEVERITY_NOTICE)
                v.armed = armed
        elif mtype == "LOCAL_POSITION_NED":
            m = msg
            v.pos_enu = _enu(m.x, m.y, m.z)  # type: ignore[attr-defined]
            v.vel_enu = _enu(m.vx, m.vy, m.vz)  # type: ignore[attr-defined]
            v.time_boot_ms = m.time_boot_ms  # type: ignore[attr-defined]
        elif mtype == "ODOMETRY":
            m = msg
            if m.frame_id in LOCAL_FRAMES:  # type: ignore[attr-defined]
                v.pos_enu = _enu(m.x, m.y, m.z)  # type: ignore[attr-defined]
            vel = (m.vx, m.vy, m.vz)  # type: ignore[attr-defined]
            q = tuple(float(c) for c in m.q)  # type: ignore[attr-defined]
            if m.child_frame_id in LOCAL_FRAMES:  # type: ignore[attr-defined]
                v.vel_enu = _enu(*vel)
            elif m.child_frame_id in BODY_FRAMES:  # type: ignore[attr-defined]
                if all(math.isfinite(c) for c in q) and abs(np.linalg.norm(q) - 1) < 0.1:
                    v.vel_enu = _enu(*(rotm_from_quat(np.array(q)) @ np.array(vel)))
            v.q_ned = q  # type: ignore[assignment]
        elif mtype == "ATTITUDE_QUATERNION":
            v.q_ned = (msg.q1, msg.q2, msg.q3, msg.q4)  # type: ignore[attr-defined]
        elif mtype == "SYS_STATUS":
            m = msg
            need = m.onboard_control_sensors_present & m.onboard_control_sensors_enabled  # type: ignore[attr-defined]
            v.sensors_ok = (need & ~m.onboard_control_sensors_health) == 0  # type: ignore[attr-defined]
            v.battery_pct = int(m.battery_remaining)  # type: ignore[attr-defined]
        elif mtype == "STATUSTEXT":
            text = msg.text  # type: ignore[attr-defined]
            if isinstance(text, bytes | bytearray):
                text = text.decode("utf-8", "replace")
            text = str(text).rstrip("\x00")
            v.statustexts += 1
            v.last_statustext = text
            self._event(now, sysid, "statustext", text, int(msg.severity))  # type: ignore[attr-defined]
        elif mtype == "COMMAND_ACK":
            pend = self._pending.get((sysid, msg.command))  # type: ignore[attr-defined]
            if pend is not None:
                if msg.result == mavlink.MAV_RESULT_IN_PROGRESS:  # type: ignore[attr-defined]
                    pend.progress = now
                else:
                    pend.result = int(msg.result)  # type: ignore[attr-defined]
                    pend.event.set()

    def tick(self, now: float | None = None) -> None:
        """Update rates, detect lost links, send the GCS heartbeat (reader thread)."""
        now = self.clock() if now is None else now
        self._last_tick = now
        targets: list[tuple[str, int]] = []
        with self._lock:
            for v in self._vehicles.values():
                dt = now - v._rate_t
                if dt >= 0.9:
                    v.rate_hz = (v.msg_count - v._rate_n) / dt
                    v._rate_t, v._rate_n = now, v.msg_count
                age = v.heartbeat_age(now)
                silent = (now - v.first_seen) if age is None else age
                if not v.lost and silent > self.heartbeat_timeout_s:
                    v.lost = True
                    text = f"link lost (heartbeat {_age(age)})"
                    self._event(now, v.sysid, "link", text, mavlink.MAV_SEVERITY_CRITICAL)
                if v.addr is not None:
                    targets.append(v.addr)
        if self._send_heartbeat and now - self._last_gcs_hb >= 1.0 and self.sock is not None:
            self._last_gcs_hb = now
            with self._tx_lock:
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

    # -- snapshots -----------------------------------------------------------------
    def vehicles(self) -> dict[int, LinkVehicle]:
        """A consistent copy of every tracked vehicle."""
        with self._lock:
            return {k: replace(v) for k, v in self._vehicles.items()}

    def drain_events(self) -> list[LinkEvent]:
        with self._lock:
            out = list(self._events)
            self._events.clear()
        return out

    # -- commands ------------------------------------------------------------------
    def _send_long(self, sysid: int, command: int, params: tuple[float, ...], conf: int) -> bool:
        with self._lock:
            v = self._vehicles.get(sysid)
            addr = v.addr if v is not None else None
        if addr is None or self.sock is None:
            return False
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        with self._tx_lock:
            buf = self._tx.command_long_encode(sysid, 1, command, conf & 0xFF, *p[:7]).pack(
                self._tx
            )
        try:
            self.sock.sendto(buf, addr)
        except OSError:
            return False
        return True

    def _begin(self, sysid: int, command: int) -> _Pending:
        pend = _Pending()
        with self._lock:
            self._pending[(sysid, command)] = pend
        return pend

    def _end(self, sysid: int, command: int, pend: _Pending) -> None:
        with self._lock:
            if self._pending.get((sysid, command)) is pend:
                del self._pending[(sysid, command)]

    def send_command(
        self,
        sysid: int,
        spec: CommandSpec,
        timeout_s: float = 1.0,
        retries: int = 2,
    ) -> CommandResult:
        """Send ``spec`` to ``sysid`` and block until its COMMAND_ACK (or give up)."""
        t0 = self.clock()
        pend = self._begin(sysid, spec.command)
        attempts = 0
        try:
            for attempt in range(retries + 1):
                if not self._send_long(sysid, spec.command, spec.params, attempt):
                    return CommandResult(
                        sysid, spec.command, spec.label, None, attempt, 0.0, "NO-LINK"
                    )
                attempts += 1
                if pend.event.wait(timeout_s):
                    break
        finally:
            self._end(sysid, spec.command, pend)
        return CommandResult(
            sysid, spec.command, spec.label, pend.result, attempts, self.clock() - t0
        )

    async def command(
        self,
        sysid: int,
        spec: CommandSpec,
        timeout_s: float = 1.0,
        retries: int = 2,
        poll_s: float = 0.02,
    ) -> CommandResult:
        """``async`` :meth:`send_command`: polls the ACK without blocking the loop."""
        t0 = self.clock()
        pend = self._begin(sysid, spec.command)
        attempts = 0
        try:
            for attempt in range(retries + 1):
                if not self._send_long(sysid, spec.command, spec.params, attempt):
                    return CommandResult(
                        sysid, spec.command, spec.label, None, attempt, 0.0, "NO-LINK"
                    )
                attempts += 1
                deadline = self.clock() + timeout_s
                while not pend.event.is_set() and self.clock() < deadline:
                    await asyncio.sleep(poll_s)
                if pend.event.is_set():
                    break
        finally:
            self._end(sysid, spec.command, pend)
        return CommandResult(
            sysid, spec.command, spec.label, pend.result, attempts, self.clock() - t0
        )


def _enu(x: float, y: float, z: float) -> tuple[float, float, float]:
    e = ned_to_enu(np.array([x, y, z], dtype=float))
    return (float(e[0]), float(e[1]), float(e[2]))


def _age(age: float | None) -> str:
    return "never" if age is None else f"{age:.1f}s"
