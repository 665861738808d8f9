"""A vehicle receiving offboard setpoints: SET_ATTITUDE_TARGET and SET_POSITION_TARGET_*.

Parsing is :mod:`vehicle_sim.autopilot.setpoints` (pure); here a valid setpoint of any kind does the
same bookkeeping: setpoint-to-odometry latency, the lockstep echo of ``time_boot_ms``
(a stale answer is counted and not applied), the setpoint count and the freshness that
keeps OFFBOARD alive (``COM_OF_LOSS_T``) and lets a client enter it. A rejected one is
counted (``setpoints_rejected``, and ``setpoints_unsupported`` for valid MAVLink the
simulator does not implement) and changes nothing.

An attitude setpoint is applied as it is (the path lockstep runs depend on, unchanged);
a position/velocity/acceleration setpoint is flown by the vehicle's position controller.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from vehicle_sim.autopilot import setpoints
from vehicle_sim.autopilot.setpoints import SetpointKind
from vehicle_sim.autopilot.state import VehicleState


def _accept(v: VehicleState, m: Any) -> bool:
    """Latency, lockstep echo and count of one valid setpoint; False for a stale lockstep
    answer (counted, not applied)."""
    w = v.odom_wall.pop(int(m.time_boot_ms), None)
    if w is not None:
        v.latency.append(time.monotonic() - w)
    if v.cfg.lockstep:
        if int(m.time_boot_ms) != v.expect_ms:
            v.ctr.setpoints_stale += 1
            return False
        v.answered_ms = v.expect_ms
        v.ever_answered = True
        v.consecutive_timeouts = 0
        v.wait_suspended = False
    v.ctr.setpoints += 1
    return True


def _stamp(v: VehicleState, m: Any, sim_t: float) -> None:
    v.sp_times.append(sim_t)
    v.last_sp_t = sim_t
    v.last_sp_ms = int(m.time_boot_ms)


def _reject(v: VehicleState, exc: setpoints.Rejected) -> None:
    if exc.unsupported:
        v.ctr.setpoints_unsupported += 1
    v.ctr.setpoints_rejected += 1


def on_attitude_target(v: VehicleState, m: Any, sim_t: float) -> None:
    """SET_ATTITUDE_TARGET (docs/conventions.md)."""
    try:
        att, thrust = setpoints.parse_attitude(m, v.dyn.f_max)
    except setpoints.Rejected as exc:
        _reject(v, exc)
        return
    if not _accept(v, m):
        return
    if att is not None:
        v.sp_att = np.array(att, dtype=float)
    if thrust is not None:
        v.sp_thrust = thrust
    v.sp_kind = SetpointKind.ATTITUDE
    _stamp(v, m, sim_t)


def on_position_target(v: VehicleState, m: Any, sim_t: float) -> None:
    """SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT (PX4's type_mask rules)."""
    try:
        if m.get_msgId() == M.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT:
            sp = setpoints.parse_global_int(m, v.cfg)
        else:
            sp = setpoints.parse_local_ned(m, v.p(), v.yaw())
    except setpoints.Rejected as exc:
        _reject(v, exc)
        return
    if not _accept(v, m):
        return
    if v.sp_kind != SetpointKind.TRAJECTORY:
        v.pc.reset(v.yaw())
    v.sp_kind = SetpointKind.TRAJECTORY
    v.sp_traj = sp
    _stamp(v, m, sim_t)
