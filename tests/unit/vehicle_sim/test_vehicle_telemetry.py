"""vehicle_sim.autopilot.telemetry / streams / commands: the tables behind the vehicle state
machine."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common import px4
from swarm_common.enums import FailsafeAction, VehicleMode
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot import telemetry
from vehicle_sim.autopilot.config import DEFAULT_RATES, AutopilotConfig
from vehicle_sim.autopilot.streams import StreamSchedule
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services.command import Command, execute
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
HB = M.MAVLINK_MSG_ID_HEARTBEAT
ODOM = M.MAVLINK_MSG_ID_ODOMETRY


def _vehicle(**kw) -> Vehicle:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    return Vehicle(1, 0, dyn, AutopilotConfig(**kw))


def test_every_default_stream_has_a_builder_of_that_id() -> None:
    v = _vehicle()
    for mid in [*DEFAULT_RATES, ODOM, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION]:
        msg = telemetry.build(v, mid, 1.234)
        assert msg is not None and msg.get_msgId() == mid
        v.pack(msg)  # every field fits its wire type
    assert telemetry.build(v, M.MAVLINK_MSG_ID_GPS_STATUS, 0.0) is None


def test_heartbeat_reflects_mode_and_arming() -> None:
    v = _vehicle()
    hb = telemetry.heartbeat(v)
    assert hb.custom_mode == px4.CUSTOM_MODE[VehicleMode.POSCTL]
    assert hb.system_status == M.MAV_STATE_STANDBY
    assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert v.arm(0.0) == M.MAV_RESULT_ACCEPTED
    hb = telemetry.heartbeat(v)
    assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.system_status == M.MAV_STATE_ACTIVE
    v.terminate()
    assert telemetry.heartbeat(v).system_status == M.MAV_STATE_FLIGHT_TERMINATION


def test_time_stamps_are_simulation_time() -> None:
    v = _vehicle()
    assert telemetry.build(v, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 2.5).time_boot_ms == 2500
    assert telemetry.odometry(v, 2.5).time_usec == 2_500_000
    assert 2500 in v.odom_wall  # the send time of stamp 2.5 s is kept for the latency


def test_stream_schedule_rates_reset_and_heartbeat_clamp() -> None:
    s = StreamSchedule({HB: 1.0, M.MAVLINK_MSG_ID_ATTITUDE: 0.0}, odometry_hz=50.0)
    assert s.due(10.0) == [HB, ODOM]  # ATTITUDE is off
    assert s.due(10.01) == []
    assert s.due(10.02) == [ODOM]
    assert s.interval_us(ODOM) == 20_000 and s.interval_us(M.MAVLINK_MSG_ID_ATTITUDE) == -1
    s.set_interval(HB, -1, 11.0)  # HEARTBEAT can never be switched off
    assert s.intervals[HB] == pytest.approx(1.0)
    s.set_interval(HB, 1000, 11.0)  # nor faster than 50 Hz
    assert s.intervals[HB] == pytest.approx(0.02)
    s.set_interval(ODOM, -1, 11.0)
    assert ODOM not in s.due(20.0)
    s.set_interval(ODOM, 0, 20.0)  # 0: back to the default rate
    assert s.interval_us(ODOM) == 20_000
    s.set_interval(ODOM, 1e12, 20.0)
    assert s.intervals[ODOM] == pytest.approx(2000.0)
    assert M.MAVLINK_MSG_ID_GPS_STATUS not in s


def test_command_table() -> None:
    v = _vehicle()
    nan = math.nan

    def run(cmd: int, *p: float) -> tuple[int, object]:
        params = (*p, *(nan,) * (7 - len(p)))
        return execute(v, Command(cmd, params, wall=0.0, sim_t=0.0))

    assert run(M.MAV_CMD_COMPONENT_ARM_DISARM, nan) == (M.MAV_RESULT_DENIED, None)
    assert run(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == (M.MAV_RESULT_ACCEPTED, None) and v.armed
    assert run(M.MAV_CMD_NAV_LOITER_UNLIM)[0] == M.MAV_RESULT_ACCEPTED
    assert v.mode == VehicleMode.HOLD
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    res, _ = run(M.MAV_CMD_DO_SET_MODE, base, px4.MAIN_AUTO, px4.SUB_AUTO_FOLLOW_TARGET)
    assert res == M.MAV_RESULT_UNSUPPORTED
    res, _ = run(M.MAV_CMD_DO_SET_MODE, base, px4.MAIN_OFFBOARD + 256)  # not a uint8 mode
    assert res == M.MAV_RESULT_UNSUPPORTED and v.mode == VehicleMode.HOLD
    res, reply = run(M.MAV_CMD_GET_MESSAGE_INTERVAL, ODOM)
    assert res == M.MAV_RESULT_ACCEPTED and reply.interval_us == 20_000
    res, reply = run(M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
    assert reply.get_msgId() == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION
    assert run(M.MAV_CMD_NAV_TAKEOFF) == (M.MAV_RESULT_ACCEPTED, None)
    assert v.mode == VehicleMode.TAKEOFF
    assert run(M.MAV_CMD_DO_SET_SERVO) == (M.MAV_RESULT_UNSUPPORTED, None)
    assert run(M.MAV_CMD_REQUEST_MESSAGE, -1) == (M.MAV_RESULT_UNSUPPORTED, None)


def test_failsafe_action_land_from_config() -> None:
    v = _vehicle(failsafe=FailsafeAction.LAND, offboard_timeout=0.5)
    sp = M.MAVLink_set_attitude_target_message(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.5)
    for t in (0.0, 0.1):
        v.handle(sp, None, 0.0, t)
    assert v.request_mode(px4.MAIN_OFFBOARD, 0, 0.1) == M.MAV_RESULT_ACCEPTED
    v.arm(0.1)
    v.update(1.0)
    assert v.mode == VehicleMode.LAND and v.failsafe and v.fs.mode == FailsafeAction.LAND
    levels = [sev for sev, line in v.events if "failsafe" in line]
    assert levels == [M.MAV_SEVERITY_CRITICAL]
