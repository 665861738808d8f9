"""Information requests a ground station sends on connect: PING, REQUEST_DATA_STREAM,
MAV_CMD_REQUEST_PROTOCOL_VERSION, MAV_CMD_GET_HOME_POSITION; and the simulated battery.

* PING with target 0/0 is a request: answered to the sender, as PX4 does, with the same
  ``time_usec`` and ``seq`` and the sender as target. A PING addressed to us is an answer
  to a ping we never send: ignored.
* REQUEST_DATA_STREAM (the legacy stream groups, still sent by QGroundControl and
  MAVProxy): the group's messages (:data:`DATA_STREAM_GROUPS`, the grouping ArduPilot
  uses, restricted to what this vehicle sends) are set to ``req_message_rate`` Hz for the
  requesting peer only (starting from its link's set, docs/px4/streams.md), or switched
  off with ``start_stop`` = 0; ``req_message_rate`` 0 with start puts the group back on
  its link's default rates. A rate is delivered, within the caps of
  :mod:`vehicle_sim.autopilot.streams` and the peer's byte budget
  (:mod:`vehicle_sim.link.endpoint`), which an ordinary client never reaches. The answer is
  a DATA_STREAM per request (stream id, the rate now in force, on/off): a request is
  never met by silence.
  PX4 itself ignores these groups; they are honoured here because MAVProxy relies on them.
* MAV_CMD_REQUEST_PROTOCOL_VERSION: ACCEPTED, then PROTOCOL_VERSION (200, 100..200).
* MAV_CMD_GET_HOME_POSITION (deprecated, QGroundControl still sends it): HOME_POSITION.

Every other information request is answered by the command table
(:mod:`vehicle_sim.services.command`): REQUEST_MESSAGE of a message the vehicle cannot build
(COMPONENT_INFORMATION, COMPONENT_METADATA, ...) is UNSUPPORTED, never silence.

Contract: :class:`vehicle_sim.autopilot.nav.VehicleService`; details in docs/px4/streams.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as M

from vehicle_sim.autopilot import telemetry
from vehicle_sim.physics.battery import BatteryModel

Outcome = tuple[int, M.MAVLink_message | None]
MessageHandler = Callable[[Any, Any, float, float], None]
COMPONENT_AUTOPILOT = M.MAV_COMP_ID_AUTOPILOT1

# MAV_DATA_STREAM group -> the messages of that group this vehicle can stream
DATA_STREAM_GROUPS: dict[int, tuple[int, ...]] = {
    M.MAV_DATA_STREAM_RAW_SENSORS: (M.MAVLINK_MSG_ID_GPS_RAW_INT,),
    M.MAV_DATA_STREAM_EXTENDED_STATUS: (
        M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_GPS_RAW_INT,
        M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
    ),
    M.MAV_DATA_STREAM_RC_CHANNELS: (),
    M.MAV_DATA_STREAM_RAW_CONTROLLER: (M.MAVLINK_MSG_ID_ATTITUDE_TARGET,),
    M.MAV_DATA_STREAM_POSITION: (
        M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    ),
    M.MAV_DATA_STREAM_EXTRA1: (M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION),
    M.MAV_DATA_STREAM_EXTRA2: (M.MAVLINK_MSG_ID_VFR_HUD,),
    M.MAV_DATA_STREAM_EXTRA3: (
        M.MAVLINK_MSG_ID_BATTERY_STATUS, M.MAVLINK_MSG_ID_ALTITUDE,
        M.MAVLINK_MSG_ID_HOME_POSITION,
    ),
}  # fmt: skip
ALL_GROUP_MESSAGES = tuple(sorted({m for ms in DATA_STREAM_GROUPS.values() for m in ms}))
US_PER_S = 1e6
DATA_STREAM_RATE_MAX = 65535  # DATA_STREAM.message_rate is uint16 (Hz)


def group_messages(stream_id: int) -> tuple[int, ...] | None:
    """The messages of a MAV_DATA_STREAM group (ALL: every group); None if unknown."""
    if stream_id == M.MAV_DATA_STREAM_ALL:
        return ALL_GROUP_MESSAGES
    return DATA_STREAM_GROUPS.get(stream_id)


def _peer_key(src: Any) -> Any:
    """The requester as a stream-schedule key (link name, address), or None."""
    if isinstance(src, tuple) and len(src) == 2 and isinstance(src[1], tuple):
        return src
    return None


class InfoService:
    """Attached to one :class:`~vehicle_sim.vehicle.Vehicle` (``vehicle``); owns its
    battery (:attr:`battery`, read by the SYS_STATUS and BATTERY_STATUS builders)."""

    def __init__(self, vehicle: Any) -> None:
        self.vehicle = vehicle
        self.battery = BatteryModel()
        self.pings_answered = 0
        self.data_stream_requests = 0

    def handlers(self) -> dict[int, MessageHandler]:
        """MAVLink message id -> ``handler(msg, src, wall, sim_t)``."""
        return {
            M.MAVLINK_MSG_ID_PING: self._on_ping,
            M.MAVLINK_MSG_ID_REQUEST_DATA_STREAM: self._on_request_data_stream,
        }

    def command_handlers(self) -> dict[int, Callable[[Any, Any], Outcome]]:
        """MAV_CMD -> ``handler(vehicle, command) -> (MAV_RESULT, reply or None)``."""
        return {
            M.MAV_CMD_REQUEST_PROTOCOL_VERSION: self._protocol_version,
            M.MAV_CMD_GET_HOME_POSITION: self._home_position,
        }

    def update(self, sim_t: float) -> None:
        """Once per simulation step: integrate the battery."""
        v = self.vehicle
        dyn = v.dyn
        self.battery.update(sim_t, float(dyn.thrust[v.idx]), float(dyn.hold_thrust()), v.armed)

    # -- messages ---------------------------------------------------------------------
    def _on_ping(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if m.target_system != 0 or m.target_component != 0:
            return  # an answer to a ping of ours (we send none)
        reply = M.MAVLink_ping_message(m.time_usec, m.seq, m.get_srcSystem(), m.get_srcComponent())
        self.pings_answered += 1
        self.vehicle.outbox.append((reply, src))

    def _on_request_data_stream(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if m.target_component not in (0, COMPONENT_AUTOPILOT):
            return  # for another component of this system
        self.data_stream_requests += 1
        mids = group_messages(int(m.req_stream_id))
        streams = self.vehicle.streams
        key = _peer_key(src)
        rate = int(m.req_message_rate)
        on = bool(m.start_stop)
        if mids and key is not None:
            sched = streams.for_peer(key, create=True)
            for mid in (x for x in mids if x in streams):
                if not on:
                    sched.set_interval(mid, -1, wall)
                elif rate <= 0:
                    sched.set_interval(mid, 0, wall)  # back to the default
                else:
                    sched.set_interval(mid, US_PER_S / rate, wall)
        shown = self._rate_now(key, mids) if on else 0
        reply = M.MAVLink_data_stream_message(int(m.req_stream_id), shown, int(on))
        self.vehicle.outbox.append((reply, src))

    def _rate_now(self, key: Any, mids: tuple[int, ...] | None) -> int:
        """The fastest rate (Hz) now in force for the requester among ``mids``."""
        sched = self.vehicle.streams.for_peer(key)
        best = 0.0
        for mid in mids or ():
            if mid in sched:
                iv = sched.interval_us(mid)
                if iv > 0:
                    best = max(best, US_PER_S / iv)
        return min(DATA_STREAM_RATE_MAX, int(math.floor(best + 0.5)))

    # -- commands ---------------------------------------------------------------------
    def _protocol_version(self, vehicle: Any, c: Any) -> Outcome:
        """PX4 answers whatever param1 says (the spec's "1: request")."""
        return M.MAV_RESULT_ACCEPTED, telemetry.protocol_version(vehicle, c.sim_t)

    def _home_position(self, vehicle: Any, c: Any) -> Outcome:
        return M.MAV_RESULT_ACCEPTED, telemetry.home_position(vehicle, c.sim_t)
