"""What the daemon sends its vehicle and how: the sending half of
:class:`offboard.daemon.mavlink.link.VehicleLink` (docs/px4/offboard-component.md).

Its setpoint (SET_ATTITUDE_TARGET) and its own HEARTBEAT as an onboard-computer component
once per :data:`HEARTBEAT_PERIOD_S`, and every other frame of the link (commands, the
requests before the lock): each packed (signed when signing is on) with the link's
sequence number and sent to the locked vehicle only, through the injected faults
(docs/faults.md) or a packed process's output burst (:mod:`offboard.daemon.output_burst`)
when there are; counted in ``sent`` and appended to the ``.tlog`` (8-byte big-endian µs
timestamp + the raw packet) once it went.
"""

from __future__ import annotations

import os
import socket
import struct
import time
from collections.abc import Iterable
from typing import Any, BinaryIO, SupportsFloat

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.link_guard import DropLog  # noqa: E402
from offboard.daemon.output_burst import OutputBurst  # noqa: E402
from swarm_common.faults import FaultInjector  # noqa: E402

mavlink = mavutil.mavlink
COMP_AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1
# SET_ATTITUDE_TARGET type_mask: ignore the three body rates
ATT_MASK_IGNORE_RATES = (
    mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)
HEARTBEAT_PERIOD_S = 1.0  # the daemon's own HEARTBEAT (MAVLink microservice: 1 Hz)


class LinkSender:
    """The sending half of :class:`~offboard.daemon.mavlink.link.VehicleLink`, which sets
    the attributes below in its ``__init__`` and locks ``peer``."""

    agent_id: int
    mav: Any  # the link's pymavlink MAVLink object: sequence number, signing
    conn: Any  # pymavlink's transport (udpout/tcp), else None
    sock: socket.socket | None  # the link's own socket (udpin), else None
    peer: tuple[str, int] | None  # the locked vehicle's address
    faults: FaultInjector | None
    burst: OutputBurst | None  # a packed lockstep process's burst: sends held until its end
    drops: DropLog
    sent: int
    heartbeat_sent_at: float  # monotonic time of our own last HEARTBEAT
    _tlog: BinaryIO | None

    def _log(self, buf: bytes) -> None:
        """Append ``buf`` (received or sent) to the ``.tlog``, if one is kept."""
        if self._tlog is not None:
            self._tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + buf)

    def _send(self, msg: Any, to: tuple[str, int] | None = None) -> None:
        """Pack (signed when signing is on) with the link's sequence number, which goes up
        by one per packed message (mod 256) like ``MAVLink.send`` does, so a receiver's loss
        count (pymavlink ``mavloss``) is right; then send to the locked vehicle (``to``:
        the one address a frame before the lock goes to,
        :meth:`~offboard.daemon.mavlink.link.VehicleLink._ask_heartbeat`)."""
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        dest = self.peer or to
        if self.sock is None:
            self.conn.write(buf)
        elif dest is None:
            return  # nothing goes out before the lock
        elif self.faults is not None:
            self.faults.send((buf, dest), self._sendto)
        elif self.burst is not None:
            self.burst.hold(self._deliver, (buf, dest))
            return
        else:
            self._deliver((buf, dest))
            return
        self.sent += 1
        self._log(buf)

    def _deliver(self, frame: tuple[bytes, tuple[str, int]]) -> None:
        """Send ``frame`` now (also a held one, :mod:`offboard.daemon.output_burst`): counted and
        logged if it went."""
        if self._sendto(frame):
            self.sent += 1
            self._log(frame[0])

    def _sendto(self, frame: tuple[bytes, tuple[str, int]]) -> bool:
        assert self.sock is not None
        try:
            self.sock.sendto(frame[0], frame[1])
        except OSError as exc:  # a full buffer or an ICMP error: the datagram is lost
            self.drops.drop("send failed", str(exc), time.monotonic())
            return False
        return True

    def send_attitude_target(
        self, time_boot_ms: int, q_wxyz: Iterable[SupportsFloat], thrust_norm: SupportsFloat
    ) -> None:
        """SET_ATTITUDE_TARGET (NED/FRD quaternion, normalised thrust, rates ignored)."""
        q = [float(c) for c in q_wxyz]
        msg = mavlink.MAVLink_set_attitude_target_message(
            int(time_boot_ms) & 0xFFFFFFFF, self.agent_id, COMP_AUTOPILOT,
            ATT_MASK_IGNORE_RATES, q, 0.0, 0.0, 0.0, float(thrust_norm),
        )
        self._send(msg)

    def send_heartbeat(self, now: float | None = None) -> bool:
        """Our own HEARTBEAT as an onboard-computer component (MAV_TYPE_ONBOARD_CONTROLLER,
        MAV_AUTOPILOT_INVALID, system = agent id, component 191) once per
        :data:`HEARTBEAT_PERIOD_S`; True when one went out. Signed when signing is on.
        Nothing goes out on a ``udpin`` link before the vehicle's lock (no peer yet)."""
        now = time.monotonic() if now is None else now
        if now - self.heartbeat_sent_at < HEARTBEAT_PERIOD_S:
            return False
        if self.sock is not None and self.peer is None:
            return False
        self.heartbeat_sent_at = now
        self._send(mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
            mavlink.MAV_STATE_ACTIVE, 3,  # mavlink_version: 3 for MAVLink 1.0 and later
        ))
        return True
