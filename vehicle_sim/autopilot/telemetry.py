"""Telemetry a simulated PX4 vehicle sends: one builder per MAVLink message, in a table.

:data:`BUILDERS` maps a message id (``MAVLINK_MSG_ID_*``) to a function
``(vehicle, sim_t) -> message`` that reads the vehicle's state (dynamics row, mode,
setpoint); :func:`build` looks it up (``None`` for a message the vehicle does not send).
:data:`vehicle_sim.autopilot.config.DEFAULT_RATES` holds the stream rates a vehicle starts
with on its API link (the onboard set), ``config.GCS_RATES`` those of its GCS link (PX4's
"normal" set); Hz, 0 = off. The ODOMETRY rate comes from ``AutopilotConfig.odometry_hz``.
Rates, health bits and the battery: docs/px4/streams.md.

Frames: the dynamics are ENU / FLU (z up); every message is NED / FRD. Time stamps are
simulation time (``time_boot_ms`` = round(sim_t · 1000), ``time_usec`` = round(sim_t · 1e6)).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames
from swarm_common.enums import VehicleMode
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.autopilot.mavlink_extra import (
    MAVLINK_MSG_ID_PROTOCOL_VERSION as MSG_ID_PROTOCOL_VERSION,
)
from vehicle_sim.autopilot.mavlink_extra import MAVLink_protocol_version_message
from vehicle_sim.autopilot.setpoints import TM_RATES_IGNORE
from vehicle_sim.autopilot.state import ODOM_STAMP_KEEP, VehicleState
from vehicle_sim.physics import geo
from vehicle_sim.physics.battery import BatteryModel

Builder = Callable[[VehicleState, float], M.MAVLink_message]

SENSORS = (
    M.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | M.MAV_SYS_STATUS_SENSOR_3D_MAG
    | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | M.MAV_SYS_STATUS_SENSOR_GPS
    | M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | M.MAV_SYS_STATUS_AHRS
    | M.MAV_SYS_STATUS_SENSOR_BATTERY
    | M.MAV_SYS_STATUS_PREARM_CHECK
    | M.MAV_SYS_STATUS_GEOFENCE
)
BATTERY_CRITICAL = 0.07  # remaining charge below which the battery bit is unhealthy (PX4)

MAVLINK_WIRE_VERSION = 3  # HEARTBEAT.mavlink_version
SYS_LOAD_PERMILLE = 100  # SYS_STATUS.load: 10 %
TEMPERATURE_UNKNOWN = 32767  # BATTERY_STATUS.temperature: INT16_MAX = not measured
CELLS_FIELD = 10  # BATTERY_STATUS.voltages: mV per cell, UINT16_MAX where no cell
UINT16_MAX = 65535
ENERGY_UNKNOWN = -1
# PROTOCOL_VERSION: MAVLink 2 active, 1 and 2 supported (version x 100), hashes unknown
MAVLINK_VERSION_ACTIVE, MAVLINK_VERSION_MIN, MAVLINK_VERSION_MAX = 200, 100, 200
# GPS_RAW_INT: a good 3D fix
GPS_EPH_CM, GPS_EPV_CM, GPS_COG_UNKNOWN, GPS_SATELLITES = 80, 120, 65535, 16
# AUTOPILOT_VERSION: PX4 v1.15.0 official, pid.codes vendor id, "SS" product id
PX4_VERSION = (1, 15, 0)
USB_VENDOR_ID, USB_PRODUCT_ID = 0x1209, 0x5353
ODOMETRY_QUALITY = 100  # %
INT16_MAX = 32767


# -- state in MAVLink frames ----------------------------------------------------------
def _t_ms(sim_t: float) -> int:
    return int(round(sim_t * 1000)) & 0xFFFFFFFF


def _t_us(sim_t: float) -> int:
    return int(round(sim_t * 1e6))


def _p_ned(v: VehicleState) -> np.ndarray:
    return frames.enu_to_ned(v.dyn.p[v.idx])


def _v_ned(v: VehicleState) -> np.ndarray:
    return frames.enu_to_ned(v.dyn.v[v.idx])


def q_ned(v: VehicleState) -> np.ndarray:
    """Attitude quaternion (w, x, y, z), body FRD -> NED."""
    r, p, y = v.dyn.att[v.idx]
    return frames.quat_ned_from_euler_enu(float(r), float(p), float(y))


def rates_frd(v: VehicleState) -> tuple[float, float, float]:
    """Body rates (FRD, rad/s) approximated by the Euler-angle rates of the attitude lag."""
    d, i = v.dyn, v.idx
    return frames.lag_rates_frd(d.att[i], d.cmd_att[i], d.tau)


def latlon(cfg: AutopilotConfig, ned: np.ndarray) -> tuple[int, int]:
    """(lat, lon) in degE7 of a NED offset from the geodetic origin
    (:mod:`vehicle_sim.physics.geo`)."""
    return geo.latlon_e7(cfg, ned)


def _alt_mm(cfg: AutopilotConfig, pn: np.ndarray) -> int:
    """AMSL altitude (mm) of a NED position."""
    return int(round((cfg.home_alt - pn[2]) * 1000))


def landed_state(v: VehicleState) -> int:
    """MAV_LANDED_STATE: TAKEOFF (armed, climbing to a take-off altitude: AUTO.TAKEOFF, a
    mission TAKEOFF), ON_GROUND, LANDING (armed, in the air, descending to land: AUTO.LAND,
    a mission LAND, the last leg of RTL) or IN_AIR."""
    if v.armed and v.taking_off:
        return M.MAV_LANDED_STATE_TAKEOFF
    if v.on_ground():
        return M.MAV_LANDED_STATE_ON_GROUND
    if v.armed and v.landing:
        return M.MAV_LANDED_STATE_LANDING
    return M.MAV_LANDED_STATE_IN_AIR


def battery(v: VehicleState) -> BatteryModel:
    """The vehicle's battery (kept by its information service); a full one if it has none."""
    b = getattr(getattr(v, "info", None), "battery", None)
    return b if isinstance(b, BatteryModel) else BatteryModel()


def health(v: VehicleState) -> int:
    """SYS_STATUS.onboard_control_sensors_health: every present sensor healthy except the
    geofence while breached (``vehicle.mission.fence_breached``), the battery below
    :data:`BATTERY_CRITICAL`, and the pre-arm check after a flight termination."""
    bits = SENSORS
    if getattr(getattr(v, "mission", None), "fence_breached", False):
        bits &= ~M.MAV_SYS_STATUS_GEOFENCE
    if battery(v).remaining < BATTERY_CRITICAL:
        bits &= ~M.MAV_SYS_STATUS_SENSOR_BATTERY
    if v.terminated:
        bits &= ~M.MAV_SYS_STATUS_PREARM_CHECK
    return bits


# -- builders ---------------------------------------------------------------------------
def heartbeat(v: VehicleState, sim_t: float = 0.0) -> M.MAVLink_heartbeat_message:
    base = (
        M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        | M.MAV_MODE_FLAG_GUIDED_ENABLED
    )
    if v.mode in (VehicleMode.POSCTL, VehicleMode.ALTCTL):
        base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    else:
        base |= M.MAV_MODE_FLAG_AUTO_ENABLED
    if v.armed:
        base |= M.MAV_MODE_FLAG_SAFETY_ARMED
    if v.terminated:
        status = M.MAV_STATE_FLIGHT_TERMINATION
    elif v.failsafe and v.armed:  # as PX4 reports while a failsafe action is active
        status = M.MAV_STATE_CRITICAL
    else:
        status = M.MAV_STATE_ACTIVE if v.armed else M.MAV_STATE_STANDBY
    return M.MAVLink_heartbeat_message(
        M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, base, v.custom_mode, status,
        MAVLINK_WIRE_VERSION,
    )  # fmt: skip


def odometry(v: VehicleState, sim_t: float) -> M.MAVLink_odometry_message:
    """ODOMETRY stamped ``sim_t``; the wall time of its first send is kept for the
    setpoint-to-odometry latency (``VehicleState.odom_wall``)."""
    stamp = int(round(sim_t * 1000))
    if stamp not in v.odom_wall:  # a re-send keeps the first send time
        if len(v.odom_wall) > ODOM_STAMP_KEEP:
            v.odom_wall.clear()
        v.odom_wall[stamp] = time.monotonic()
    d, i = v.dyn, v.idx
    # NED position, quaternion, body FRD velocity (child_frame_id = BODY_FRD)
    f = frames.odometry_ned(d.p[i], d.v[i], d.att[i]).tolist()
    wr = rates_frd(v)
    nan21 = [math.nan] * 21
    return M.MAVLink_odometry_message(
        _t_us(sim_t), M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_BODY_FRD,
        f[0], f[1], f[2], f[3:7], f[7], f[8], f[9], wr[0], wr[1], wr[2],
        nan21, nan21, 0, M.MAV_ESTIMATOR_TYPE_NAIVE, ODOMETRY_QUALITY,
    )  # fmt: skip


def attitude_quaternion(v: VehicleState, sim_t: float) -> M.MAVLink_attitude_quaternion_message:
    q = q_ned(v)
    return M.MAVLink_attitude_quaternion_message(
        _t_ms(sim_t), float(q[0]), float(q[1]), float(q[2]), float(q[3]), *rates_frd(v)
    )


def attitude(v: VehicleState, sim_t: float) -> M.MAVLink_attitude_message:
    rn, pn, yn = frames.euler_from_rotm(frames.rotm_from_quat(q_ned(v)))
    return M.MAVLink_attitude_message(_t_ms(sim_t), rn, pn, yn, *rates_frd(v))


def local_position_ned(v: VehicleState, sim_t: float) -> M.MAVLink_local_position_ned_message:
    pn, vn = _p_ned(v), _v_ned(v)
    return M.MAVLink_local_position_ned_message(
        _t_ms(sim_t), float(pn[0]), float(pn[1]), float(pn[2]),
        float(vn[0]), float(vn[1]), float(vn[2]),
    )  # fmt: skip


def global_position_int(v: VehicleState, sim_t: float) -> M.MAVLink_global_position_int_message:
    pn, vn = _p_ned(v), _v_ned(v)
    lat, lon = latlon(v.cfg, pn)
    yaw_ned = math.pi / 2 - float(v.dyn.att[v.idx, 2])
    hdg = int(round(math.degrees(yaw_ned) % 360.0 * 100)) % 36000
    vx, vy, vz = (int(max(-INT16_MAX - 1, min(INT16_MAX, round(x * 100)))) for x in vn)
    return M.MAVLink_global_position_int_message(
        _t_ms(sim_t), lat, lon, _alt_mm(v.cfg, pn), int(round(-pn[2] * 1000)), vx, vy, vz, hdg
    )


def gps_raw_int(v: VehicleState, sim_t: float) -> M.MAVLink_gps_raw_int_message:
    pn = _p_ned(v)
    lat, lon = latlon(v.cfg, pn)
    return M.MAVLink_gps_raw_int_message(
        _t_us(sim_t), M.GPS_FIX_TYPE_3D_FIX, lat, lon, _alt_mm(v.cfg, pn),
        GPS_EPH_CM, GPS_EPV_CM, 0, GPS_COG_UNKNOWN, GPS_SATELLITES,
    )  # fmt: skip


def home_position(v: VehicleState, sim_t: float) -> M.MAVLink_home_position_message:
    h = v.home_ned
    lat, lon = latlon(v.cfg, h)
    return M.MAVLink_home_position_message(
        lat, lon, int(round(v.cfg.home_alt * 1000)),
        float(h[0]), float(h[1]), float(h[2]), [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
        _t_us(sim_t),
    )  # fmt: skip


def gps_global_origin(v: VehicleState, sim_t: float) -> M.MAVLink_gps_global_origin_message:
    """GPS_GLOBAL_ORIGIN: the geodetic point of the local frame's origin (NED 0, 0, 0), the
    frame of LOCAL_POSITION_NED and ODOMETRY (PX4 streams it at 1 Hz on an onboard link)."""
    lat, lon = latlon(v.cfg, np.zeros(3))
    return M.MAVLink_gps_global_origin_message(lat, lon, int(round(v.cfg.home_alt * 1000)),
                                               _t_us(sim_t))


def extended_sys_state(v: VehicleState, sim_t: float) -> M.MAVLink_extended_sys_state_message:
    return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED, landed_state(v))


def sys_status(v: VehicleState, sim_t: float) -> M.MAVLink_sys_status_message:
    b = battery(v)
    return M.MAVLink_sys_status_message(
        SENSORS, SENSORS, health(v), SYS_LOAD_PERMILLE, int(round(b.voltage * 1000)),
        int(round(b.current_a * 100)), int(round(b.remaining * 100)), 0, 0, 0, 0, 0, 0,
    )  # fmt: skip


def battery_status(v: VehicleState, sim_t: float) -> M.MAVLink_battery_status_message:
    """BATTERY_STATUS of the simulated pack (:mod:`vehicle_sim.physics.battery`)."""
    b = battery(v)
    cell_mv = min(UINT16_MAX - 1, int(round(b.cell_voltage * 1000)))
    cells = [cell_mv] * b.cells + [UINT16_MAX] * (CELLS_FIELD - b.cells)
    return M.MAVLink_battery_status_message(
        0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, TEMPERATURE_UNKNOWN,
        cells[:CELLS_FIELD], int(round(b.current_a * 100)), int(round(b.consumed_mah)),
        ENERGY_UNKNOWN, int(round(b.remaining * 100)), b.time_remaining_s(),
        M.MAV_BATTERY_CHARGE_STATE_OK if b.remaining >= BATTERY_CRITICAL
        else M.MAV_BATTERY_CHARGE_STATE_CRITICAL,
    )  # fmt: skip


def vfr_hud(v: VehicleState, sim_t: float) -> M.MAVLink_vfr_hud_message:
    """VFR_HUD: no wind, so airspeed = ground speed (m/s); throttle = thrust / f_max (%)."""
    pn, vn = _p_ned(v), _v_ned(v)
    yaw_ned = math.pi / 2 - float(v.dyn.att[v.idx, 2])
    heading = int(math.degrees(yaw_ned) % 360.0) % 360
    gs = float(math.hypot(vn[0], vn[1]))
    throttle = int(round(100.0 * float(v.dyn.thrust[v.idx]) / v.dyn.f_max))
    alt = v.cfg.home_alt - float(pn[2])
    climb = -float(vn[2])
    return M.MAVLink_vfr_hud_message(gs, gs, heading, max(0, min(100, throttle)), alt, climb)


def altitude(v: VehicleState, sim_t: float) -> M.MAVLink_altitude_message:
    """ALTITUDE (m): flat ground at home altitude, so terrain height = local altitude."""
    up = -float(_p_ned(v)[2])
    amsl = v.cfg.home_alt + up
    rel = up + float(v.home_ned[2])
    return M.MAVLink_altitude_message(_t_us(sim_t), amsl, amsl, up, rel, up, up)


def protocol_version(v: VehicleState, sim_t: float) -> MAVLink_protocol_version_message:
    """PROTOCOL_VERSION: MAVLink 2 active, versions 1 to 2 understood."""
    return MAVLink_protocol_version_message(
        MAVLINK_VERSION_ACTIVE, MAVLINK_VERSION_MIN, MAVLINK_VERSION_MAX, [0] * 8, [0] * 8
    )


def autopilot_version(v: VehicleState, sim_t: float) -> M.MAVLink_autopilot_version_message:
    caps = (
        M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
        | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
        | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
        | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
        | M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
        | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
        | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
        | M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
        | M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
    )
    major, minor, patch = PX4_VERSION
    sw = (major << 24) | (minor << 16) | (patch << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
    return M.MAVLink_autopilot_version_message(
        caps, sw, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, USB_VENDOR_ID, USB_PRODUCT_ID,
        v.uid & 0xFFFFFFFFFFFFFFFF, list(v.uid.to_bytes(8, "little")) + [0] * 10,
    )  # fmt: skip


def attitude_target(v: VehicleState, sim_t: float) -> M.MAVLink_attitude_target_message:
    """The setpoint being applied (what PX4 reports back)."""
    r, p, y = (float(a) for a in v.sp_att)
    q = frames.quat_ned_from_euler_enu(r, p, y)
    return M.MAVLink_attitude_target_message(
        _t_ms(sim_t), TM_RATES_IGNORE, [float(x) for x in q], 0.0, 0.0, 0.0,
        frames.thrust_to_norm(v.sp_thrust, v.dyn.f_max),
    )  # fmt: skip


BUILDERS: dict[int, Builder] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    M.MAVLINK_MSG_ID_ODOMETRY: odometry,
    M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: attitude_quaternion,
    M.MAVLINK_MSG_ID_ATTITUDE: attitude,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: local_position_ned,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: gps_raw_int,
    M.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: gps_global_origin,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    M.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: autopilot_version,
    M.MAVLINK_MSG_ID_ATTITUDE_TARGET: attitude_target,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: battery_status,
    M.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    M.MAVLINK_MSG_ID_ALTITUDE: altitude,
    MSG_ID_PROTOCOL_VERSION: protocol_version,
}


def build(v: VehicleState, mid: int, sim_t: float) -> M.MAVLink_message | None:
    """Message ``mid`` built from the vehicle's current state (None if not supported)."""
    builder = BUILDERS.get(mid)
    return None if builder is None else builder(v, sim_t)
