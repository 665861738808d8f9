"""PX4 flight modes and commands through an unmodified MAVSDK over loopback UDP: ``action``
(take-off, goto, return to launch, land) and ``offboard`` with velocity, position and
acceleration setpoints, flown by the simulated vehicle's own position controller.

One vehicle of ground8 (on its pad), real time. Distances and altitudes are small and
every check is an outcome with a tolerance, never a duration."""

from __future__ import annotations

import math
import time

import pytest
from conftest import ROOT, wait_for
from mavsdk_client import mavsdk_autopilot, position_ready

pytestmark = pytest.mark.timeout(180)

GROUND8 = str(ROOT / "scenarios" / "ground8.toml")
ONE = ["--no-zenoh", "--vehicles", "1"]
M_PER_DEG = 111_320.0  # metres per degree of latitude (flat earth, for offsets only)
TAKEOFF_ALT = 3.0
RTL_ALT = 5.0


@pytest.fixture
def drone(sim_factory):
    """(sim, system, telemetry) with an unmodified MAVSDK on vehicle 1's API link."""
    pytest.importorskip("mavsdk")
    from mavsdk.plugins.telemetry import Telemetry

    sim = sim_factory(ONE, scenario=GROUND8)
    with mavsdk_autopilot(sim) as system:
        tel = Telemetry(system)
        assert wait_for(lambda: position_ready(tel) and tel.health().is_armable,
                        10.0), sim.text()  # fmt: skip
        yield sim, system, tel


def _rel_alt(tel) -> float:
    return float(tel.position().relative_altitude_m)


def _ned(tel) -> tuple[float, float, float]:
    p = tel.position_velocity_ned().position
    return p.north_m, p.east_m, p.down_m


def _take_off(system, tel) -> None:
    from mavsdk.plugins.action import Action

    act = Action(system)
    act.set_takeoff_altitude(TAKEOFF_ALT)
    assert act.get_takeoff_altitude() == pytest.approx(TAKEOFF_ALT)
    act.arm()
    assert wait_for(tel.armed, 5.0)
    act.takeoff()
    assert wait_for(lambda: abs(_rel_alt(tel) - TAKEOFF_ALT) < 0.3, 30.0), _rel_alt(tel)


def test_takeoff_goto_return_to_launch(drone) -> None:
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.telemetry import FlightMode, LandedState

    sim, system, tel = drone
    act = Action(system)
    home = tel.position()
    home_ned = _ned(tel)
    _take_off(system, tel)
    assert wait_for(lambda: tel.flight_mode() == FlightMode.HOLD, 10.0)  # as PX4: loiter
    assert wait_for(lambda: tel.landed_state() == LandedState.IN_AIR, 5.0)
    # goto 10 m north, 4 m above home (absolute altitude, as MAVSDK sends it)
    lat = home.latitude_deg + 10.0 / M_PER_DEG
    act.goto_location(lat, home.longitude_deg, home.absolute_altitude_m + 4.0, math.nan)

    def at_goal() -> bool:
        n, e, d = _ned(tel)
        return math.dist((n, e, -d), (home_ned[0] + 10.0, home_ned[1], 4.0)) < 0.5

    assert wait_for(at_goal, 30.0), _ned(tel)
    act.set_return_to_launch_altitude(RTL_ALT)
    act.return_to_launch()
    assert wait_for(lambda: tel.flight_mode() == FlightMode.RETURN_TO_LAUNCH, 5.0)
    assert wait_for(lambda: _rel_alt(tel) > RTL_ALT - 0.4, 20.0)  # climbed to RTL_RETURN_ALT
    assert wait_for(lambda: not tel.armed(), 60.0), sim.text()  # landed and disarmed
    n, e, _ = _ned(tel)
    assert math.hypot(n - home_ned[0], e - home_ned[1]) < 0.6
    assert _rel_alt(tel) < 0.2


def test_land(drone) -> None:
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.telemetry import LandedState

    sim, system, tel = drone
    _take_off(system, tel)
    Action(system).land()
    assert wait_for(lambda: tel.landed_state() == LandedState.LANDING, 5.0)
    assert wait_for(lambda: not tel.armed(), 30.0), sim.text()
    assert _rel_alt(tel) < 0.2


def _start_offboard(system, tel, set_first) -> None:
    from mavsdk.plugins.offboard import Offboard
    from mavsdk.plugins.telemetry import FlightMode

    off = Offboard(system)
    set_first(off)
    time.sleep(0.3)  # MAVSDK streams the setpoint at 20 Hz
    off.start()
    assert wait_for(lambda: tel.flight_mode() == FlightMode.OFFBOARD, 5.0)


def test_offboard_velocity_position_acceleration(drone) -> None:
    from mavsdk.plugins.offboard import AccelerationNed, Offboard, PositionNedYaw, VelocityNedYaw
    from mavsdk.plugins.telemetry import FlightMode

    sim, system, tel = drone
    _take_off(system, tel)
    off = Offboard(system)
    _start_offboard(system, tel, lambda o: o.set_velocity_ned(VelocityNedYaw(0, 0, 0, 0)))
    # velocity: 1 m/s east, 0.5 m/s up
    off.set_velocity_ned(VelocityNedYaw(0.0, 1.0, -0.5, 0.0))

    def vel_ok() -> bool:
        v = tel.position_velocity_ned().velocity
        return math.dist((v.north_m_s, v.east_m_s, v.down_m_s), (0.0, 1.0, -0.5)) < 0.2

    assert wait_for(vel_ok, 10.0), tel.position_velocity_ned().velocity
    # position: 3 m north and 2 m west of the take-off point's NED origin, 4 m up
    n0, e0, _ = _ned(tel)
    goal = (n0 + 3.0, e0 - 2.0, -4.0)
    off.set_position_ned(PositionNedYaw(*goal, 0.0))

    def pos_ok() -> bool:
        n, e, d = _ned(tel)
        return math.dist((n, e, d), goal) < 0.3

    assert wait_for(pos_ok, 20.0), (_ned(tel), goal)
    # acceleration: 1 m/s² north (no yaw in MAVSDK's acceleration setpoint): speeds up north
    off.set_acceleration_ned(AccelerationNed(1.0, 0.0, 0.0))
    assert wait_for(lambda: tel.position_velocity_ned().velocity.north_m_s > 1.5, 10.0)
    off.set_position_ned(PositionNedYaw(*goal, 0.0))  # back before it goes too far
    assert wait_for(pos_ok, 30.0), (_ned(tel), goal)
    off.stop()  # MAVSDK switches to Hold
    assert wait_for(lambda: tel.flight_mode() == FlightMode.HOLD, 5.0)
