"""vehicle_sim.physics.position_control and the AUTO modes, flown on the real dynamics.

One vehicle of ground8 (on its pad at z = 0), stepped as the server steps it: the
vehicle's update, its command, physics_hz / control_hz dynamics steps
(:class:`one_vehicle.OneVehicle`)."""

from __future__ import annotations

import numpy as np
import pytest
from one_vehicle import NAN, OneVehicle
from pymavlink.dialects.v20 import common as M

from swarm_common.enums import VehicleMode
from vehicle_sim.autopilot.nav_flight import OFFBOARD_LIMITS
from vehicle_sim.physics.position_control import PositionController, PositionSetpoint, SpeedLimits


def fly_controller(pc: PositionController, sp: PositionSetpoint, seconds: float) -> OneVehicle:
    """The bare controller on a vehicle released in the air at 5 m."""
    s = OneVehicle()
    s.dyn.p[0, 2] = 5.0
    s.dyn.release(0)
    for _ in range(int(round(seconds / s.dt))):
        cmd = pc.update(sp, s.dyn.p[0], s.dyn.v[0], OFFBOARD_LIMITS, s.dt)
        s.dyn.set_command(0, *cmd)
        for _ in range(s.sub):
            s.dyn.step()
    return s


def _pc(hover: float | None = None) -> tuple[PositionController, float]:
    s = OneVehicle()
    d = s.dyn
    true_hover = d.hold_thrust() / d.f_max
    return PositionController(d.g, d.f_max, d.tilt_max, hover or true_hover), true_hover


def test_position_setpoint_is_reached() -> None:
    pc, _ = _pc()
    target = np.array([6.0, -3.0, 7.0])
    s = fly_controller(pc, PositionSetpoint(pos=target), 12.0)
    assert np.linalg.norm(s.dyn.p[0] - target) < 0.2
    assert np.linalg.norm(s.dyn.v[0]) < 0.2


def test_velocity_setpoint_is_tracked() -> None:
    pc, _ = _pc()
    vel = np.array([1.0, -0.5, 0.0])
    s = fly_controller(pc, PositionSetpoint(vel=vel), 6.0)
    assert s.dyn.v[0] == pytest.approx(vel, abs=0.1)


def test_speed_limits_bound_the_velocity_reference() -> None:
    pc, _ = _pc()
    lim = SpeedLimits(xy=2.0, up=1.0, down=0.5)
    ref = pc.velocity_reference(PositionSetpoint(pos=np.array([100.0, 0.0, 100.0])),
                                np.zeros(3), lim)  # fmt: skip
    assert ref == pytest.approx([2.0, 0.0, 1.0])
    ref = pc.velocity_reference(PositionSetpoint(vel=np.array([NAN, NAN, -3.0])), np.zeros(3), lim)
    assert ref[2] == pytest.approx(-0.5) and np.isnan(ref[0])


@pytest.mark.parametrize("factor", [0.8, 1.25])
def test_wrong_hover_thrust_is_a_transient_the_integrator_removes(factor: float) -> None:
    _, true_hover = _pc()
    pc, _ = _pc(true_hover * factor)
    hold = np.array([4.0, 0.0, 5.0])
    s = OneVehicle()
    s.dyn.p[0] = hold
    s.dyn.release(0)
    dz = []
    for _ in range(int(round(15.0 / s.dt))):
        cmd = pc.update(PositionSetpoint(pos=hold), s.dyn.p[0], s.dyn.v[0], OFFBOARD_LIMITS, s.dt)
        s.dyn.set_command(0, *cmd)
        for _ in range(s.sub):
            s.dyn.step()
        dz.append(float(s.dyn.p[0, 2] - hold[2]))
    assert max(abs(x) for x in dz) > 0.1  # a visible transient …
    settled = dz[-int(round(3.0 / s.dt)) :]
    assert max(abs(x) for x in settled) < 0.05  # … that the integral removes


def test_takeoff_goto_rtl_land_disarm() -> None:
    s = OneVehicle()
    v = s.v
    home = s.p
    v.params.set("MIS_TAKEOFF_ALT", 3.0)
    v.params.set("RTL_RETURN_ALT", 6.0)
    assert v.arm(0.0) == M.MAV_RESULT_ACCEPTED
    assert s.run(M.MAV_CMD_NAV_TAKEOFF) == M.MAV_RESULT_ACCEPTED
    s.step(0.5)
    assert v.taking_off and v.mode == VehicleMode.TAKEOFF
    s.step(6.0)
    assert v.mode == VehicleMode.HOLD and s.p[2] == pytest.approx(3.0, abs=0.2)
    # DO_REPOSITION 10 m north at 5 m relative altitude (COMMAND_INT, relative frame)
    assert s.goto(home[1] + 10.0, home[0], 5.0) == M.MAV_RESULT_ACCEPTED
    s.step(10.0)
    assert s.p == pytest.approx(home + [0.0, 10.0, 5.0], abs=0.3)
    assert s.run(M.MAV_CMD_NAV_RETURN_TO_LAUNCH) == M.MAV_RESULT_ACCEPTED
    s.step(4.0)
    assert v.mode == VehicleMode.RTL and s.p[2] > 5.5  # climbed to RTL_RETURN_ALT
    for _ in range(40):
        s.step(1.0)
        if not v.armed:
            break
    assert not v.armed and v.on_ground()
    assert np.hypot(*(s.p - home)[:2]) < 0.5


def test_land_and_speed_commands() -> None:
    s = OneVehicle()
    v = s.v
    v.arm(0.0)
    s.run(M.MAV_CMD_NAV_TAKEOFF)
    s.step(5.0)
    assert s.run(M.MAV_CMD_DO_CHANGE_SPEED, 1, 2.0) == M.MAV_RESULT_ACCEPTED
    assert v.speed_override == 2.0
    assert s.run(M.MAV_CMD_DO_CHANGE_SPEED, 2, 1.0) == M.MAV_RESULT_UNSUPPORTED
    assert s.run(M.MAV_CMD_DO_CHANGE_SPEED, 1, 100.0) == M.MAV_RESULT_DENIED
    assert s.run(M.MAV_CMD_NAV_LAND) == M.MAV_RESULT_ACCEPTED
    s.step(0.5)
    assert v.landing
    s.step(8.0)
    assert not v.armed and v.on_ground()


def test_disarmed_vehicle_cannot_rtl_or_reposition() -> None:
    s = OneVehicle()
    assert s.run(M.MAV_CMD_NAV_RETURN_TO_LAUNCH) == M.MAV_RESULT_DENIED
    assert s.run(M.MAV_CMD_DO_REPOSITION, -1, 1, 0, NAN, NAN, NAN, 500.0) == M.MAV_RESULT_DENIED
    assert s.run(M.MAV_CMD_MISSION_START) == M.MAV_RESULT_DENIED  # no mission stored
