"""Flight modes, arming and mode transitions of one simulated PX4 vehicle.

Functions of a :class:`~vehicle_sim.autopilot.state.VehicleState` (the
:class:`~vehicle_sim.vehicle.Vehicle` delegates to them); the state (``mode``, ``armed``,
``nav``, ``rtl`` …) stays on the vehicle. docs/px4/modes.md describes every mode; in
short:

* POSCTL, ALTCTL (no sticks: armed = hold), AUTO.LOITER without a target ("HOLD") and
  AUTO.LAND fly the onboard hold/land controller (:mod:`vehicle_sim.physics.failsafe_controller`),
  exactly as before the AUTO modes existed;
* AUTO.TAKEOFF, AUTO.LOITER with a target (DO_REPOSITION, the end of a take-off),
  AUTO.RTL and AUTO.MISSION fly a :class:`~vehicle_sim.autopilot.nav.NavTarget` (``vehicle.nav``)
  with the position controller (:mod:`vehicle_sim.physics.position_control`);
* OFFBOARD flies the client's setpoints; losing them for ``COM_OF_LOSS_T`` seconds
  (simulated time) triggers ``COM_OBL_RC_ACT``: 3 return, 4 land, anything else hold
  (there are no sticks, so PX4's position/altitude/manual actions hold too).

After touching down in a landing (AUTO.LAND, a mission's LAND, RTL's last phase) the
vehicle disarms once it has been on the ground for ``COM_DISARM_LAND`` seconds (a
negative value: never).
"""

from __future__ import annotations

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import px4
from swarm_common.enums import FailsafeAction, VehicleMode
from vehicle_sim.autopilot import nav_flight
from vehicle_sim.autopilot.nav import NavKind, NavTarget
from vehicle_sim.autopilot.param_defaults import OBL_ACT_LAND, OBL_ACT_RETURN
from vehicle_sim.autopilot.state import VehicleState

HOLD_MODES = (VehicleMode.POSCTL, VehicleMode.ALTCTL, VehicleMode.HOLD)
NAV_MODES = (VehicleMode.TAKEOFF, VehicleMode.RTL, VehicleMode.MISSION)


# -- entering modes -------------------------------------------------------------------------
def takeoff_altitude(
    z_now: float, alt_m: float | None, mis_takeoff_alt: float, home_z: float = 0.0,
) -> float:
    """PX4's take-off altitude (ENU z, m; Navigator ``Takeoff::set_takeoff_position`` as
    PX4 v1.14 has it, with the raise to the minimum): the minimum is home +
    ``MIS_TAKEOFF_ALT``; a requested altitude below it is raised to it ("Using minimum
    takeoff altitude"), no altitude (NaN) means the minimum; then never lower than now
    ("Already higher than takeoff altitude")."""
    minimum = float(home_z) + float(mis_takeoff_alt)
    alt = minimum if alt_m is None else max(float(alt_m), minimum)
    return max(alt, z_now)


def takeoff_target(v: VehicleState, alt_m: float | None, quiet: bool = False) -> NavTarget:
    """Climb over the current point to :func:`takeoff_altitude`; tells the client, as PX4
    does, when it uses or raises to the minimum, or keeps the current altitude (``quiet``:
    no)."""
    p = v.p()
    z_now = float(p[2])
    mis = float(v.params.get("MIS_TAKEOFF_ALT"))
    home_z = float(v.home_enu[2])
    alt = takeoff_altitude(z_now, alt_m, mis, home_z)
    if not quiet:
        minimum = home_z + mis
        if alt_m is None:
            v.event(f"Using minimum takeoff altitude: {mis:.2f} m", M.MAV_SEVERITY_INFO)
        elif alt_m < minimum - 0.1:
            v.event(f"Using minimum takeoff altitude: {mis:.2f} m", M.MAV_SEVERITY_CRITICAL)
        if (minimum if alt_m is None else max(alt_m, minimum)) < z_now:
            v.event("Already higher than takeoff altitude", M.MAV_SEVERITY_CRITICAL)
    return NavTarget(NavKind.TAKEOFF, np.array([p[0], p[1], alt]))


def rtl_plan(v: VehicleState) -> nav_flight.RtlPlan:
    """A return from here to the nearest rally point, else home."""
    dest = nav_flight.nearest_xy(v.p(), v.home_enu, v.mission.rally_points_enu())
    return nav_flight.RtlPlan(v.p(), dest, float(v.params.get("RTL_RETURN_ALT")))


def engage_onboard(v: VehicleState) -> None:
    """Point the controllers at the current mode, from here (on a mode change, on arming)."""
    if v.mode in HOLD_MODES:
        v.fs.engage(FailsafeAction.HOLD, v.p(), v.yaw())
    elif v.mode == VehicleMode.LAND:
        land = min(float(v.params.get("MPC_LAND_SPEED")), float(v.params.get("MPC_Z_VEL_MAX_DN")))
        v.fs.gains.land_speed = land
        v.fs.engage(FailsafeAction.LAND, v.p(), v.yaw())
    v.pc.reset(v.yaw())


def enter_mode(
    v: VehicleState, mode: VehicleMode, why: str = "", nav: NavTarget | None = None
) -> None:
    """Switch to ``mode``; ``nav``: the target an AUTO.LOITER flies (None: hold here)."""
    prev = v.mode
    v.mode = mode
    keep_integral = nav is not None and (prev in NAV_MODES or v.nav is not None)
    v.nav = nav
    v.rtl = None
    if not keep_integral:
        engage_onboard(v)
    if mode == VehicleMode.TAKEOFF:
        v.nav = takeoff_target(v, v.takeoff_alt)
    elif mode == VehicleMode.RTL:
        v.rtl = rtl_plan(v)
        v.nav = v.rtl.target(v.p(), v.dyn.v[v.idx])
    v.takeoff_alt = None
    v.landed_since = None
    if prev != mode or why:
        v.event(f"mode {prev} -> {mode}{(' (' + why + ')') if why else ''}")


def request_mode(v: VehicleState, main: int, sub: int, sim_t: float) -> int:
    """Switch on a PX4 (main, sub) custom mode. Returns a MAV_RESULT."""
    target = px4.vehicle_mode(main, sub)
    if target is None:
        return M.MAV_RESULT_UNSUPPORTED
    if v.terminated:
        return M.MAV_RESULT_DENIED
    if target == VehicleMode.OFFBOARD and not v.setpoints_streaming(sim_t):
        v.event("OFFBOARD refused: no setpoint stream", M.MAV_SEVERITY_WARNING)
        return M.MAV_RESULT_TEMPORARILY_REJECTED
    if target == VehicleMode.RTL and not v.armed:
        v.event("RTL refused: not armed", M.MAV_SEVERITY_WARNING)
        return M.MAV_RESULT_DENIED
    if target == VehicleMode.MISSION and target != v.mode:
        res = int(v.mission.start(sim_t))
        if res != M.MAV_RESULT_ACCEPTED:
            v.event("MISSION refused: no mission", M.MAV_SEVERITY_WARNING)
            return res
    v.failsafe = False
    if target != v.mode:
        enter_mode(v, target)
    return M.MAV_RESULT_ACCEPTED


def takeoff(v: VehicleState, alt_m: float | None) -> int:
    """NAV_TAKEOFF: AUTO.TAKEOFF to ENU z ``alt_m`` (None: home + MIS_TAKEOFF_ALT; raised to
    that minimum, never down: :func:`takeoff_altitude`)."""
    if v.terminated:
        return M.MAV_RESULT_DENIED
    v.failsafe = False
    v.takeoff_alt = alt_m
    enter_mode(v, VehicleMode.TAKEOFF, "takeoff")
    return M.MAV_RESULT_ACCEPTED


def reposition(v: VehicleState, target: NavTarget) -> int:
    """DO_REPOSITION: AUTO.LOITER flying to ``target`` (armed vehicles only, as PX4)."""
    if v.terminated or not v.armed:
        return M.MAV_RESULT_DENIED
    v.failsafe = False
    enter_mode(v, VehicleMode.HOLD, "reposition", nav=target)
    return M.MAV_RESULT_ACCEPTED


def start_mission(v: VehicleState, sim_t: float) -> int:
    """MISSION_START: (re)start the stored mission in AUTO.MISSION."""
    if v.terminated:
        return M.MAV_RESULT_DENIED
    res = int(v.mission.start(sim_t))
    if res == M.MAV_RESULT_ACCEPTED:
        v.failsafe = False
        enter_mode(v, VehicleMode.MISSION, "mission start")
    return res


# -- arming ---------------------------------------------------------------------------------
def arm(v: VehicleState, sim_t: float) -> int:
    if v.terminated:
        v.event("arming denied: flight terminated", M.MAV_SEVERITY_CRITICAL)
        return M.MAV_RESULT_DENIED
    if v.armed:
        return M.MAV_RESULT_ACCEPTED
    if v.mode == VehicleMode.RTL:
        v.event("arming denied: not in an armable mode", M.MAV_SEVERITY_WARNING)
        return M.MAV_RESULT_DENIED
    v.armed = True
    if not v.ever_armed:
        v.ever_armed = True
        v.release_requested = True
    engage_onboard(v)
    if v.mode == VehicleMode.TAKEOFF:
        z = None if v.nav is None else float(v.nav.position_enu[2])
        v.nav = takeoff_target(v, z, quiet=z is not None)
    v.landed_since = None
    v.event("armed")
    return M.MAV_RESULT_ACCEPTED


def disarm(v: VehicleState, force: bool, why: str = "") -> int:
    if not v.armed:
        return M.MAV_RESULT_ACCEPTED
    if not force and not v.on_ground():
        v.event("disarm denied: not landed", M.MAV_SEVERITY_WARNING)
        return M.MAV_RESULT_DENIED
    v.armed = False
    v.failsafe = False
    if v.mode not in (VehicleMode.TAKEOFF, VehicleMode.MISSION):
        v.nav = None
    v.rtl = None
    v.release_requested = True  # a forced disarm drops it, fixture or not
    v.event("disarmed" + (f" ({why})" if why else ""))
    return M.MAV_RESULT_ACCEPTED


def terminate(v: VehicleState) -> int:
    v.terminated = True
    v.armed = False
    v.failsafe = False
    v.release_requested = True
    v.event("FLIGHT TERMINATION: motors off", M.MAV_SEVERITY_EMERGENCY)
    return M.MAV_RESULT_ACCEPTED


# -- per step ---------------------------------------------------------------------------------
def offboard_loss(v: VehicleState, sim_t: float) -> None:
    """In OFFBOARD without a valid setpoint for COM_OF_LOSS_T: COM_OBL_RC_ACT."""
    timeout = float(v.params.get("COM_OF_LOSS_T"))
    if (
        v.mode == VehicleMode.OFFBOARD
        and not v.failsafe
        and (v.last_sp_t is None or sim_t - v.last_sp_t > timeout)
    ):
        v.ctr.failsafes += 1
        act = int(v.params.get("COM_OBL_RC_ACT"))
        target = VehicleMode.HOLD
        if act == OBL_ACT_LAND:
            target = VehicleMode.LAND
        elif act == OBL_ACT_RETURN and v.armed:
            target = VehicleMode.RTL
        v.event(f"failsafe: offboard lost, {target.lower()}", M.MAV_SEVERITY_CRITICAL)
        enter_mode(v, target)
        v.failsafe = True


def advance_auto(v: VehicleState, sim_t: float) -> None:
    """AUTO modes: take-off complete -> loiter there; RTL phases; the mission's target."""
    if not v.armed:
        return
    p = v.p()
    if v.mode == VehicleMode.TAKEOFF and v.nav is not None:
        if nav_flight.takeoff_reached(v.nav, p):
            loiter = NavTarget(NavKind.LOITER, np.array(v.nav.position_enu, dtype=float))
            enter_mode(v, VehicleMode.HOLD, "takeoff complete", nav=loiter)
    elif v.mode == VehicleMode.RTL and v.rtl is not None:
        v.nav = v.rtl.target(p, v.dyn.v[v.idx])
    elif v.mode == VehicleMode.MISSION:
        t = v.mission.nav_target(p, v.dyn.v[v.idx], sim_t)
        if t is not None and t.kind == NavKind.RTL:
            enter_mode(v, VehicleMode.RTL, "mission")
        elif t is not None:
            v.nav = t
        elif not v.on_ground():
            enter_mode(v, VehicleMode.HOLD, "mission complete")
        else:
            v.nav = None


def auto_disarm(v: VehicleState, sim_t: float) -> None:
    """Disarm after COM_DISARM_LAND seconds on the ground in a landing."""
    delay = float(v.params.get("COM_DISARM_LAND"))
    if not v.landing or delay < 0:
        return
    if v.on_ground():
        if v.landed_since is None:
            v.landed_since = sim_t
        elif sim_t - v.landed_since >= delay:
            disarm(v, force=False, why="landed")
    else:
        v.landed_since = None
