"""The compiled attitude conversions of the simulator's telemetry (swarm_common.frames →
frames_kernel): rotation matrix, quaternion and ODOMETRY fields, against SciPy's
``Rotation`` (an independent implementation) and against the wire's float32 values of
the numpy formulation they replaced."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M
from scipy.spatial.transform import Rotation

from swarm_common import frames
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot import telemetry
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"


def _attitudes(n: int, seed: int) -> np.ndarray:
    """(n,3) roll, pitch, yaw: mostly flight attitudes, every fifth anywhere."""
    rng = np.random.default_rng(seed)
    att = rng.uniform(-1.0, 1.0, (n, 3)) * np.array([0.6, 0.6, math.pi])
    att[::5] = rng.uniform(-math.pi, math.pi, (len(att[::5]), 3))
    att[::5, 1] /= 2.0  # pitch within ±π/2, where ZYX angles are unique
    return att


def _scipy_ned_quat(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """[w, x, y, z] of T R_zyx D from SciPy, w ≥ 0."""
    r = frames.T_ENU_NED @ Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    x, y, z, w = Rotation.from_matrix(r @ frames.D_FRD_FLU).as_quat()
    q = np.array([w, x, y, z])
    return q if q[0] >= 0 else -q


def test_rotation_matrix_is_scipys_zyx() -> None:
    for roll, pitch, yaw in _attitudes(300, 1):
        want = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
        np.testing.assert_allclose(frames.rotm_from_euler(roll, pitch, yaw), want, atol=1e-15)


def test_ned_quaternion_is_scipys_and_unit_with_w_nonnegative() -> None:
    for roll, pitch, yaw in _attitudes(500, 2):
        q = frames.quat_ned_from_euler_enu(roll, pitch, yaw)
        assert q[0] >= 0.0
        assert abs(float(np.sum(q * q)) - 1.0) < 1e-15
        np.testing.assert_allclose(q, _scipy_ned_quat(roll, pitch, yaw), atol=1e-14)


def test_quaternion_of_each_branch_round_trips() -> None:
    """Each of the four formulas (trace, then the largest diagonal entry) gives back the
    matrix it was computed from."""
    for angle, axis in [(0.3, [0, 0, 1]), (3.0, [1, 0, 0]), (3.0, [0, 1, 0]), (3.0, [0, 0, 1])]:
        r = Rotation.from_rotvec(angle * np.asarray(axis, float)).as_matrix()
        q = frames.quat_from_rotm(r)
        np.testing.assert_allclose(frames.rotm_from_quat(q), r, atol=1e-15)
    with pytest.raises(ValueError):
        frames.quat_from_rotm(np.eye(4))


def test_odometry_fields_against_scipy_and_the_float32_wire() -> None:
    rng = np.random.default_rng(3)
    for att in _attitudes(400, 4):
        p, v = rng.normal(0.0, 5.0, 3), rng.normal(0.0, 2.0, 3)
        f = frames.odometry_ned(p, v, att)
        assert np.array_equal(f[:3], frames.enu_to_ned(p))  # a permutation: exact
        q = _scipy_ned_quat(*att)
        np.testing.assert_allclose(f[3:7], q, atol=1e-14)
        r_ned_frd = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
        v_body = r_ned_frd.T @ frames.enu_to_ned(v)
        np.testing.assert_allclose(f[7:10], v_body, atol=1e-13)


def test_odometry_message_carries_the_kernel_fields() -> None:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    veh = Vehicle(1, 0, dyn, AutopilotConfig())
    dyn.att[0] = [0.1, -0.2, 0.7]
    dyn.cmd_att[0] = [0.15, -0.1, 0.6]
    dyn.v[0] = [1.0, -2.0, 0.5]
    msg = telemetry.odometry(veh, 1.25)
    assert msg.get_msgId() == M.MAVLINK_MSG_ID_ODOMETRY
    f = frames.odometry_ned(dyn.p[0], dyn.v[0], dyn.att[0])
    assert [msg.x, msg.y, msg.z] == f[:3].tolist()
    assert list(msg.q) == f[3:7].tolist()
    assert [msg.vx, msg.vy, msg.vz] == f[7:10].tolist()
    rate = (dyn.cmd_att[0] - dyn.att[0]) / dyn.tau
    assert [msg.rollspeed, msg.pitchspeed, msg.yawspeed] == [rate[0], -rate[1], -rate[2]]


def test_conversions_take_any_array_type_after_their_first_call() -> None:
    """The conversions call their kernels through module-level sites typed at their first
    call (swarm_common.jit.CallSite), so every later call must reach the kernel as the
    same types: lists, float32 arrays and strided views give what float64 arrays of the
    same values give."""
    rng = np.random.default_rng(5)
    for trial in range(20):
        p, v = rng.normal(0.0, 5.0, 3), rng.normal(0.0, 2.0, 3)
        att = rng.uniform(-0.5, 0.5, 3).astype(np.float32).astype(np.float64)
        q = Rotation.from_euler("xyz", rng.uniform(-1.0, 1.0, 3)).as_quat(scalar_first=True)
        want_odo = frames.odometry_ned(p, v, att)
        want_eul = frames.euler_enu_from_quat_ned(q)
        want_rates = frames.lag_rates_frd(att, att[::-1].copy(), np.array([0.1, 0.1, 0.2]))
        wide = np.zeros((3, 2))
        wide[:, 0] = p  # a strided (3,) view
        assert np.array_equal(frames.odometry_ned(wide[:, 0], list(v), att.astype(np.float32)),
                              want_odo), trial
        assert frames.euler_enu_from_quat_ned(list(q)) == want_eul, trial
        assert frames.lag_rates_frd(list(att), att[::-1].astype(np.float32),
                                    [0.1, 0.1, 0.2]) == want_rates, trial
        rows = np.stack([q, q[::-1]])
        assert np.array_equal(frames.euler_enu_from_quats_ned(rows.astype(np.float32)),
                              frames.euler_enu_from_quats_ned(
                                  rows.astype(np.float32).astype(np.float64))), trial
