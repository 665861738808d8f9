"""u → attitude/thrust → wire → acceleration round trip (paper §2.2, §5.5)."""

import math

import numpy as np

from offboard.inner_loop.attitude import InnerLoopModel, accel_from_attitude, setpoint_from_accel
from swarm_common.frames import thrust_accel
from swarm_common.scenario.model import VehicleConfig

VEH = VehicleConfig(
    mass_kg=1.8, gravity_mps2=9.81, thrust_max_n=52.92, tilt_max_deg=30.0,
    tau_rollpitch_s=0.15, tau_yaw_s=0.15, tau_thrust_s=0.03, collision_radius_m=0.3,
)


def test_round_trip_within_limits():
    rng = np.random.default_rng(5)
    for _ in range(200):
        u = rng.uniform([-4, -4, -5], [4, 4, 8])
        yaw = rng.uniform(-3, 3)
        sp = setpoint_from_accel(u, yaw, VEH, decode=True)
        assert sp.q_ned.dtype == np.float32 and abs(np.linalg.norm(sp.q_ned) - 1) < 1e-6
        a = accel_from_attitude(sp.roll, sp.pitch, sp.yaw, sp.thrust_n, 1.8, 9.81)
        a2 = thrust_accel(sp.roll, sp.pitch, sp.yaw, sp.thrust_n, 1.8) - [0, 0, 9.81]
        assert np.allclose(a, a2)
        tilt = math.degrees(math.acos(math.cos(sp.roll) * math.cos(sp.pitch)))
        h = np.hypot(u[0], u[1])
        if h <= (u[2] + 9.81) * math.tan(math.radians(30)) - 1e-6:
            assert np.allclose(a, u, atol=2e-4)  # realisable: exact (float32 wire)
        assert tilt <= 30.0 + 1e-3 and sp.thrust_n <= 52.92 + 1e-6
        assert abs(sp.yaw - yaw) < 1e-5 or abs(abs(sp.yaw - yaw) - 2 * math.pi) < 1e-5


def test_saturation_limits():
    sp = setpoint_from_accel(np.array([50.0, 0.0, 0.0]), 0.0, VEH)
    assert math.degrees(abs(sp.pitch)) <= 30.0 + 1e-6
    sp = setpoint_from_accel(np.array([0.0, 0.0, 100.0]), 0.0, VEH)
    assert sp.thrust_n <= 52.92 + 1e-9


def test_inner_loop_model_converges_to_command():
    m = InnerLoopModel(VEH, 0.005)
    u = np.array([1.0, -0.5, 0.3])
    sp = setpoint_from_accel(u, 0.0, VEH)
    for _ in range(200):
        out = m.run(sp, 4)
    assert np.allclose(out[-1], u, atol=1e-6)


def test_closed_form_quaternion_is_the_rotation_t_r_d():
    """The one ENU/FLU Euler -> NED/FRD conversion (closed form) against the rotation it
    stands for, ``quat(T R(roll, pitch, yaw) D)`` built from matrices here."""
    from swarm_common.frames import (
        D_FRD_FLU,
        T_ENU_NED,
        quat_from_rotm,
        quat_ned_from_euler_enu,
        rotm_from_euler,
    )

    rng = np.random.default_rng(9)
    for _ in range(200):
        r, p, y = rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(-3.1, 3.1)
        ref = quat_from_rotm(T_ENU_NED @ rotm_from_euler(r, p, y) @ D_FRD_FLU)
        ref = ref if ref[0] >= 0 else -ref
        assert np.allclose(quat_ned_from_euler_enu(r, p, y), ref, atol=1e-12)
