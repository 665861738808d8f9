"""The PX4 parameters ``vehicle-sim`` exposes, with defaults taken from the simulated vehicle.

The behaviour-changing ones are read by the vehicle (offboard-loss time and action,
take-off altitude, hover thrust and tilt limit of the onboard position controller, land
speed, RTL altitude, geofence); the identity ones are what clients read on connect.
PX4 names and units; ``COM_OBL_RC_ACT`` values follow PX4 (docs/px4-compatibility.md
lists which actions the simulator implements).
"""

from __future__ import annotations

import math
from typing import Any

from swarm_common.enums import FailsafeAction
from vehicle_sim.params import INT32, REAL32, ParamSpec

# PX4 COM_OBL_RC_ACT: 0 position, 1 altitude, 2 manual, 3 return, 4 land, 5 hold
OBL_ACT_RETURN = 3
OBL_ACT_LAND = 4
OBL_ACT_HOLD = 5


def default_param_specs(agent_id: int, cfg: Any, dyn: Any) -> list[ParamSpec]:
    """Every exposed parameter, defaults from ``cfg`` (VehicleConfig) and ``dyn``."""
    hover = float(dyn.hold_thrust()) / float(dyn.f_max)
    tilt_deg = math.degrees(float(dyn.tilt_max))
    obl = OBL_ACT_LAND if cfg.failsafe == FailsafeAction.LAND else OBL_ACT_HOLD
    return [
        ParamSpec("SYS_AUTOSTART", INT32, 10016, 0, 9_999_999, "airframe (10016: Iris SITL)"),
        ParamSpec("MAV_SYS_ID", INT32, agent_id, 1, 250, "MAVLink system id (read only here)"),
        ParamSpec("MAV_COMP_ID", INT32, 1, 1, 250, "MAVLink component id"),
        ParamSpec("MAV_TYPE", INT32, 2, 0, 40, "MAV_TYPE_QUADROTOR"),
        ParamSpec("SYS_HITL", INT32, 0, 0, 1, "hardware in the loop"),
        ParamSpec("COM_OF_LOSS_T", REAL32, cfg.offboard_timeout, 0.0, 60.0,
                  "s without offboard setpoints before the failsafe"),
        ParamSpec("COM_OBL_RC_ACT", INT32, obl, 0, 5, "offboard-loss action"),
        ParamSpec("COM_DISARM_LAND", REAL32, cfg.land_disarm_delay, -1.0, 20.0,
                  "s landed before auto-disarm"),
        ParamSpec("MPC_TKO_ALT", REAL32, 2.5, -1.0, 100.0, "take-off altitude, m (legacy)"),
        ParamSpec("MIS_TAKEOFF_ALT", REAL32, 2.5, 0.0, 200.0, "take-off altitude, m"),
        ParamSpec("MPC_TKO_SPEED", REAL32, 1.5, 0.5, 5.0, "take-off climb speed, m/s"),
        ParamSpec("MPC_THR_HOVER", REAL32, round(hover, 4), 0.1, 0.8,
                  "hover thrust, normalised (physical hover = m g / F_max)"),
        ParamSpec("MPC_TILTMAX_AIR", REAL32, round(tilt_deg, 2), 20.0, 89.0, "tilt limit, deg"),
        ParamSpec("MPC_XY_CRUISE", REAL32, 5.0, 1.0, 20.0, "horizontal cruise speed, m/s"),
        ParamSpec("MPC_LAND_SPEED", REAL32, 0.7, 0.3, 3.0, "land descent speed, m/s"),
        ParamSpec("RTL_RETURN_ALT", REAL32, 30.0, 0.0, 150.0, "RTL altitude above home, m"),
        ParamSpec("RTL_DESCEND_ALT", REAL32, 10.0, 2.0, 100.0, "RTL loiter altitude, m"),
        ParamSpec("NAV_ACC_RAD", REAL32, 2.0, 0.05, 200.0, "waypoint acceptance radius, m"),
        ParamSpec("GF_ACTION", INT32, 1, 0, 5, "geofence action: 0 none, 1 warn, 2 hold, 3 RTL, "
                  "4 terminate, 5 land"),
        ParamSpec("GF_MAX_HOR_DIST", REAL32, 0.0, 0.0, 10_000.0, "max distance from home, m"),
        ParamSpec("GF_MAX_VER_DIST", REAL32, 0.0, 0.0, 10_000.0, "max height above home, m"),
    ]
