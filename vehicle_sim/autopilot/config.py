"""The settings of one simulated autopilot: its protocol side, as the command line sets it.

:class:`AutopilotConfig` is what ``vehicle-sim`` tells each PX4-style vehicle it runs
(offboard-loss defaults, ODOMETRY rate, lockstep, geodetic origin, unique id, stream
rates). It is not the scenario's physical vehicle (mass, thrust, tilt: that is
:class:`swarm_common.scenario.schema.VehicleConfig`, which the dynamics read).

:data:`DEFAULT_RATES` holds the stream rates a vehicle starts with on its API link (the
"onboard" set: PX4's MAVLINK_MODE_ONBOARD streams that this simulator builds, at the
rates the offboard daemon needs; ODOMETRY uses ``AutopilotConfig.odometry_hz``) and
:data:`GCS_RATES` those of its GCS link (PX4's MAVLINK_MODE_NORMAL set, restricted to the
messages this simulator builds: no ODOMETRY, no ATTITUDE_QUATERNION). Hz, 0 = off.
docs/px4/streams.md lists both.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as M

from swarm_common.enums import FailsafeAction
from swarm_common.world import geodesy

DEFAULT_RATES: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 20.0,
    M.MAVLINK_MSG_ID_ATTITUDE: 15.0,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 20.0,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 1.0,
    M.MAVLINK_MSG_ID_ALTITUDE: 1.0,
    M.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    M.MAVLINK_MSG_ID_ATTITUDE_TARGET: 0.0,
}

# PX4 Mavlink::configure_streams_to_default, MAVLINK_MODE_NORMAL (rates in Hz)
GCS_RATES: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_ALTITUDE: 1.0,
    M.MAVLINK_MSG_ID_ATTITUDE: 15.0,
    M.MAVLINK_MSG_ID_ATTITUDE_TARGET: 2.0,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 0.1,
    M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 1.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    M.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0.0,  # not in the normal set
    M.MAVLINK_MSG_ID_ODOMETRY: 0.0,  # onboard only: a client may request it
}


@dataclass
class AutopilotConfig:
    """One vehicle's autopilot settings (protocol, not physics)."""

    # defaults of COM_OF_LOSS_T, COM_OBL_RC_ACT and COM_DISARM_LAND (the vehicle reads
    # the parameters, which a client may change)
    offboard_timeout: float = 0.5  # s (sim time) without setpoint in OFFBOARD -> failsafe
    failsafe: FailsafeAction = FailsafeAction.HOLD
    odometry_hz: float = 50.0
    lockstep: bool = False
    setpoint_window: float = 0.5  # s: OFFBOARD needs >= setpoint_min_count in this window
    setpoint_min_count: int = 2
    land_disarm_delay: float = 1.0  # s on the ground in LAND before auto-disarm
    # the shared geodetic origin (PX4 SITL's default home): the daemons read fences back
    # about the same one (swarm_common.world.geodesy)
    home_lat: float = geodesy.ORIGIN_LAT_DEG
    home_lon: float = geodesy.ORIGIN_LON_DEG
    home_alt: float = geodesy.ORIGIN_ALT_M
    uid_base: int = 0x4253574152000000  # "BSWAR" + offset << 8 + id
    port_offset: int = 0
    # default stream rates (Hz) of the API link; 0 = off. ODOMETRY uses odometry_hz.
    rates: dict[int, float] = field(default_factory=lambda: dict(DEFAULT_RATES))
    # default stream rates (Hz) of the GCS link (PX4's normal set)
    gcs_rates: dict[int, float] = field(default_factory=lambda: dict(GCS_RATES))
