"""Telemetry the daemon does not read is switched off on its API link (docs/performance.md).

A PX4 vehicle streams its default telemetry (ATTITUDE, LOCAL_POSITION_NED, VFR_HUD, ...)
to every MAVLink peer, the companion computer included. The daemon reads a few messages of
its vehicle: HEARTBEAT, ODOMETRY, COMMAND_ACK and STATUSTEXT (and the DATA_STREAM answer
to its own request), and MISSION_CURRENT (1 Hz) with the fence download's answers.
Decoding the rest cost it about three pymavlink decodes per control step, and the
simulator one pack and one ``sendto`` each.

So, once the link is locked, the daemon asks its vehicle to stop every legacy stream
group on its link: REQUEST_DATA_STREAM(MAV_DATA_STREAM_ALL, start_stop = 0), the request
MAVProxy uses for the same purpose. It touches the requester's link only (the GCS link
keeps its defaults) and never HEARTBEAT or ODOMETRY, which are not in any group. The
vehicle answers it with DATA_STREAM, so the request needs no COMMAND_ACK bookkeeping.

Self-healing rather than acknowledged: whenever a message of a stream group still
arrives, the request is sent again, at most once per :data:`RETRY_S`. That covers a lost
request, a vehicle that forgot the requester's rates (our simulator resets them when a
peer falls silent; PX4 keeps them only for the life of its MAVLink instance) and a
vehicle restart. A vehicle that ignores the request (PX4 ignores REQUEST_DATA_STREAM)
costs one small message a second and nothing else: the daemon still drops what it does
not read after decoding it, exactly as before.

``offboard --keep-streams`` leaves the vehicle's defaults on (full telemetry in the
daemon's ``.tlog``, at the cost above).
"""

from __future__ import annotations

import os
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

M = mavutil.mavlink

# the vehicle messages the daemon reads (offboard.daemon.mavlink.link.VehicleLink._handle), and
# the answers to its own requests (TIMESYNC: the lock challenge, mavlink.lock_gate; the
# MISSION_* of the fence download, mavlink.fence_download, which MISSION_CURRENT starts;
# GPS_GLOBAL_ORIGIN, about which the fence is read)
READ_KINDS = frozenset({"HEARTBEAT", "ODOMETRY", "COMMAND_ACK", "STATUSTEXT", "DATA_STREAM",
                        "TIMESYNC", "MISSION_CURRENT", "MISSION_COUNT", "MISSION_ITEM_INT",
                        "MISSION_ACK", "GPS_GLOBAL_ORIGIN"})
# the telemetry of the legacy stream groups (ArduPilot's grouping, which MAVProxy and our
# simulator use): receiving one of these means the request has not taken (yet). Messages
# outside every group (MISSION_CURRENT, ...) cannot be stopped this way and never retrigger.
GROUP_KINDS = frozenset({
    "RAW_IMU", "SCALED_PRESSURE", "GPS_RAW_INT", "SYS_STATUS", "EXTENDED_SYS_STATE",
    "RC_CHANNELS", "SERVO_OUTPUT_RAW", "ATTITUDE_TARGET", "GLOBAL_POSITION_INT",
    "LOCAL_POSITION_NED", "ATTITUDE", "ATTITUDE_QUATERNION", "VFR_HUD", "BATTERY_STATUS",
    "ALTITUDE", "HOME_POSITION",
})
RETRY_S = 1.0  # s, at most one request per this period


class StreamTrim:
    """Decides when to (re)send the stop-streams request; pure, no I/O."""

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        self.last_request = -float("inf")
        self.requests = 0  # requests sent so far
        self.unread = 0  # messages received that the daemon does not read

    def on_message(self, kind: str, now: float) -> bool:
        """A message of ``kind`` arrived at ``now`` (monotonic s): True if the request
        should be sent now."""
        if kind in READ_KINDS:
            return False
        self.unread += 1
        return kind in GROUP_KINDS and self.due(now)

    def due(self, now: float) -> bool:
        """True (and books the request) when enabled and none went out in RETRY_S."""
        if not self.enabled or now - self.last_request < RETRY_S:
            return False
        self.last_request = now
        self.requests += 1
        return True


def stop_streams_message(target_system: int) -> Any:
    """REQUEST_DATA_STREAM(ALL, rate 0, stop) to the autopilot of ``target_system``."""
    return M.MAVLink_request_data_stream_message(
        target_system, M.MAV_COMP_ID_AUTOPILOT1, M.MAV_DATA_STREAM_ALL, 0, 0
    )
