"""The receive side of the GCS link: per-system-id vehicle state from MAVLink datagrams.

Vehicles are told apart by the MAVLink system id (= agent id). One pymavlink
``MAVLink`` parser object reads every datagram (MAVLink 2, common dialect). Per system
id :class:`LinkTracker` keeps heartbeat age, message rate, PX4 mode, armed state,
position and velocity (converted NED -> ENU; from LOCAL_POSITION_NED or ODOMETRY, with
the time of the last one), attitude (ATTITUDE_QUATERNION, ODOMETRY, or ATTITUDE: PX4's
normal GCS set streams ATTITUDE at 15 Hz and no quaternion), STATUSTEXT and mode/arming changes as
:class:`LinkEvent`, and hands a COMMAND_ACK to the :class:`PendingAck` awaiting it.
Malformed packets are counted, never raised. No socket here: the caller feeds datagrams.
"""

from __future__ import annotations

import logging
import math
import re
import threading
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from swarm_common import signing
from swarm_common.frames import ned_to_enu, quat_from_rotm, rotm_from_euler, rotm_from_quat
from swarm_common.px4 import wire_to_int32

from .command_retry import PendingAck
from .px4modes import decode_px4_mode

log = logging.getLogger(__name__)

LOCAL_FRAMES = (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD)
BODY_FRAMES = (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED)
# vehicle-sim's report of frames its links rejected (totals since start, docs/security.md)
REJECTED_RE = re.compile(r"^rejected (\d+) unsigned (\d+) badsig (\d+) replay")
GCS_SIGNING_LINK_ID = 200  # the ground station's signing link id (vehicles use 0, daemons i)
# what a well-formed message with absurd field values can raise in a handler
_CONTENT_ERRORS = (ArithmeticError, LookupError, TypeError, ValueError, AttributeError)

Addr = tuple[str, int]


@dataclass
class LinkVehicle:
    """What the link knows about one system id (a copy is handed out by snapshots)."""

    sysid: int
    addr: Addr | None = None
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
    pos_t: float | None = None  # clock() time of the last position (None: none yet)
    time_boot_ms: int = 0
    sim_s: float | None = None  # the vehicle's latest clock stamp (time_boot_ms, s)
    hb_sim_s: float | None = None  # the link's sim clock when its last heartbeat came
    sensors_ok: bool | None = None
    params: dict[str, float] = field(default_factory=dict)  # PARAM_VALUEs heard, decoded
    battery_pct: int = -1
    lost: bool = False
    statustexts: int = 0
    last_statustext: str = ""
    rejected: int = 0  # frames this vehicle's links rejected (its last "rejected" report)
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


class LinkTracker:
    """Thread-safe per-system-id state; :meth:`feed` is called from the reader thread."""

    def __init__(
        self,
        clock: Callable[[], float],
        source_system: int,
        source_component: int,
        max_events: int = 2000,
    ) -> None:
        self.clock = clock
        self._rx = mavlink.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
        self._rx.robust_parsing = True
        self._lock = threading.Lock()
        self._vehicles: dict[int, LinkVehicle] = {}
        self._events: deque[LinkEvent] = deque(maxlen=max_events)
        self.sim_s: float | None = None  # the link's sim clock: the latest vehicle stamp
        self.last_rx: float | None = None  # clock() of the last message from any vehicle
        self._pending: dict[tuple[int, int], PendingAck] = {}
        self.bad_packets = 0
        self.packets = 0
        self.rejected = 0  # frames that failed signature checks here (signing on)
        self.rejected_replay = 0  # ... of them replayed or reflected (claiming our own id)
        self.signed = False
        self._handlers: dict[str, Callable[[LinkVehicle, Any, float], None]] = {
            "HEARTBEAT": self._on_heartbeat,
            "LOCAL_POSITION_NED": self._on_local_position,
            "ODOMETRY": self._on_odometry,
            "ATTITUDE_QUATERNION": self._on_attitude,
            "ATTITUDE": self._on_attitude_euler,
            "SYS_STATUS": self._on_sys_status,
            "STATUSTEXT": self._on_statustext,
            "PARAM_VALUE": self._on_param_value,
            "COMMAND_ACK": self._on_command_ack,
        }

    def enable_signing(self, key: bytes) -> None:
        """Accept only frames signed with ``key`` (MAVLink 2 signing); the others are
        counted in :attr:`rejected`, replayed or reflected ones (a stream's timestamp not
        above its last, a new stream older than 60 s, a frame claiming this ground
        station's own system and component) also in :attr:`rejected_replay`."""
        signing.setup_signing(self._rx, key, GCS_SIGNING_LINK_ID)
        self.signed = True

    # -- parsing -------------------------------------------------------------------
    def feed(self, data: bytes, addr: Addr) -> None:
        """Parse one datagram from ``addr``."""
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
                    reason = str(getattr(msg, "reason", ""))
                    if reason.startswith(signing.INVALID_SIGNATURE_REASON):
                        self.rejected += 1
                        self.rejected_replay += reason.endswith(signing.REPLAY_REASONS)
                    else:
                        self.bad_packets += 1
                    continue
                self.packets += 1
                try:
                    self._handle(msg, addr, now)
                except _CONTENT_ERRORS as exc:  # a well-formed packet with absurd content
                    self.bad_packets += 1
                    log.debug("bad %s from %s: %r", msg.get_type(), addr, exc)

    def _vehicle(self, sysid: int, addr: Addr, now: float) -> LinkVehicle:
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

    def _handle(self, msg: Any, addr: Addr, now: float) -> None:
        """Autopilot messages (and any COMMAND_ACK) update the sender's :class:`LinkVehicle`."""
        mtype = msg.get_type()
        if msg.get_srcComponent() != mavlink.MAV_COMP_ID_AUTOPILOT1 and mtype != "COMMAND_ACK":
            return
        v = self._vehicle(msg.get_srcSystem(), addr, now)
        v.last_msg = now
        self.last_rx = now
        if v.lost and mtype != "COMMAND_ACK":  # any message of its autopilot: it is back
            v.lost = False
            self._event(now, v.sysid, "link", "link regained", mavlink.MAV_SEVERITY_NOTICE)
        v.msg_count += 1
        stamp = getattr(msg, "time_boot_ms", None)
        if isinstance(stamp, int) and stamp > 0:  # the vehicle's (sim) clock
            t = stamp / 1000.0
            v.sim_s = t if v.sim_s is None else max(v.sim_s, t)
            self.sim_s = t if self.sim_s is None else max(self.sim_s, t)
        handler = self._handlers.get(mtype)
        if handler is not None:
            handler(v, msg, now)

    # -- per-message handlers (under self._lock) -----------------------------------
    def _on_heartbeat(self, v: LinkVehicle, msg: Any, now: float) -> None:
        if msg.type == mavlink.MAV_TYPE_GCS:
            return
        v.last_heartbeat = now
        v.hb_sim_s = self.sim_s
        v.base_mode = msg.base_mode
        v.autopilot = msg.autopilot
        v.system_status = msg.system_status
        mode = decode_px4_mode(msg.custom_mode, msg.base_mode)
        if mode != v.mode:
            if v.mode != "?":
                text = f"mode {v.mode} -> {mode}"
                self._event(now, v.sysid, "mode", text, mavlink.MAV_SEVERITY_NOTICE)
            v.mode = mode
        v.custom_mode = msg.custom_mode
        armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if armed != v.armed:
            text = "armed" if armed else "disarmed"
            self._event(now, v.sysid, "armed", text, mavlink.MAV_SEVERITY_NOTICE)
            v.armed = armed

    def _on_local_position(self, v: LinkVehicle, msg: Any, now: float) -> None:
        v.pos_enu = _enu(msg.x, msg.y, msg.z)
        v.vel_enu = _enu(msg.vx, msg.vy, msg.vz)
        v.time_boot_ms = msg.time_boot_ms
        v.pos_t = now

    def _on_odometry(self, v: LinkVehicle, msg: Any, now: float) -> None:
        """Position in a local frame; velocity in a local or body frame (body: rotate by q)."""
        if msg.frame_id in LOCAL_FRAMES:
            v.pos_enu = _enu(msg.x, msg.y, msg.z)
            v.pos_t = now
        vel = (msg.vx, msg.vy, msg.vz)
        q = tuple(float(c) for c in msg.q)
        if msg.child_frame_id in LOCAL_FRAMES:
            v.vel_enu = _enu(*vel)
        elif msg.child_frame_id in BODY_FRAMES:
            if all(math.isfinite(c) for c in q) and abs(np.linalg.norm(q) - 1) < 0.1:
                v.vel_enu = _enu(*(rotm_from_quat(np.array(q)) @ np.array(vel)))
        v.q_ned = q  # type: ignore[assignment]

    def _on_attitude(self, v: LinkVehicle, msg: Any, now: float) -> None:
        v.q_ned = (msg.q1, msg.q2, msg.q3, msg.q4)

    def _on_attitude_euler(self, v: LinkVehicle, msg: Any, now: float) -> None:
        """ATTITUDE: roll, pitch, yaw (rad, FRD relative to NED, ZYX) -> NED quaternion."""
        e = (float(msg.roll), float(msg.pitch), float(msg.yaw))
        if all(math.isfinite(c) for c in e):
            q = quat_from_rotm(rotm_from_euler(*e))
            v.q_ned = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    def _on_sys_status(self, v: LinkVehicle, msg: Any, now: float) -> None:
        need = msg.onboard_control_sensors_present & msg.onboard_control_sensors_enabled
        v.sensors_ok = (need & ~msg.onboard_control_sensors_health) == 0
        v.battery_pct = int(msg.battery_remaining)

    def _on_param_value(self, v: LinkVehicle, msg: Any, now: float) -> None:
        """A parameter's value (INT32 decoded from PX4's bytewise encoding)."""
        name = msg.param_id
        if isinstance(name, bytes | bytearray):
            name = name.decode("ascii", "replace")
        name = str(name).rstrip("\x00")
        value = float(msg.param_value)
        if msg.param_type == mavlink.MAV_PARAM_TYPE_INT32:
            value = float(wire_to_int32(value))
        if name and math.isfinite(value):
            v.params[name] = value

    def _on_statustext(self, v: LinkVehicle, msg: Any, now: float) -> None:
        text = msg.text
        if isinstance(text, bytes | bytearray):
            text = text.decode("utf-8", "replace")
        text = str(text).rstrip("\x00")
        v.statustexts += 1
        v.last_statustext = text
        m = REJECTED_RE.match(text)
        if m is not None:
            v.rejected = sum(int(g) for g in m.groups())
        self._event(now, v.sysid, "statustext", text, int(msg.severity))

    def _on_command_ack(self, v: LinkVehicle, msg: Any, now: float) -> None:
        pend = self._pending.get((v.sysid, msg.command))
        if pend is None:
            return
        if msg.result == mavlink.MAV_RESULT_IN_PROGRESS:
            pend.progress = now
        else:
            pend.result = int(msg.result)
            pend.event.set()

    # -- periodic --------------------------------------------------------------------
    def update(
        self, now: float, heartbeat_timeout_s: float, caught_up: float | None = None,
    ) -> list[Addr]:
        """Update rates, flag lost links (:meth:`silent`); return every address.
        ``caught_up``: the last clock() time the caller had read every datagram that had
        arrived (default ``now``)."""
        targets: list[Addr] = []
        seen_to = now if caught_up is None else min(now, caught_up)
        with self._lock:
            for v in self._vehicles.values():
                dt = now - v._rate_t
                if dt >= 0.9:
                    v.rate_hz = (v.msg_count - v._rate_n) / dt
                    v._rate_t, v._rate_n = now, v.msg_count
                if not v.lost and self._silent(v, seen_to, heartbeat_timeout_s):
                    v.lost = True
                    age = v.heartbeat_age(now)
                    text = f"link lost (heartbeat {_age(age)})"
                    self._event(now, v.sysid, "link", text, mavlink.MAV_SEVERITY_CRITICAL)
                if v.addr is not None:
                    targets.append(v.addr)
        return targets

    def _silent(self, v: LinkVehicle, seen_to: float, timeout_s: float) -> bool:
        """A vehicle's link is lost when nothing of its autopilot (a heartbeat or any other
        message: one late or dropped heartbeat of a link that carries its 15 Hz attitude
        is no loss) was read for ``timeout_s`` (wall clock, up to ``seen_to``: when every
        datagram that had arrived was read, so a reader starved by load sees no silence that
        is not there) AND, while the others' stamps move on, its own sim clock fell
        ``timeout_s`` behind theirs (a lockstep run slower than the wall is no silence);
        when nothing at all arrives for ``timeout_s`` (the simulator gone), the wall clock
        alone decides."""
        if seen_to - v.last_msg <= timeout_s:
            return False
        link_quiet = self.last_rx is None or seen_to - self.last_rx > timeout_s
        if link_quiet or self.sim_s is None:
            return True
        return v.sim_s is None or self.sim_s - v.sim_s > timeout_s

    # -- snapshots and command bookkeeping -------------------------------------------
    def vehicles(self) -> dict[int, LinkVehicle]:
        """A consistent copy of every tracked vehicle."""
        with self._lock:
            return {k: replace(v, params=dict(v.params)) for k, v in self._vehicles.items()}

    def drain_events(self) -> list[LinkEvent]:
        with self._lock:
            out = list(self._events)
            self._events.clear()
        return out

    def address(self, sysid: int) -> Addr | None:
        """Where ``sysid`` streams from (None: never heard)."""
        with self._lock:
            v = self._vehicles.get(sysid)
            return v.addr if v is not None else None

    @contextmanager
    def awaiting_ack(self, sysid: int, command: int) -> Iterator[PendingAck]:
        """Register a :class:`PendingAck` for ``(sysid, command)`` for the ``with`` body."""
        pend = PendingAck()
        key = (sysid, command)
        with self._lock:
            self._pending[key] = pend
        try:
            yield pend
        finally:
            with self._lock:
                if self._pending.get(key) is pend:
                    del self._pending[key]


def _enu(x: float, y: float, z: float) -> tuple[float, float, float]:
    e = ned_to_enu(np.array([x, y, z], dtype=float))
    return (float(e[0]), float(e[1]), float(e[2]))


def _age(age: float | None) -> str:
    return "never" if age is None else f"{age:.1f}s"
