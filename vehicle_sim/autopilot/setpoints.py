"""Offboard setpoint messages -> what the vehicle flies (pure: no vehicle state changed).

* SET_ATTITUDE_TARGET -> (ENU roll, pitch, yaw or None; thrust N or None)
  (:func:`parse_attitude`, the rules of docs/conventions.md);
* SET_POSITION_TARGET_LOCAL_NED and SET_POSITION_TARGET_GLOBAL_INT ->
  :class:`~vehicle_sim.physics.position_control.PositionSetpoint` in ENU (:func:`parse_local_ned`,
  :func:`parse_global_int`) with PX4's ``type_mask`` rules (docs/px4/modes.md):

  - a bit set = that component is ignored (NaN in the setpoint); x/y/z position,
    vx/vy/vz, ax/ay/az, yaw, yaw rate;
  - rejected: the force bit together with an acceleration (PX4: "force not supported"),
    no position, velocity nor acceleration at all, an axis with none of them, x and y of
    one kind not given together, a non-finite value in a given component, an unknown
    coordinate frame.

A rejected message raises :class:`Rejected` (``unsupported`` when the message is well
formed but asks for something the simulator does not do); the vehicle counts it.
:class:`SetpointKind` names what the last valid setpoint asked for.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames
from vehicle_sim.physics import geo
from vehicle_sim.physics.position_control import PositionSetpoint


class SetpointKind(StrEnum):
    """What the last valid offboard setpoint asked for."""

    ATTITUDE = "attitude"  # SET_ATTITUDE_TARGET: attitude + thrust, applied as they are
    TRAJECTORY = "trajectory"  # SET_POSITION_TARGET_*: the position controller flies it


TM_RATES_IGNORE = (
    M.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | M.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | M.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)
TM_THRUST_IGNORE = M.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE
TM_ATT_IGNORE = M.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE

POS_BITS = (
    M.POSITION_TARGET_TYPEMASK_X_IGNORE,
    M.POSITION_TARGET_TYPEMASK_Y_IGNORE,
    M.POSITION_TARGET_TYPEMASK_Z_IGNORE,
)
VEL_BITS = (
    M.POSITION_TARGET_TYPEMASK_VX_IGNORE,
    M.POSITION_TARGET_TYPEMASK_VY_IGNORE,
    M.POSITION_TARGET_TYPEMASK_VZ_IGNORE,
)
ACC_BITS = (
    M.POSITION_TARGET_TYPEMASK_AX_IGNORE,
    M.POSITION_TARGET_TYPEMASK_AY_IGNORE,
    M.POSITION_TARGET_TYPEMASK_AZ_IGNORE,
)
FORCE_BIT = M.POSITION_TARGET_TYPEMASK_FORCE_SET
YAW_BIT = M.POSITION_TARGET_TYPEMASK_YAW_IGNORE
YAW_RATE_BIT = M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE

LOCAL_FRAMES = (
    M.MAV_FRAME_LOCAL_NED,
    M.MAV_FRAME_LOCAL_OFFSET_NED,
    M.MAV_FRAME_BODY_NED,
    M.MAV_FRAME_BODY_OFFSET_NED,
)
GLOBAL_AMSL_FRAMES = (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT)
GLOBAL_RELATIVE_FRAMES = (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


class Rejected(ValueError):
    """A setpoint that is not applied; ``unsupported``: valid MAVLink we do not implement."""

    def __init__(self, why: str, unsupported: bool = False) -> None:
        super().__init__(why)
        self.unsupported = unsupported


# -- SET_ATTITUDE_TARGET ------------------------------------------------------------------
def parse_attitude(m: Any, thrust_max_n: float) -> tuple[Any, float | None]:
    """(ENU attitude or None, thrust N or None) of a SET_ATTITUDE_TARGET; raises
    :class:`Rejected` when it is invalid or asks for body rates only."""
    tm = int(m.type_mask)
    att_ignore = bool(tm & TM_ATT_IGNORE)
    rates_given = (tm & TM_RATES_IGNORE) != TM_RATES_IGNORE
    if att_ignore and rates_given:  # pure body-rate control: not supported
        raise Rejected("body-rate setpoint", unsupported=True)
    att = None
    thrust = None
    if not att_ignore:
        q = np.asarray(m.q, dtype=float)
        if frames.valid_quaternion(q):
            att = frames.euler_enu_from_quat_ned(q)
        if att is None or not all(math.isfinite(a) for a in att):
            raise Rejected("invalid quaternion")
    if not tm & TM_THRUST_IGNORE:
        th = float(m.thrust)
        if not (math.isfinite(th) and 0.0 <= th <= 1.0):
            raise Rejected("thrust outside [0, 1]")
        thrust = frames.norm_to_thrust(th, thrust_max_n)
    return att, thrust


# -- SET_POSITION_TARGET_* -----------------------------------------------------------------
def _masked(values: tuple[float, float, float], bits: tuple[int, ...], tm: int) -> np.ndarray:
    """The three components, NaN where their ignore bit is set; Rejected if a given one is
    not finite."""
    out = np.array([math.nan if tm & b else float(x) for x, b in zip(values, bits, strict=True)])
    given = np.array([not tm & b for b in bits])
    if not np.all(np.isfinite(out[given])):
        raise Rejected("non-finite component")
    return out


def check_mask(tm: int) -> None:
    """PX4's type_mask rules (module docstring); raises :class:`Rejected`."""
    given = [[not tm & b for b in bits] for bits in (POS_BITS, VEL_BITS, ACC_BITS)]
    if given[2][0] or given[2][1] or given[2][2]:
        if tm & FORCE_BIT:
            raise Rejected("force setpoint", unsupported=True)
    if not any(any(k) for k in given):
        raise Rejected("no position, velocity or acceleration")
    for axis in range(3):
        if not any(k[axis] for k in given):
            raise Rejected(f"axis {'xyz'[axis]} has no setpoint")
    for k in given:
        if k[0] != k[1]:
            raise Rejected("x and y not given together")


def yaw_enu_from_ned(yaw_ned: float) -> float:
    """ENU yaw (rad, from east, counter-clockwise) of a NED heading (rad, from north)."""
    q = np.array([math.cos(yaw_ned / 2), 0.0, 0.0, math.sin(yaw_ned / 2)])
    return frames.euler_enu_from_quat_ned(q)[2]


def _yaw(m: Any, tm: int) -> tuple[float | None, float | None]:
    """(ENU yaw, ENU yaw rate) of the message, None where ignored; Rejected if not finite."""
    yaw = rate = None
    if not tm & YAW_BIT:
        y_ned = float(m.yaw)
        if not math.isfinite(y_ned):
            raise Rejected("non-finite yaw")
        yaw = yaw_enu_from_ned(y_ned)
    if not tm & YAW_RATE_BIT:
        r_ned = float(m.yaw_rate)
        if not math.isfinite(r_ned):
            raise Rejected("non-finite yaw rate")
        rate = float(frames.ned_to_enu(np.array([0.0, 0.0, r_ned]))[2])
    return yaw, rate


def _body_to_enu(v_frd: np.ndarray, yaw_enu: float) -> np.ndarray:
    """A body-frame vector (FRD, yaw-only rotation as PX4's BODY_NED) in ENU; x and y are
    NaN together (check_mask), z stays separate."""
    flu = frames.D_FRD_FLU @ np.where(np.isfinite(v_frd), v_frd, 0.0)
    out = frames.rotm_from_euler(0.0, 0.0, yaw_enu) @ flu
    return np.where(np.isfinite(frames.ned_to_enu(v_frd)), out, math.nan)


def parse_local_ned(m: Any, p_enu: np.ndarray, yaw_enu: float) -> PositionSetpoint:
    """SET_POSITION_TARGET_LOCAL_NED -> ENU setpoint. ``p_enu``, ``yaw_enu``: the vehicle's
    position and yaw now (for the offset and body frames)."""
    tm = int(m.type_mask)
    frame = int(m.coordinate_frame)
    if frame not in LOCAL_FRAMES:
        raise Rejected(f"coordinate frame {frame}", unsupported=True)
    check_mask(tm)
    pos = _masked((m.x, m.y, m.z), POS_BITS, tm)
    vel = _masked((m.vx, m.vy, m.vz), VEL_BITS, tm)
    acc = _masked((m.afx, m.afy, m.afz), ACC_BITS, tm)
    yaw, rate = _yaw(m, tm)
    p_now = np.asarray(p_enu, dtype=float)
    if frame in (M.MAV_FRAME_BODY_NED, M.MAV_FRAME_BODY_OFFSET_NED):
        pos_e = p_now + _body_to_enu(pos, yaw_enu)
        vel_e, acc_e = _body_to_enu(vel, yaw_enu), _body_to_enu(acc, yaw_enu)
    else:
        pos_e = frames.ned_to_enu(pos)
        if frame == M.MAV_FRAME_LOCAL_OFFSET_NED:
            pos_e = p_now + pos_e
        vel_e, acc_e = frames.ned_to_enu(vel), frames.ned_to_enu(acc)
    return PositionSetpoint(pos_e, vel_e, acc_e, yaw, rate)


def parse_global_int(m: Any, cfg: Any) -> PositionSetpoint:
    """SET_POSITION_TARGET_GLOBAL_INT -> ENU setpoint (``cfg``: the vehicle's
    AutopilotConfig, whose geodetic origin is the world origin; the ground is home_alt)."""
    tm = int(m.type_mask)
    frame = int(m.coordinate_frame)
    if frame not in GLOBAL_AMSL_FRAMES + GLOBAL_RELATIVE_FRAMES:
        raise Rejected(f"coordinate frame {frame}", unsupported=True)
    check_mask(tm)
    raw = _masked((m.lat_int * 1e-7, m.lon_int * 1e-7, m.alt), POS_BITS, tm)
    pos = np.full(3, math.nan)
    if math.isfinite(raw[0]):
        north, east = geo.ned_from_latlon(cfg, float(raw[0]), float(raw[1]))
        pos[0], pos[1] = north, east
    if math.isfinite(raw[2]):
        rel = frame in GLOBAL_RELATIVE_FRAMES
        pos[2] = -float(raw[2]) if rel else geo.down_from_amsl(cfg, float(raw[2]))
    vel = _masked((m.vx, m.vy, m.vz), VEL_BITS, tm)
    acc = _masked((m.afx, m.afy, m.afz), ACC_BITS, tm)
    yaw, rate = _yaw(m, tm)
    return PositionSetpoint(
        frames.ned_to_enu(pos), frames.ned_to_enu(vel), frames.ned_to_enu(acc), yaw, rate
    )
