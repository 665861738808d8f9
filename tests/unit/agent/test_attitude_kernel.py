"""The compiled setpoint conversion, inner-loop model and frame conversions
(offboard.inner_loop.attitude_kernel, swarm_common.frames_kernel) against the numpy/Python
formulation they replaced, on random inputs.

Within rounding everywhere (tests/reference/close.py: two implementations may round
differently in the last bits, and an un-jitted kernel runs in Python floats): where the
operations are the same floats in the same order (quaternion of the Euler angles,
R e3 F/m − g e_z, the inner-loop sub-steps, the rotation matrix of a quaternion) they
agree to a few ulp of the trigonometric functions of the C library; elsewhere to rounding
where the old code went through a library whose order is not ours: ``np.linalg.norm``/
``ndarray.dot`` (OpenBLAS, which fuses multiply-adds on CPUs that have them) and CPython's
``math.hypot`` (rounds its own way; the kernel's is the C library's, as ``np.hypot`` is).
A float32 wire quaternion may then differ in its last float32 bit.

The oracles below are the previous implementations, kept verbatim (compacted).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from reference.close import assert_close

from offboard.inner_loop.attitude import (
    InnerLoopModel,
    Setpoint,
    accel_from_attitude,
    setpoint_from_accel,
)
from swarm_common.frames import (
    D_FRD_FLU,
    T_ENU_NED,
    accel_to_attitude,
    euler_enu_from_quat_ned,
    euler_from_rotm,
    quat_ned_from_euler_enu,
    rotm_from_quat,
    thrust_to_norm,
)
from swarm_common.scenario.model import VehicleConfig

VEH = VehicleConfig(
    mass_kg=1.8, gravity_mps2=9.81, thrust_max_n=52.92, tilt_max_deg=30.0,
    tau_rollpitch_s=0.15, tau_yaw_s=0.15, tau_thrust_s=0.03, collision_radius_m=0.3,
)
TOL = {"rtol": 1e-12, "atol": 1e-12}


# --- the previous implementations (oracles) ------------------------------------------------
def rotm_from_quat_py(q: np.ndarray) -> np.ndarray:
    w, x, y, z = (float(c) for c in q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def euler_enu_from_quat_ned_py(q: np.ndarray) -> tuple[float, float, float]:
    qa = np.asarray(q, dtype=float)
    qa = qa / float(np.linalg.norm(qa))
    return euler_from_rotm(T_ENU_NED @ rotm_from_quat_py(qa) @ D_FRD_FLU)


def accel_to_attitude_py(
    u: np.ndarray, yaw: float, gravity: float, mass: float, tilt_max_rad: float,
    thrust_max_n: float, min_vertical_frac: float = 0.1,
) -> tuple[float, float, float, float]:
    a = np.asarray(u, dtype=float) + np.array([0.0, 0.0, gravity])
    az = max(float(a[2]), min_vertical_frac * gravity)
    ah = a[:2].copy()
    h = float(np.hypot(ah[0], ah[1]))
    hmax = az * math.tan(tilt_max_rad)
    if h > hmax:
        ah *= hmax / h
    a = np.array([ah[0], ah[1], az])
    f = mass * float(np.linalg.norm(a))
    if f > thrust_max_n:
        a *= thrust_max_n / f
        f = thrust_max_n
    cy, sy = math.cos(yaw), math.sin(yaw)
    ax = cy * a[0] + sy * a[1]
    ay = -sy * a[0] + cy * a[1]
    return math.atan2(-ay, math.hypot(ax, a[2])), math.atan2(ax, a[2]), yaw, f


def _qmul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, ...]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def quat_ned_fast_py(roll: float, pitch: float, yaw: float) -> np.ndarray:
    s2 = math.sqrt(0.5)
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    q = (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
         cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)
    q = _qmul(_qmul((0.0, s2, s2, 0.0), q), (0.0, 1.0, 0.0, 0.0))
    if q[0] < 0:
        q = (-q[0], -q[1], -q[2], -q[3])
    return np.array(q)


def setpoint_py(u: np.ndarray, yaw: float, veh: VehicleConfig) -> Setpoint:
    f_max = veh.thrust_max_n
    roll, pitch, yaw_c, f = accel_to_attitude_py(
        u, yaw, veh.gravity_mps2, veh.mass_kg, math.radians(veh.tilt_max_deg), f_max)
    q = quat_ned_fast_py(roll, pitch, yaw_c).astype(np.float32)
    return Setpoint(roll, pitch, yaw_c, f, q, np.float32(thrust_to_norm(f, f_max)))


def accel_from_attitude_py(
    roll: float, pitch: float, yaw: float, thrust_n: float, mass: float, g: float
) -> np.ndarray:
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    k = thrust_n / mass
    return np.array(
        [(cy * sp * cr + sy * sr) * k, (sy * sp * cr - cy * sr) * k, cp * cr * k - g])


def inner_run_py(m: InnerLoopModel, sp: Setpoint, n_sub: int) -> np.ndarray:
    lim = m.tilt
    rc = min(lim, max(-lim, sp.roll))
    pc = min(lim, max(-lim, sp.pitch))
    yc = sp.yaw
    fc = min(m.f_max, max(0.0, sp.thrust_n))
    rows = []
    r, p, y = m.att
    f = m.f
    for _ in range(n_sub):
        r = rc + (r - rc) * m.a_rp
        p = pc + (p - pc) * m.a_rp
        y = yc + (y - yc) * m.a_y
        f = fc + (f - fc) * m.a_f
        cr, sr, cp, sp_, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                                   math.cos(y), math.sin(y))
        k = f / m.m
        rows.append(((cy * sp_ * cr + sy * sr) * k, (sy * sp_ * cr - cy * sr) * k,
                     cp * cr * k - m.g))
    m.state = np.array([r, p, y, f])
    return np.array(rows)


# --- the tests --------------------------------------------------------------------------
def _u(rng: np.random.Generator) -> np.ndarray:
    """Commands within and far outside the limits (tilt, thrust, inverted)."""
    return rng.normal(0.0, 1.0, 3) * rng.choice([0.5, 3.0, 30.0], 3)


def test_accel_to_attitude_equals_previous() -> None:
    rng = np.random.default_rng(1)
    for trial in range(3000):
        u, yaw = _u(rng), float(rng.uniform(-4.0, 4.0))
        tilt, frac = float(rng.uniform(0.1, 1.2)), float(rng.choice([0.1, 0.3]))
        got = accel_to_attitude(u, yaw, 9.81, 1.8, tilt, 52.92, frac)
        ref = accel_to_attitude_py(u, yaw, 9.81, 1.8, tilt, 52.92, frac)
        assert np.allclose(got, ref, **TOL), trial
        assert got[2] == ref[2], trial


def test_setpoint_equals_previous() -> None:
    rng = np.random.default_rng(2)
    q_ulp = 0
    for trial in range(3000):
        u, yaw = _u(rng), float(rng.uniform(-4.0, 4.0))
        got, ref = setpoint_from_accel(u, yaw, VEH), setpoint_py(u, yaw, VEH)
        assert np.allclose([got.roll, got.pitch, got.yaw, got.thrust_n],
                           [ref.roll, ref.pitch, ref.yaw, ref.thrust_n], **TOL), trial
        assert got.q_ned.dtype == np.float32 and got.q_ned.shape == (4,)
        assert isinstance(got.thrust_norm, np.float32)
        assert abs(float(got.thrust_norm) - float(ref.thrust_norm)) <= 6e-8, trial
        # the float32 rounding of a quaternion equal to rounding: at most one float32 ulp
        assert np.allclose(got.q_ned, ref.q_ned, rtol=0.0, atol=6e-8), trial
        q_ulp += int(not np.array_equal(got.q_ned, ref.q_ned))
    assert q_ulp < 30  # nearly always the same float32 bits


def test_quaternion_and_realised_accel_equal_previous() -> None:
    rng = np.random.default_rng(3)
    for trial in range(2000):
        r, p, y = rng.uniform(-3.2, 3.2, 3)
        assert_close(quat_ned_from_euler_enu(r, p, y), quat_ned_fast_py(r, p, y), trial)
        f, m, g = rng.uniform(0.0, 60.0), rng.uniform(0.5, 3.0), 9.81
        assert_close(accel_from_attitude(r, p, y, f, m, g),
                     accel_from_attitude_py(r, p, y, f, m, g), trial)


def test_inner_loop_model_equals_previous() -> None:
    rng = np.random.default_rng(4)
    new, old = InnerLoopModel(VEH, 0.005), InnerLoopModel(VEH, 0.005)
    for k in range(500):
        sp = setpoint_from_accel(_u(rng), float(rng.uniform(-3.0, 3.0)), VEH)
        n_sub = int(rng.integers(1, 25))
        got, ref = new.run(sp, n_sub), inner_run_py(old, sp, n_sub)
        assert got.shape == ref.shape == (n_sub, 3), k
        assert_close(got, ref, k)
        assert_close([*new.att, new.f], [*old.att, old.f], k)
        assert all(type(x) is float for x in [*new.att, new.f]), k


@pytest.mark.full
def test_frames_quaternion_conversions_equal_previous() -> None:
    rng = np.random.default_rng(5)
    for trial in range(3000):
        q = rng.normal(0.0, 1.0, 4) * rng.choice([0.0, 1.0], 4, p=[0.2, 0.8])
        if not q.any():
            continue
        qn = q / np.linalg.norm(q)
        assert_close(rotm_from_quat(qn), rotm_from_quat_py(qn), trial)
        for qq in (q, qn, qn.astype(np.float32)):
            got, ref = euler_enu_from_quat_ned(qq), euler_enu_from_quat_ned_py(qq)
            # ±π for a roll/yaw exactly at the cut, equal modulo 2π
            diff = np.angle(np.exp(1j * (np.array(got) - np.array(ref))))
            assert np.allclose(diff, 0.0, rtol=0.0, atol=1e-12), trial


def test_frames_euler_of_the_wire_quaternions() -> None:
    """What the simulator decodes from the float32 wire quaternion (the per-step use)."""
    rng = np.random.default_rng(6)
    for trial in range(2000):
        q = setpoint_from_accel(_u(rng), float(rng.uniform(-3.0, 3.0)), VEH).q_ned
        got, ref = euler_enu_from_quat_ned(q), euler_enu_from_quat_ned_py(q)
        assert np.allclose(got, ref, **TOL), trial


@pytest.mark.full
def test_one_period_command_is_the_separate_calls() -> None:
    """InnerLoopModel.command (one compiled call) against the calls it replaced: the
    setpoint, the clipping check against the realised acceleration (numpy's max, nan
    included), the inner loop's sub-steps and the rows' mean (numpy's reduce), with the
    model's state carried over from period to period in both. Within rounding
    (tests/reference/close.py; the float32 quaternion within one float32 ulp, 6e-8)."""
    from offboard.agent.base import CLIP_TOL

    rng = np.random.default_rng(21)
    for n_sub in (1, 4, 7):
        fused, separate = InnerLoopModel(VEH, 0.005), InnerLoopModel(VEH, 0.005)
        for trial in range(400):
            u = rng.normal(0.0, 6.0, 3)
            if trial % 50 == 7:
                u[trial % 3] = np.nan
            yaw = float(rng.uniform(-3.0, 3.0))
            sp, rows, clipped, mean = fused.command(u, yaw, n_sub, CLIP_TOL)
            sp_ref = setpoint_from_accel(u, yaw, VEH)
            real = accel_from_attitude(sp_ref.roll, sp_ref.pitch, sp_ref.yaw, sp_ref.thrust_n,
                                       VEH.mass_kg, VEH.gravity_mps2)
            rows_ref = separate.run(sp_ref, n_sub)
            if np.isfinite(u).all():
                assert_close([sp.roll, sp.pitch, sp.yaw, sp.thrust_n],
                             [sp_ref.roll, sp_ref.pitch, sp_ref.yaw, sp_ref.thrust_n], trial)
                assert_close(sp.thrust_norm, sp_ref.thrust_norm, trial, atol=6e-8)
                assert_close(fused.att, separate.att, trial)
            assert_close(sp.q_ned, sp_ref.q_ned, trial, atol=6e-8)
            # bool (np.bool_ where the kernel runs un-jitted, NUMBA_DISABLE_JIT=1)
            assert bool(clipped) is bool(np.abs(real - u).max() > CLIP_TOL)
            assert_close(rows, rows_ref, trial)
            assert_close(mean, np.add.reduce(rows_ref, axis=0) / n_sub, trial)
