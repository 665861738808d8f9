"""vehicle_sim.autopilot.setpoints: PX4's type_mask rules for SET_POSITION_TARGET_*, and the
vehicle's bookkeeping of a position setpoint (counted, keeps OFFBOARD alive)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common import px4
from swarm_common.enums import VehicleMode
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot import setpoints
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.autopilot.setpoints import SetpointKind
from vehicle_sim.physics import geo
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
P = setpoints.POS_BITS[0] | setpoints.POS_BITS[1] | setpoints.POS_BITS[2]
V = setpoints.VEL_BITS[0] | setpoints.VEL_BITS[1] | setpoints.VEL_BITS[2]
A = setpoints.ACC_BITS[0] | setpoints.ACC_BITS[1] | setpoints.ACC_BITS[2]
YAW, RATE = setpoints.YAW_BIT, setpoints.YAW_RATE_BIT
LOCAL = M.MAV_FRAME_LOCAL_NED


def local(mask: int, frame: int = LOCAL, xyz=(1.0, 2.0, -3.0), vel=(0.5, -0.5, 0.1),
          acc=(0.0, 0.0, 0.0), yaw: float = 0.0, rate: float = 0.0, t_ms: int = 0):  # fmt: skip
    return M.MAVLink_set_position_target_local_ned_message(
        t_ms, 1, 1, frame, mask, *xyz, *vel, *acc, yaw, rate
    )


def test_position_only_in_local_ned_becomes_enu() -> None:
    sp = setpoints.parse_local_ned(local(V | A | RATE, yaw=0.0), np.zeros(3), 0.0)
    assert sp.pos == pytest.approx([2.0, 1.0, 3.0])  # NED (1, 2, -3) -> ENU (2, 1, 3)
    assert np.all(np.isnan(sp.vel)) and np.all(np.isnan(sp.acc))
    assert sp.yaw == pytest.approx(math.pi / 2)  # NED heading north = ENU yaw 90 deg
    assert sp.yaw_rate is None


def test_velocity_only_and_yaw_rate() -> None:
    sp = setpoints.parse_local_ned(local(P | A | YAW, rate=0.2), np.zeros(3), 0.0)
    assert sp.vel == pytest.approx([-0.5, 0.5, -0.1]) and np.all(np.isnan(sp.pos))
    assert sp.yaw is None and sp.yaw_rate == pytest.approx(-0.2)


def test_offset_and_body_frames() -> None:
    here = np.array([10.0, 20.0, 5.0])
    sp = setpoints.parse_local_ned(local(V | A, M.MAV_FRAME_LOCAL_OFFSET_NED), here, 0.0)
    assert sp.pos == pytest.approx(here + [2.0, 1.0, 3.0])
    # body frame, facing ENU +y (north): 1 m forward = +1 north, 2 m right = +2 east
    sp = setpoints.parse_local_ned(local(P | A, M.MAV_FRAME_BODY_NED, vel=(1.0, 2.0, 0.0)),
                                   here, math.pi / 2)  # fmt: skip
    assert sp.vel == pytest.approx([2.0, 1.0, 0.0])


@pytest.mark.parametrize(
    ("mask", "frame", "unsupported"),
    [
        (P | V | A, LOCAL, False),  # nothing to fly
        (P | V | A | YAW | RATE, LOCAL, False),
        (setpoints.POS_BITS[0] | V | A, LOCAL, False),  # x without y
        (setpoints.POS_BITS[2] | V | A, LOCAL, False),  # z has no setpoint
        (P | V | setpoints.FORCE_BIT, LOCAL, True),  # force setpoint
        (V | A, M.MAV_FRAME_GLOBAL, True),  # not a local frame
    ],
)
def test_invalid_masks_are_rejected(mask: int, frame: int, unsupported: bool) -> None:
    with pytest.raises(setpoints.Rejected) as exc:
        setpoints.parse_local_ned(local(mask, frame), np.zeros(3), 0.0)
    assert exc.value.unsupported == unsupported


def test_non_finite_given_component_is_rejected_ignored_one_is_not() -> None:
    with pytest.raises(setpoints.Rejected):
        setpoints.parse_local_ned(local(V | A, xyz=(math.nan, 0.0, -1.0)), np.zeros(3), 0.0)
    sp = setpoints.parse_local_ned(local(P | A, xyz=(math.nan,) * 3), np.zeros(3), 0.0)
    assert np.all(np.isfinite(sp.vel))


def test_global_int_relative_and_amsl() -> None:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    cfg = Vehicle(1, 0, dyn, AutopilotConfig()).cfg
    lat, lon = geo.latlon_e7(cfg, np.array([30.0, -4.0, 0.0]))
    for frame, alt in ((M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 7.0),
                       (M.MAV_FRAME_GLOBAL_INT, cfg.home_alt + 7.0)):  # fmt: skip
        m = M.MAVLink_set_position_target_global_int_message(
            0, 1, 1, frame, V | A | YAW | RATE, lat, lon, alt, 0, 0, 0, 0, 0, 0, 0, 0
        )
        sp = setpoints.parse_global_int(m, cfg)
        assert sp.pos == pytest.approx([-4.0, 30.0, 7.0], abs=0.02)


def test_vehicle_counts_and_streams_position_setpoints() -> None:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    v = Vehicle(1, 0, dyn, AutopilotConfig())
    v.handle(local(P | V | A), None, 0.0, 0.0)
    assert v.ctr.setpoints_rejected == 1 and v.ctr.setpoints == 0
    v.handle(local(P | V | setpoints.FORCE_BIT), None, 0.0, 0.0)
    assert v.ctr.setpoints_unsupported == 1
    for t in (0.0, 0.1):
        v.handle(local(P | A | YAW | RATE), None, 0.0, t)
    assert v.ctr.setpoints == 2 and v.sp_kind == SetpointKind.TRAJECTORY
    assert v.request_mode(px4.MAIN_OFFBOARD, 0, 0.1) == M.MAV_RESULT_ACCEPTED
    v.arm(0.1)
    v.update(0.3)
    assert v.mode == VehicleMode.OFFBOARD and not v.failsafe  # within COM_OF_LOSS_T
    v.update(1.0)
    assert v.mode == VehicleMode.HOLD and v.failsafe


def test_lockstep_echo_applies_to_position_setpoints() -> None:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    v = Vehicle(1, 0, dyn, AutopilotConfig(lockstep=True))
    v.expect_ms = 40
    v.handle(local(P | A | YAW | RATE, t_ms=20), None, 0.0, 0.04)
    assert v.ctr.setpoints_stale == 1 and v.answered_ms is None
    v.handle(local(P | A | YAW | RATE, t_ms=40), None, 0.0, 0.04)
    assert v.answered_ms == 40
