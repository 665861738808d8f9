"""MAVLink commands a simulated PX4 vehicle answers (COMMAND_LONG / COMMAND_INT).

:data:`HANDLERS` maps a ``MAV_CMD_*`` to a function ``(vehicle, command) -> Outcome``:
the ``MAV_RESULT_*`` to acknowledge and, for the commands that answer with a message
(GET_MESSAGE_INTERVAL, REQUEST_MESSAGE, REQUEST_AUTOPILOT_CAPABILITIES), that message,
sent right after the COMMAND_ACK. Any other command is acknowledged UNSUPPORTED.
Parameters arrive as floats, NaN where unused (MAVSDK sends NaN): :func:`finite`.
The flight commands (take-off, RTL, land, loiter, reposition, mission start, speed) go
through :mod:`vehicle_sim.autopilot.modes`; docs/px4/modes.md lists them with PX4's semantics.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import px4
from vehicle_sim.autopilot import modes, setpoints, telemetry
from vehicle_sim.autopilot.nav import NavKind, NavTarget
from vehicle_sim.autopilot.state import VehicleState
from vehicle_sim.physics import geo

Outcome = tuple[int, M.MAVLink_message | None]
MSG_ID_LIMIT = 1 << 24  # MAVLink 2 message ids are 24 bits
TRUE_THRESHOLD = 0.5  # a boolean parameter is "on" above this


def finite(x: Any, default: float | None = None) -> float | None:
    """A command parameter, or ``default`` when it is NaN/inf or not a number."""
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return default
    return xf if math.isfinite(xf) else default


def _flag(x: Any, default: float) -> float:
    """A parameter with a finite default (never None)."""
    f = finite(x, default)
    return default if f is None else f


@dataclass(frozen=True)
class Command:
    """One received command, its 7 parameters (COMMAND_INT x/y scaled by 1e-7)."""

    cmd: int
    p: tuple[float, ...]
    wall: float
    sim_t: float
    src: Any = None  # (link name, address) of the requester: rate requests are per peer
    frame: int = M.MAV_FRAME_GLOBAL  # COMMAND_INT's frame; COMMAND_LONG: global, AMSL


def _arm_disarm(v: VehicleState, c: Command) -> Outcome:
    want = finite(c.p[0])
    force = finite(c.p[1], 0.0) == px4.FORCE_MAGIC
    if want is None:
        return M.MAV_RESULT_DENIED, None
    if want > TRUE_THRESHOLD:
        return modes.arm(v, c.sim_t), None
    return modes.disarm(v, force, "forced" if force else ""), None


def _set_mode(v: VehicleState, c: Command) -> Outcome:
    base, main, sub = finite(c.p[0]), finite(c.p[1]), _flag(c.p[2], 0.0)
    if base is None or main is None or not (int(base) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
        return M.MAV_RESULT_UNSUPPORTED, None
    return modes.request_mode(v, int(main), int(sub), c.sim_t), None


def _land(v: VehicleState, c: Command) -> Outcome:
    return modes.request_mode(v, px4.MAIN_AUTO, px4.SUB_AUTO_LAND, c.sim_t), None


def _loiter(v: VehicleState, c: Command) -> Outcome:
    return modes.request_mode(v, px4.MAIN_AUTO, px4.SUB_AUTO_LOITER, c.sim_t), None


def _altitude_enu(v: VehicleState, c: Command, alt: float | None) -> float | None:
    """ENU z (m above the ground/home) of a command's altitude in its frame; None when the
    altitude is not given. Raises ValueError for a frame without an altitude we know."""
    if alt is None:
        return None
    if c.frame in setpoints.GLOBAL_RELATIVE_FRAMES:
        return alt
    if c.frame in setpoints.GLOBAL_AMSL_FRAMES:
        return -geo.down_from_amsl(v.cfg, alt)
    raise ValueError(f"frame {c.frame}")


def _takeoff(v: VehicleState, c: Command) -> Outcome:
    """NAV_TAKEOFF: p7 altitude (AMSL; NaN: MIS_TAKEOFF_ALT above the current altitude;
    :func:`vehicle_sim.autopilot.modes.takeoff_target` has PX4's rule)."""
    try:
        alt = _altitude_enu(v, c, finite(c.p[6]))
    except ValueError:
        return M.MAV_RESULT_UNSUPPORTED, None
    return modes.takeoff(v, alt), None


def _rtl(v: VehicleState, c: Command) -> Outcome:
    return modes.request_mode(v, px4.MAIN_AUTO, px4.SUB_AUTO_RTL, c.sim_t), None


def _reposition(v: VehicleState, c: Command) -> Outcome:
    """DO_REPOSITION: p1 ground speed (m/s, < 0 default), p4 yaw (deg NED, NaN keep),
    p5/p6 latitude/longitude (deg; NaN: here), p7 altitude (frame; NaN: here)."""
    p = v.p()
    lat, lon = finite(c.p[4]), finite(c.p[5])
    try:
        alt = _altitude_enu(v, c, finite(c.p[6]))
    except ValueError:
        return M.MAV_RESULT_UNSUPPORTED, None
    x, y = float(p[0]), float(p[1])
    if lat is not None and lon is not None:
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            return M.MAV_RESULT_DENIED, None
        north, east = geo.ned_from_latlon(v.cfg, lat, lon)
        x, y = east, north  # ENU
    z = float(p[2]) if alt is None else alt
    if z < 0.0:
        return M.MAV_RESULT_DENIED, None
    speed = finite(c.p[0])
    yaw_deg = finite(c.p[3])
    yaw = None if yaw_deg is None else setpoints.yaw_enu_from_ned(math.radians(yaw_deg))
    spd = speed if speed is not None and speed > 0 else None
    target = NavTarget(NavKind.GOTO, np.array([x, y, z]), yaw, spd)
    return modes.reposition(v, target), None


def _mission_start(v: VehicleState, c: Command) -> Outcome:
    return modes.start_mission(v, c.sim_t), None


SPEED_RESET = -2.0  # DO_CHANGE_SPEED p2: back to the default (-1: no change)


def _change_speed(v: VehicleState, c: Command) -> Outcome:
    """DO_CHANGE_SPEED: p1 speed type (air or ground speed; climb/descent unsupported),
    p2 speed m/s (-1 no change, -2 default; above ``MPC_XY_VEL_MAX``: DENIED)."""
    kind, speed = finite(c.p[0], float(M.SPEED_TYPE_GROUNDSPEED)), finite(c.p[1])
    if kind not in (M.SPEED_TYPE_AIRSPEED, M.SPEED_TYPE_GROUNDSPEED):
        return M.MAV_RESULT_UNSUPPORTED, None
    if speed is None or speed == -1.0:
        return M.MAV_RESULT_ACCEPTED, None
    if speed == SPEED_RESET:
        v.speed_override = None
        return M.MAV_RESULT_ACCEPTED, None
    if not 0.0 < speed <= float(v.params.get("MPC_XY_VEL_MAX")):
        return M.MAV_RESULT_DENIED, None
    v.speed_override = speed
    return M.MAV_RESULT_ACCEPTED, None


def _terminate(v: VehicleState, c: Command) -> Outcome:
    on = _flag(c.p[0], 0.0) > TRUE_THRESHOLD
    return (modes.terminate(v) if on else M.MAV_RESULT_ACCEPTED), None


def _peer_key(c: Command) -> Any:
    """The requester as a stream-schedule key, None when it is not one peer."""
    src = c.src
    if isinstance(src, tuple) and len(src) == 2 and isinstance(src[1], tuple):
        return src
    return None


def _set_interval(v: VehicleState, c: Command) -> Outcome:
    mid, interval_us = finite(c.p[0]), finite(c.p[1])
    if mid is None or interval_us is None or int(mid) not in v.streams:
        return M.MAV_RESULT_UNSUPPORTED, None
    v.streams.for_peer(_peer_key(c), create=True).set_interval(int(mid), interval_us, c.wall)
    return M.MAV_RESULT_ACCEPTED, None


def _get_interval(v: VehicleState, c: Command) -> Outcome:
    mid = finite(c.p[0])
    if mid is None or int(mid) not in v.streams:
        return M.MAV_RESULT_UNSUPPORTED, None
    iv = v.streams.for_peer(_peer_key(c)).interval_us(int(mid))
    reply = M.MAVLink_message_interval_message(int(mid), iv)
    return M.MAV_RESULT_ACCEPTED, reply


def _request_message(v: VehicleState, c: Command) -> Outcome:
    mid = finite(c.p[0])
    msg = None
    if mid is not None and 0 <= mid < MSG_ID_LIMIT:
        msg = telemetry.build(v, int(mid), c.sim_t)
    if msg is None:
        return M.MAV_RESULT_UNSUPPORTED, None
    return M.MAV_RESULT_ACCEPTED, msg


def _request_capabilities(v: VehicleState, c: Command) -> Outcome:
    if _flag(c.p[0], 1.0) > TRUE_THRESHOLD:
        return M.MAV_RESULT_ACCEPTED, telemetry.autopilot_version(v, c.sim_t)
    return M.MAV_RESULT_ACCEPTED, None


# what a client on an unsigned link may ask (docs/security.md): telemetry only
TELEMETRY_COMMANDS = frozenset({
    M.MAV_CMD_SET_MESSAGE_INTERVAL,
    M.MAV_CMD_GET_MESSAGE_INTERVAL,
    M.MAV_CMD_REQUEST_MESSAGE,
    M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    M.MAV_CMD_REQUEST_PROTOCOL_VERSION,
    M.MAV_CMD_GET_HOME_POSITION,
})  # fmt: skip

HANDLERS: dict[int, Callable[[VehicleState, Command], Outcome]] = {
    M.MAV_CMD_COMPONENT_ARM_DISARM: _arm_disarm,
    M.MAV_CMD_DO_SET_MODE: _set_mode,
    M.MAV_CMD_NAV_LAND: _land,
    M.MAV_CMD_NAV_LOITER_UNLIM: _loiter,
    M.MAV_CMD_NAV_TAKEOFF: _takeoff,
    M.MAV_CMD_NAV_RETURN_TO_LAUNCH: _rtl,
    M.MAV_CMD_DO_REPOSITION: _reposition,
    M.MAV_CMD_MISSION_START: _mission_start,
    M.MAV_CMD_DO_CHANGE_SPEED: _change_speed,
    M.MAV_CMD_DO_FLIGHTTERMINATION: _terminate,
    M.MAV_CMD_SET_MESSAGE_INTERVAL: _set_interval,
    M.MAV_CMD_GET_MESSAGE_INTERVAL: _get_interval,
    M.MAV_CMD_REQUEST_MESSAGE: _request_message,
    M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _request_capabilities,
}


def execute(v: VehicleState, c: Command) -> Outcome:
    """Run one command: the vehicle's services' handler for it
    (``v.command_handlers``), else :data:`HANDLERS`; UNSUPPORTED for a command the
    vehicle does not implement."""
    handler = v.command_handlers.get(c.cmd) or HANDLERS.get(c.cmd)
    if handler is None:
        return M.MAV_RESULT_UNSUPPORTED, None
    return handler(v, c)
