"""The PX4 parameters ``vehicle-sim`` exposes, with defaults taken from the simulated vehicle.

Every entry is one of two kinds, named at the start of its ``doc``: ``behaviour`` (read by
the vehicle: offboard-loss time and action, take-off altitude, hover thrust and tilt limit
of the onboard position controller, speeds and speed ceilings, RTL altitude, geofence) or
``identity`` (what clients read on connect; read-only, PARAM_SET answers
MAV_PARAM_ERROR_READ_ONLY). Ranges: a PARAM_SET outside ``[lo, hi]`` is refused
(MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, the value unchanged), where PX4 stores it and only
QGroundControl warns.
PX4 names and units; ``COM_OBL_RC_ACT`` values follow PX4 (docs/px4/params.md lists
them).
"""

from __future__ import annotations

import math
from typing import Any

from swarm_common.enums import FailsafeAction
from vehicle_sim.autopilot.params import INT32, REAL32, ParamSpec

# PX4 COM_OBL_RC_ACT: 0 position, 1 altitude, 2 manual, 3 return, 4 land, 5 hold
OBL_ACT_RETURN = 3
OBL_ACT_LAND = 4
OBL_ACT_HOLD = 5


def default_param_specs(agent_id: int, cfg: Any, dyn: Any) -> list[ParamSpec]:
    """Every exposed parameter, defaults from ``cfg`` (AutopilotConfig) and ``dyn``."""
    hover = float(dyn.hold_thrust()) / float(dyn.f_max)
    tilt_deg = math.degrees(float(dyn.tilt_max))
    obl = OBL_ACT_LAND if cfg.failsafe == FailsafeAction.LAND else OBL_ACT_HOLD
    # fmt: off
    return [
        # identity values: read by clients on connect, read-only here
        ParamSpec("SYS_AUTOSTART", INT32, 10016, 0, 9_999_999,
                  "identity: airframe (10016: Iris SITL)", read_only=True),
        ParamSpec("MAV_SYS_ID", INT32, agent_id, 1, 255,
                  "identity: MAVLink system id (= the vehicle id)", read_only=True),
        ParamSpec("MAV_COMP_ID", INT32, 1, 1, 250,
                  "identity: MAVLink component id of the autopilot", read_only=True),
        ParamSpec("MAV_TYPE", INT32, 2, 0, 40, "identity: MAV_TYPE_QUADROTOR", read_only=True),
        ParamSpec("SYS_HITL", INT32, 0, 0, 1, "identity: 0, not hardware in the loop",
                  read_only=True),
        # behaviour: read by the vehicle's mode logic and position controller
        ParamSpec("COM_OF_LOSS_T", REAL32, cfg.offboard_timeout, 0.0, 60.0,
                  "behaviour: s without offboard setpoints before the failsafe"),
        ParamSpec("COM_OBL_RC_ACT", INT32, obl, 0, 5, "behaviour: offboard-loss action"),
        ParamSpec("COM_DISARM_LAND", REAL32, cfg.land_disarm_delay, -1.0, 20.0,
                  "behaviour: s landed before auto-disarm"),
        ParamSpec("MIS_TAKEOFF_ALT", REAL32, 2.5, 0.0, 200.0,
                  "behaviour: take-off altitude above ground, m"),
        ParamSpec("MPC_TKO_ALT", REAL32, 2.5, 0.0, 200.0,
                  "behaviour: alias of MIS_TAKEOFF_ALT (writing either writes both)",
                  alias_of="MIS_TAKEOFF_ALT"),
        ParamSpec("MPC_TKO_SPEED", REAL32, 1.5, 0.5, 5.0, "behaviour: take-off climb speed, m/s"),
        ParamSpec("MPC_THR_HOVER", REAL32, round(hover, 4), 0.1, 0.8,
                  "behaviour: hover thrust, normalised (physical hover = m g / F_max)"),
        ParamSpec("MPC_TILTMAX_AIR", REAL32, round(tilt_deg, 2), 20.0, 89.0,
                  "behaviour: tilt limit of the position controller, deg"),
        ParamSpec("MPC_XY_CRUISE", REAL32, 5.0, 1.0, 20.0,
                  "behaviour: horizontal cruise speed, m/s"),
        ParamSpec("MPC_LAND_SPEED", REAL32, 0.7, 0.3, 3.0, "behaviour: land descent speed, m/s"),
        ParamSpec("MPC_XY_VEL_MAX", REAL32, 12.0, 0.5, 20.0,
                  "behaviour: horizontal speed ceiling (every mode, offboard too), m/s"),
        ParamSpec("MPC_Z_VEL_MAX_UP", REAL32, 3.0, 0.5, 8.0,
                  "behaviour: climb speed ceiling (every mode), m/s"),
        ParamSpec("MPC_Z_VEL_MAX_DN", REAL32, 1.5, 0.5, 4.0,
                  "behaviour: descent speed ceiling (every mode), m/s"),
        ParamSpec("RTL_RETURN_ALT", REAL32, 30.0, 0.0, 150.0,
                  "behaviour: RTL altitude above home, m"),
        ParamSpec("NAV_ACC_RAD", REAL32, 2.0, 0.05, 200.0,
                  "behaviour: waypoint acceptance radius, m"),
        ParamSpec("GF_ACTION", INT32, 1, 0, 5, "behaviour: geofence action: 0 none, 1 warn, "
                  "2 hold, 3 RTL, 4 terminate, 5 land"),
        ParamSpec("GF_MAX_HOR_DIST", REAL32, 0.0, 0.0, 10_000.0,
                  "behaviour: max distance from home, m (0: off)"),
        ParamSpec("GF_MAX_VER_DIST", REAL32, 0.0, 0.0, 10_000.0,
                  "behaviour: max height above home, m (0: off)"),
    ]
    # fmt: on
