"""The offboard daemon's MAVLink link to its own vehicle (the companion-computer side).

Listens where the vehicle streams its API link (``udpin:127.0.0.1:<api_remote>``, PX4's
14540 for vehicle 1), talks as system = agent id, component 191 (onboard computer).
Every command waits for its COMMAND_ACK and is retried; the result is returned, never
assumed. Every received and sent message is appended to a ``.tlog`` when one is given
(8-byte big-endian µs timestamp + the raw packet: pymavlink's tools read it).
"""

from __future__ import annotations

import math
import os
import struct
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, BinaryIO, SupportsFloat

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from swarm_common import px4  # noqa: E402

mavlink = mavutil.mavlink

COMP_ONBOARD = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
COMP_AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1
# SET_ATTITUDE_TARGET type_mask: ignore the three body rates
ATT_MASK_IGNORE_RATES = (
    mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)


@dataclass
class Odometry:
    """The latest ODOMETRY of the vehicle (NED, as on the wire): position (m), attitude
    quaternion (w, x, y, z, FRD -> NED) and body FRD velocity (m/s)."""

    time_usec: int
    x: float
    y: float
    z: float
    received: float
    q: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    v_body: tuple[float, float, float] = (0.0, 0.0, 0.0)


class VehicleLink:
    """MAVLink connection of one offboard daemon to its vehicle."""

    def __init__(self, url: str, agent_id: int, tlog: str | None = None) -> None:
        self.agent_id = agent_id
        self.conn = mavutil.mavlink_connection(
            url, source_system=agent_id, source_component=COMP_ONBOARD, autoreconnect=True
        )
        self._tlog: BinaryIO | None = open(tlog, "wb") if tlog else None  # noqa: SIM115
        self.heartbeat: Any = None
        self.heartbeat_time = 0.0
        self.odometry: Odometry | None = None
        self.acks: dict[int, Any] = {}
        self.statustexts: list[str] = []
        self.bad_packets = 0
        self.custom_mode = 0
        self.armed = False

    # -- io ---------------------------------------------------------------------------
    def _log(self, buf: bytes) -> None:
        if self._tlog is not None:
            self._tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + buf)

    def poll(self, timeout: float = 0.0) -> list[Any]:
        """Read every pending message (waiting up to ``timeout`` for the first)."""
        out: list[Any] = []
        if timeout > 0 and not self.conn.select(timeout):
            return out
        while True:
            try:
                msg = self.conn.recv_msg()
            except (OSError, ValueError, struct.error, IndexError, TypeError):
                self.bad_packets += 1
                continue
            if msg is None:
                break
            if msg.get_type() == "BAD_DATA":
                self.bad_packets += 1
                continue
            if msg.get_srcSystem() != self.agent_id:
                continue
            self._log(msg.get_msgbuf())
            self._handle(msg)
            out.append(msg)
        return out

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT" and msg.get_srcComponent() == COMP_AUTOPILOT:
            self.heartbeat = msg
            self.heartbeat_time = time.monotonic()
            self.custom_mode = int(msg.custom_mode)
            self.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        elif kind == "ODOMETRY":
            q = tuple(float(c) for c in msg.q)
            self.odometry = Odometry(
                int(msg.time_usec), msg.x, msg.y, msg.z, time.monotonic(),
                (q[0], q[1], q[2], q[3]), (float(msg.vx), float(msg.vy), float(msg.vz)),
            )
        elif kind == "COMMAND_ACK":
            self.acks[int(msg.command)] = msg
        elif kind == "STATUSTEXT":
            self.statustexts.append(str(msg.text))

    def _send(self, msg: Any) -> None:
        buf = msg.pack(self.conn.mav)
        self.conn.write(buf)
        self._log(buf)

    # -- high level ---------------------------------------------------------------------
    @property
    def in_offboard(self) -> bool:
        return px4.split_mode(self.custom_mode)[0] == px4.MAIN_OFFBOARD

    def wait_heartbeat(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while self.heartbeat is None and time.monotonic() < deadline:
            self.poll(0.1)
        return self.heartbeat is not None

    def send_attitude_target(
        self, time_boot_ms: int, q_wxyz: Iterable[SupportsFloat], thrust_norm: SupportsFloat
    ) -> None:
        """SET_ATTITUDE_TARGET (NED/FRD quaternion, normalised thrust, rates ignored)."""
        q = [float(c) for c in q_wxyz]
        msg = mavlink.MAVLink_set_attitude_target_message(
            int(time_boot_ms) & 0xFFFFFFFF,
            self.agent_id,
            COMP_AUTOPILOT,
            ATT_MASK_IGNORE_RATES,
            q,
            0.0,
            0.0,
            0.0,
            float(thrust_norm),
        )
        self._send(msg)

    def command(
        self, command: int, params: list[float], retries: int = 3, timeout: float = 1.0
    ) -> int | None:
        """COMMAND_LONG with retries; returns the MAV_RESULT, or None if never acknowledged."""
        p = [float(x) for x in params] + [math.nan] * (7 - len(params))
        for attempt in range(retries):
            self.acks.pop(command, None)
            msg = mavlink.MAVLink_command_long_message(
                self.agent_id, COMP_AUTOPILOT, command, attempt, *p[:7]
            )
            self._send(msg)
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                self.poll(0.05)
                ack = self.acks.get(command)
                if ack is not None:
                    return int(ack.result)
        return None

    def set_offboard(self) -> int | None:
        return self.command(
            mavlink.MAV_CMD_DO_SET_MODE,
            [
                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
                px4.MAIN_OFFBOARD,
                0,
            ],
        )

    def set_message_interval(self, msg_id: int, interval_s: float) -> int | None:
        """MAV_CMD_SET_MESSAGE_INTERVAL on this link (param2 in µs); the MAV_RESULT or None."""
        return self.command(
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, [msg_id, round(interval_s * 1e6)]
        )

    def arm(self) -> int | None:
        return self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1, 0])  # param1 1 = arm

    def close(self) -> None:
        try:
            self.conn.close()
        finally:
            if self._tlog is not None:
                self._tlog.close()
                self._tlog = None
