"""The PX4 parameters clients read and write first, each end to end on one vehicle: written
with a MAVLink PARAM_SET (answered by PARAM_VALUE), read back with PARAM_REQUEST_READ,
and seen to change what the vehicle does (flown on the real dynamics of ground8, the
vehicle on its pad at z = 0, stepped as the server steps it). Also PX4's take-off
altitude rule (vehicle_sim.autopilot.modes.takeoff_altitude) and the range checks."""

from __future__ import annotations

import numpy as np
import pytest
from one_vehicle import NAN, OneVehicle
from pymavlink.dialects.v20 import common as M

from swarm_common import px4
from swarm_common.enums import VehicleMode
from vehicle_sim.autopilot import setpoints
from vehicle_sim.autopilot.modes import takeoff_altitude
from vehicle_sim.autopilot.nav_flight import OFFBOARD_LIMITS
from vehicle_sim.autopilot.params import INT32
from vehicle_sim.physics.position_control import PositionSetpoint
from vehicle_sim.services.param import int32_to_wire, wire_to_int32
from vehicle_sim.vehicle import Vehicle

GCS = ("gcs", ("127.0.0.1", 14550))
# a measured peak speed against the limit it should fly at: the velocity loop (with its
# integral) overshoots by up to 20 %; 0.9 × below: the limit is flown, not only a bound
PEAK_LO, PEAK_HI = 0.9, 1.25


def at_rate(peak: float, limit: float) -> bool:
    return PEAK_LO * limit <= peak <= PEAK_HI * limit


def mav_set(v: Vehicle, name: str, value: float) -> None:
    """PARAM_SET over MAVLink; asserts the PARAM_VALUE broadcast and a read-back."""
    spec = v.params.spec(name)
    wire = int32_to_wire(int(value)) if spec.ptype == INT32 else float(value)
    v.outbox.clear()
    v.handle(M.MAVLink_param_set_message(1, 1, name.encode(), wire, spec.ptype), GCS, 0.0, 0.0)
    echoed = [m for m, d in v.outbox if m.get_type() == "PARAM_VALUE" and m.param_id == name]
    assert echoed, f"no PARAM_VALUE for {name}: {v.outbox}"
    assert mav_read(v, name) == pytest.approx(value)


def mav_read(v: Vehicle, name: str) -> float:
    v.outbox.clear()
    v.handle(M.MAVLink_param_request_read_message(1, 1, name.encode(), -1), GCS, 0.0, 0.0)
    (m,) = [m for m, _ in v.outbox if m.get_type() == "PARAM_VALUE"]
    assert m.param_id == name
    return float(wire_to_int32(m.param_value)) if m.param_type == INT32 else float(m.param_value)


def statustexts(v: Vehicle) -> list[str]:
    return [m.text for m, _ in v.outbox if m.get_type() == "STATUSTEXT"]


# -- take-off altitude ------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("z_now", "requested", "mis", "expected"),
    [
        (0.0, None, 2.5, 2.5),  # NaN: home + MIS_TAKEOFF_ALT
        (10.0, None, 2.5, 10.0),  # … already higher: stays where it is
        (0.0, 1.0, 10.0, 10.0),  # a requested altitude under the minimum is raised to it
        (0.0, 30.0, 2.5, 30.0),  # above it: as requested
        (5.0, 3.0, 2.5, 5.0),  # below the vehicle: stays where it is, never descends
    ],
)
def test_takeoff_altitude_rule(z_now, requested, mis, expected) -> None:
    assert takeoff_altitude(z_now, requested, mis) == expected


def test_mis_takeoff_alt_is_the_minimum_and_a_higher_request_wins() -> None:
    s = OneVehicle()
    v = s.v
    assert mav_read(v, "MIS_TAKEOFF_ALT") == pytest.approx(2.5)
    mav_set(v, "MIS_TAKEOFF_ALT", 4.0)
    v.arm(0.0)
    v.outbox.clear()
    assert s.run(M.MAV_CMD_NAV_TAKEOFF) == M.MAV_RESULT_ACCEPTED  # p7 NaN
    assert "Using minimum takeoff altitude: 4.00 m" in statustexts(v)
    s.step(8.0)
    assert v.mode == VehicleMode.HOLD and s.p[2] == pytest.approx(4.0, abs=0.2)
    # an explicit altitude (AMSL, COMMAND_LONG) under home + MIS_TAKEOFF_ALT is raised
    mav_set(v, "MIS_TAKEOFF_ALT", 6.0)
    v.outbox.clear()
    assert s.run(M.MAV_CMD_NAV_TAKEOFF, *(NAN,) * 6, v.cfg.home_alt + 1.0) == 0
    assert "Using minimum takeoff altitude: 6.00 m" in statustexts(v)
    s.step(6.0)
    assert s.p[2] == pytest.approx(6.0, abs=0.2)
    # above the minimum: flown as requested (a height above home, RELATIVE_ALT frame)
    assert s.run(M.MAV_CMD_NAV_TAKEOFF, *(NAN,) * 6, 8.0,
                 frame=M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT) == 0  # fmt: skip
    s.step(6.0)
    assert s.p[2] == pytest.approx(8.0, abs=0.2)
    # under the vehicle: it stays, and says so
    v.outbox.clear()
    assert s.run(M.MAV_CMD_NAV_TAKEOFF, *(NAN,) * 6, v.cfg.home_alt + 7.0) == 0
    assert "Already higher than takeoff altitude" in statustexts(v)
    s.step(3.0)
    assert s.p[2] == pytest.approx(8.0, abs=0.2)


# -- speeds --------------------------------------------------------------------------------
@pytest.mark.parametrize("tko_speed", [1.0, 2.5])
def test_mpc_tko_speed_is_the_takeoff_climb_rate(tko_speed: float) -> None:
    s = OneVehicle()
    assert mav_read(s.v, "MPC_TKO_SPEED") == pytest.approx(1.5)
    mav_set(s.v, "MPC_TKO_SPEED", tko_speed)
    mav_set(s.v, "MIS_TAKEOFF_ALT", 10.0)
    s.v.arm(0.0)
    s.run(M.MAV_CMD_NAV_TAKEOFF)
    s.step(4.0)
    assert at_rate(s.trace()[:, 2].max(), tko_speed)


def test_mpc_z_vel_max_up_caps_the_takeoff_speed_and_every_climb() -> None:
    s = OneVehicle()
    mav_set(s.v, "MPC_TKO_SPEED", 2.5)
    mav_set(s.v, "MPC_Z_VEL_MAX_UP", 1.0)
    mav_set(s.v, "MIS_TAKEOFF_ALT", 3.0)
    s.v.arm(0.0)
    s.run(M.MAV_CMD_NAV_TAKEOFF)
    s.step(6.0)
    assert at_rate(s.trace()[:, 2].max(), 1.0)  # not 2.5
    assert s.goto(s.p[1], s.p[0], 12.0) == M.MAV_RESULT_ACCEPTED
    s.step(5.0)
    assert at_rate(s.trace()[:, 2].max(), 1.0)  # not 3 (the default ceiling)


def _airborne(alt: float = 6.0) -> OneVehicle:
    s = OneVehicle()
    mav_set(s.v, "MIS_TAKEOFF_ALT", alt)
    s.v.arm(0.0)
    s.run(M.MAV_CMD_NAV_TAKEOFF)
    s.step(alt / 1.5 + 3.0)
    assert s.p[2] == pytest.approx(alt, abs=0.3)
    s.trace()
    return s


@pytest.mark.parametrize("xy_max", [None, 2.0])
def test_mpc_xy_vel_max_caps_the_cruise_speed(xy_max: float | None) -> None:
    s = _airborne()
    assert mav_read(s.v, "MPC_XY_VEL_MAX") == pytest.approx(12.0)
    if xy_max is not None:
        mav_set(s.v, "MPC_XY_VEL_MAX", xy_max)
    p0 = s.p
    assert s.goto(p0[1] + 30.0, p0[0], 6.0) == M.MAV_RESULT_ACCEPTED
    s.step(8.0)
    vxy = np.hypot(*s.trace()[:, :2].T).max()
    if xy_max is None:
        assert vxy >= 4.5  # MPC_XY_CRUISE (5 m/s) is flown …
    else:  # … unless the ceiling is lower
        assert at_rate(vxy, xy_max)
        # DO_CHANGE_SPEED above the ceiling is refused, below it accepted
        assert s.run(M.MAV_CMD_DO_CHANGE_SPEED, 1, 3.0) == M.MAV_RESULT_DENIED
        assert s.run(M.MAV_CMD_DO_CHANGE_SPEED, 1, 1.5) == M.MAV_RESULT_ACCEPTED


def test_speed_ceilings_reach_the_offboard_velocity_reference() -> None:
    """OFFBOARD flies OFFBOARD_LIMITS (PX4's defaults); after a PARAM_SET the vehicle's
    position controller caps them at the new ceilings from the next step on."""
    s = OneVehicle()
    far = PositionSetpoint(pos=np.array([1000.0, 1000.0, 1000.0]))
    below = PositionSetpoint(pos=np.array([1000.0, 1000.0, -1000.0]))
    s.step(s.dt)
    v_ref = s.v.pc.velocity_reference(far, s.p, OFFBOARD_LIMITS)
    assert np.hypot(*v_ref[:2]) == pytest.approx(12.0) and v_ref[2] == pytest.approx(3.0)
    mav_set(s.v, "MPC_XY_VEL_MAX", 4.0)
    mav_set(s.v, "MPC_Z_VEL_MAX_UP", 2.0)
    mav_set(s.v, "MPC_Z_VEL_MAX_DN", 0.8)
    s.step(s.dt)
    v_ref = s.v.pc.velocity_reference(far, s.p, OFFBOARD_LIMITS)
    assert np.hypot(*v_ref[:2]) == pytest.approx(4.0) and v_ref[2] == pytest.approx(2.0)
    assert s.v.pc.velocity_reference(below, s.p, OFFBOARD_LIMITS)[2] == pytest.approx(-0.8)


def test_mpc_z_vel_max_dn_caps_a_descent() -> None:
    s = _airborne(8.0)
    mav_set(s.v, "MPC_Z_VEL_MAX_DN", 0.6)
    assert s.goto(s.p[1], s.p[0], 2.0) == M.MAV_RESULT_ACCEPTED
    s.step(6.0)
    assert at_rate(-s.trace()[:, 2].min(), 0.6)  # not 1.5 (the default ceiling)


@pytest.mark.parametrize(("land", "dn_max", "expected"), [(0.4, None, 0.4), (1.5, 0.6, 0.6)])
def test_mpc_land_speed_is_the_descent_rate_within_the_ceiling(land, dn_max, expected) -> None:
    s = _airborne(6.0)
    assert mav_read(s.v, "MPC_LAND_SPEED") == pytest.approx(0.7)
    mav_set(s.v, "MPC_LAND_SPEED", land)
    if dn_max is not None:
        mav_set(s.v, "MPC_Z_VEL_MAX_DN", dn_max)
    assert s.run(M.MAV_CMD_NAV_LAND) == M.MAV_RESULT_ACCEPTED
    s.step(5.0)  # well above ground all along: 6 m - 5 s * 0.6 m/s = 3 m
    assert at_rate(-s.trace()[:, 2].min(), expected)


# -- offboard loss ----------------------------------------------------------------------------
def _offboard(s: OneVehicle) -> float:
    """OFFBOARD entered on two setpoints; returns the time of the last one."""
    m = M.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, M.MAV_FRAME_LOCAL_NED,
        setpoints.VEL_BITS[0] | setpoints.VEL_BITS[1] | setpoints.VEL_BITS[2]
        | setpoints.ACC_BITS[0] | setpoints.ACC_BITS[1] | setpoints.ACC_BITS[2]
        | setpoints.YAW_RATE_BIT,
        0.0, 0.0, -2.0, 0, 0, 0, 0, 0, 0, 0.0, 0.0,
    )  # fmt: skip
    for t in (0.0, 0.1):
        s.v.handle(m, GCS, 0.0, t)
    assert s.v.request_mode(px4.MAIN_OFFBOARD, 0, 0.1) == M.MAV_RESULT_ACCEPTED
    s.v.arm(0.1)
    return 0.1


@pytest.mark.parametrize(("act", "mode"), [(4, VehicleMode.LAND), (3, VehicleMode.RTL),
                                           (5, VehicleMode.HOLD)])  # fmt: skip
def test_com_of_loss_t_and_com_obl_rc_act(act: int, mode: VehicleMode) -> None:
    s = OneVehicle()
    v = s.v
    mav_set(v, "COM_OF_LOSS_T", 2.0)
    mav_set(v, "COM_OBL_RC_ACT", act)
    last = _offboard(s)
    v.update(last + 1.9)
    assert v.mode == VehicleMode.OFFBOARD and not v.failsafe  # the default 0.5 s is gone
    v.update(last + 2.1)
    assert v.mode == mode and v.failsafe


# -- geofence ---------------------------------------------------------------------------------
def test_gf_max_hor_dist_with_gf_action_rtl() -> None:
    s = _airborne(4.0)
    v = s.v
    assert mav_read(v, "GF_MAX_HOR_DIST") == 0.0 and mav_read(v, "GF_ACTION") == 1
    home = v.home_enu
    mav_set(v, "GF_MAX_HOR_DIST", 6.0)
    mav_set(v, "GF_ACTION", 3)
    s.pos.clear()
    s.modes.clear()
    assert s.goto(home[1] + 20.0, home[0], 4.0) == M.MAV_RESULT_ACCEPTED
    s.step(8.0)
    assert VehicleMode.RTL in s.modes
    k = s.modes.index(VehicleMode.RTL)
    dist = float(np.hypot(*(s.pos[k] - home)[:2]))
    assert 6.0 <= dist <= 6.0 + 5.0 * s.dt * 2  # the step it crossed 6 m (≤ 5 m/s)


def test_gf_max_ver_dist_with_gf_action_land() -> None:
    s = OneVehicle()
    v = s.v
    mav_set(v, "GF_MAX_VER_DIST", 5.0)
    mav_set(v, "GF_ACTION", 5)
    mav_set(v, "MIS_TAKEOFF_ALT", 10.0)
    v.arm(0.0)
    s.run(M.MAV_CMD_NAV_TAKEOFF)
    s.step(8.0)
    assert VehicleMode.LAND in s.modes
    k = s.modes.index(VehicleMode.LAND)
    assert 5.0 <= s.pos[k][2] <= 5.2
    assert max(p[2] for p in s.pos) < 6.0  # it stopped climbing


def test_gf_action_none_does_nothing() -> None:
    s = _airborne(4.0)
    mav_set(s.v, "GF_MAX_VER_DIST", 2.0)
    mav_set(s.v, "GF_ACTION", 0)
    s.step(1.0)
    assert s.v.mission.fence_breached and s.v.mode == VehicleMode.HOLD
    assert s.p[2] == pytest.approx(4.0, abs=0.3)


# -- ranges -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "bad"),
    [
        ("MPC_XY_VEL_MAX", 0.0), ("MPC_XY_VEL_MAX", 25.0), ("MPC_Z_VEL_MAX_UP", 0.2),
        ("MPC_Z_VEL_MAX_UP", 9.0), ("MPC_Z_VEL_MAX_DN", 0.2), ("MPC_Z_VEL_MAX_DN", 5.0),
        ("MPC_TKO_SPEED", 0.1), ("MPC_TKO_SPEED", 6.0), ("MPC_LAND_SPEED", 0.1),
        ("MPC_LAND_SPEED", 4.0), ("MIS_TAKEOFF_ALT", -1.0), ("MIS_TAKEOFF_ALT", 250.0),
        ("COM_OF_LOSS_T", -0.1), ("COM_OF_LOSS_T", 61.0), ("COM_OBL_RC_ACT", 6),
        ("GF_ACTION", 6), ("GF_MAX_HOR_DIST", -1.0), ("GF_MAX_VER_DIST", 20_000.0),
        ("MPC_XY_VEL_MAX", NAN),
    ],
)  # fmt: skip
def test_out_of_range_set_is_refused_and_the_value_kept(name: str, bad: float) -> None:
    v = OneVehicle().v
    before = mav_read(v, name)
    spec = v.params.spec(name)
    wire = int32_to_wire(int(bad)) if spec.ptype == INT32 else bad
    v.outbox.clear()
    v.handle(M.MAVLink_param_set_message(1, 1, name.encode(), wire, spec.ptype), GCS, 0.0, 0.0)
    errs = [m for m, _ in v.outbox if m.get_type() == "PARAM_ERROR"]
    assert [e.error for e in errs] == [M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE]
    assert mav_read(v, name) == before
