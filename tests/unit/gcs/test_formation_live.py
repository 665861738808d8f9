"""Offboard setpoints to the formation vehicle (gcs.formation.live): what a client's
SET_POSITION_TARGET_LOCAL_NED asks of the formation's centroid, in ENU."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from gcs.formation.live import (
    CHANGE_MPS,
    POSITION_GAIN,
    SEND_EVERY_S,
    SETPOINT_TIMEOUT_S,
    LiveSetpoints,
    parse_setpoint,
)
from swarm_common.mission.config import MissionError

POS_ONLY = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
            | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE | M.POSITION_TARGET_TYPEMASK_YAW_IGNORE)
VEL_ONLY = (M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
            | M.POSITION_TARGET_TYPEMASK_Z_IGNORE)


def msg(mask: int, pos=(0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), frame=M.MAV_FRAME_LOCAL_NED):
    return M.MAVLink_set_position_target_local_ned_message(
        0, 200, 1, frame, mask, *pos, *vel, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_ned_setpoints_become_enu() -> None:
    v = parse_setpoint(msg(VEL_ONLY, vel=(1.0, 2.0, -0.5)), 3.0)  # north 1, east 2, up 0.5
    assert v.position is None and v.received == 3.0
    np.testing.assert_array_equal(v.velocity, [2.0, 1.0, 0.5])
    p = parse_setpoint(msg(POS_ONLY, pos=(4.0, -1.0, -5.0)), 3.0)
    assert p.velocity is None
    np.testing.assert_array_equal(p.position, [-1.0, 4.0, 5.0])


@pytest.mark.parametrize("bad", [
    msg(VEL_ONLY, frame=M.MAV_FRAME_BODY_NED),
    msg(VEL_ONLY | POS_ONLY),  # neither
    msg(VEL_ONLY, vel=(float("nan"), 0.0, 0.0)),
    msg(POS_ONLY, pos=(0.0, float("inf"), 0.0)),
])
def test_what_cannot_be_flown_is_refused(bad) -> None:
    with pytest.raises(MissionError):
        parse_setpoint(bad, 0.0)


def test_speed_limit_timeout_and_when_a_command_goes() -> None:
    live = LiveSetpoints(max_speed_mps=2.0)
    assert not live.fresh(0.0) and np.array_equal(live.velocity(np.zeros(3)), np.zeros(3))
    with pytest.raises(MissionError, match="above"):
        live.take(parse_setpoint(msg(VEL_ONLY, vel=(2.1, 0.0, 0.0)), 0.0))
    assert live.latest is None  # nothing kept
    live.take(parse_setpoint(msg(VEL_ONLY, vel=(1.0, 0.0, 0.0)), 10.0))
    assert live.fresh(10.0 + SETPOINT_TIMEOUT_S) and not live.fresh(10.0 + SETPOINT_TIMEOUT_S
                                                                      + 1e-6)
    v = live.velocity(np.zeros(3))
    assert live.due(0.0, v)
    live.sent(5.0, v)
    assert not live.due(5.0 + SEND_EVERY_S * 0.99, v)
    assert live.due(5.0 + SEND_EVERY_S, v)
    assert live.due(5.01, v + [0.0, 1.01 * CHANGE_MPS, 0.0])  # a change goes at once


def test_a_position_setpoint_slows_into_its_target() -> None:
    live = LiveSetpoints(max_speed_mps=2.0)
    live.take(parse_setpoint(msg(POS_ONLY, pos=(0.0, 10.0, -5.0)), 0.0))  # ENU (10, 0, 5)
    far = live.velocity(np.array([0.0, 0.0, 5.0]))
    assert np.linalg.norm(far) == pytest.approx(2.0) and far[0] == pytest.approx(2.0)
    near = live.velocity(np.array([9.0, 0.0, 5.0]))
    np.testing.assert_allclose(near, [POSITION_GAIN * 1.0, 0.0, 0.0], atol=1e-12)
    # stepping the centroid with what it asks converges on the target
    c = np.array([0.0, 0.0, 5.0])
    for _ in range(200):
        c = c + 0.1 * live.velocity(c)
    np.testing.assert_allclose(c, [10.0, 0.0, 5.0], atol=1e-3)
