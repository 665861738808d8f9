"""Compiled conversions of :mod:`swarm_common.frames` (issue 11): the per-step ones.

:mod:`swarm_common.frames` stays the one NED↔ENU conversion boundary: its public functions
call these kernels, and other compiled code (:mod:`offboard.inner_loop.attitude_kernel`) calls them
directly. The conventions are those of :mod:`swarm_common.frames` (ENU/FLU inside, NED/FRD
on the wire, ZYX Euler, quaternions [w, x, y, z]).

The operations and their order are those of the numpy/Python formulation they replaced,
but for: dot products summed left to right (numpy's BLAS dot) and ``math.hypot`` being the
C library's, as ``np.hypot`` is (CPython's ``math.hypot`` rounds its own way, within an
ulp). Results agree to rounding (``tests/unit/agent/test_attitude_kernel.py``), and every
process (controller and simulator) runs the same kernels.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel

_S2 = math.sqrt(0.5)  # the half turn about (1,1,0)/√2 of ENU→NED


@kernel
def py_max(a: float, b: float) -> float:
    """Python's ``max(a, b)`` of two floats (``b`` only if ``b > a``: NaN as in Python)."""
    return b if b > a else a


@kernel
def py_min(a: float, b: float) -> float:
    """Python's ``min(a, b)`` of two floats (``b`` only if ``b < a``: NaN as in Python)."""
    return b if b < a else a


@kernel
def rotm_from_quat_kernel(w: float, x: float, y: float, z: float) -> np.ndarray:
    """Unit quaternion [w, x, y, z] → (3,3) rotation matrix (frames.rotm_from_quat)."""
    r = np.empty((3, 3))
    r[0, 0] = 1 - 2 * (y * y + z * z)
    r[0, 1] = 2 * (x * y - w * z)
    r[0, 2] = 2 * (x * z + w * y)
    r[1, 0] = 2 * (x * y + w * z)
    r[1, 1] = 1 - 2 * (x * x + z * z)
    r[1, 2] = 2 * (y * z - w * x)
    r[2, 0] = 2 * (x * z - w * y)
    r[2, 1] = 2 * (y * z + w * x)
    r[2, 2] = 1 - 2 * (x * x + y * y)
    return r


@kernel
def matmul3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3,3) product ``a @ b``, each entry summed over k = 0, 1, 2."""
    c = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            c[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]
    return c


@kernel
def euler_enu_from_quat_ned_kernel(
    q: np.ndarray, t_enu_ned: np.ndarray, d_frd_flu: np.ndarray
) -> tuple[float, float, float]:
    """NED/FRD quaternion q (4,) [w, x, y, z] → ENU/FLU ZYX Euler (roll, pitch, yaw) (rad).

    q is normalised (q/‖q‖), ``R_enu_flu = T R_ned_frd(q) D`` with t_enu_ned = T and
    d_frd_flu = D of :mod:`swarm_common.frames` (the full products: entries of T and D are
    0 and ±1, so they are exact and give numpy's ``@`` bit for bit, signs of zeros
    included), then frames.euler_from_rotm of R_enu_flu.
    """
    nq = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    r = rotm_from_quat_kernel(q[0] / nq, q[1] / nq, q[2] / nq, q[3] / nq)
    r = matmul3(matmul3(t_enu_ned, r), d_frd_flu)
    pitch = math.asin(py_max(-1.0, py_min(1.0, -r[2, 0])))
    roll = math.atan2(r[2, 1], r[2, 2])
    yaw = math.atan2(r[1, 0], r[0, 0])
    return roll, pitch, yaw


@kernel
def euler_enu_from_quats_ned_kernel(
    q: np.ndarray, t_enu_ned: np.ndarray, d_frd_flu: np.ndarray
) -> np.ndarray:
    """(N,3) [roll, pitch, yaw] (rad) of :func:`euler_enu_from_quat_ned_kernel` for each
    row of q (N,4) [w, x, y, z]."""
    out = np.empty((q.shape[0], 3))
    for i in range(q.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = euler_enu_from_quat_ned_kernel(
            q[i], t_enu_ned, d_frd_flu
        )
    return out


@kernel
def accel_to_attitude_kernel(
    u: np.ndarray, yaw: float, gravity: float, mass: float, tilt_max_rad: float,
    thrust_max_n: float, min_vertical_frac: float,
) -> tuple[float, float, float, float]:
    """Virtual control u (3,) m/s² (paper 2.2: ``u = R[0,0,F]/m − g e_z``) → (roll, pitch,
    yaw (rad), F (N)) within the limits of frames.accel_to_attitude (same order: vertical
    part ≥ min_vertical_frac·g, tilt ≤ tilt_max_rad, F ≤ thrust_max_n)."""
    a0, a1, a2 = u[0] + 0.0, u[1] + 0.0, u[2] + gravity
    az = py_max(a2, min_vertical_frac * gravity)
    h = math.hypot(a0, a1)
    hmax = az * math.tan(tilt_max_rad)
    if h > hmax:
        s = hmax / h
        a0 *= s
        a1 *= s
    a2 = az
    f = mass * math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if f > thrust_max_n:
        s = thrust_max_n / f
        a0 *= s
        a1 *= s
        a2 *= s
        f = thrust_max_n
    cy, sy = math.cos(yaw), math.sin(yaw)
    ax = cy * a0 + sy * a1  # rotate into the yaw frame
    ay = -sy * a0 + cy * a1
    pitch = math.atan2(ax, a2)
    roll = math.atan2(-ay, math.hypot(ax, a2))
    return roll, pitch, yaw, f


@kernel
def rotm_from_euler_kernel(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """ZYX Euler angles (rad) → (3,3) rotation matrix, body to world
    (frames.rotm_from_euler)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    r = np.empty((3, 3))
    r[0, 0], r[0, 1], r[0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    r[1, 0], r[1, 1], r[1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    r[2, 0], r[2, 1], r[2, 2] = -sp, cp * sr, cp * cr
    return r


@kernel
def quat_from_rotm_kernel(m: np.ndarray) -> np.ndarray:
    """(3,3) rotation matrix → unit quaternion (4,) [w, x, y, z] with w ≥ 0
    (frames.quat_from_rotm): the largest of trace, m00, m11, m22 picks the formula, then
    the result is divided by its norm (squares summed w, x, y, z in order)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    q = np.empty(4)
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q[0], q[1] = 0.25 * s, (m[2, 1] - m[1, 2]) / s
        q[2], q[3] = (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q[0], q[1] = (m[2, 1] - m[1, 2]) / s, 0.25 * s
        q[2], q[3] = (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q[0], q[1] = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s
        q[2], q[3] = 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q[0], q[1] = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s
        q[2], q[3] = (m[1, 2] + m[2, 1]) / s, 0.25 * s
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        q[i] /= n
    return with_w_nonnegative(q)


@kernel
def with_w_nonnegative(q: np.ndarray) -> np.ndarray:
    """The quaternion q (4,) [w, x, y, z], negated in place when w < 0 (q and −q are the
    same rotation; MAVLink's convention here is w ≥ 0); returns q."""
    if q[0] < 0:
        for i in range(4):
            q[i] = -q[i]
    return q


@kernel
def quat_ned_from_euler_enu_kernel(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """NED/FRD quaternion (4,) [w, x, y, z], w ≥ 0, of the ENU/FLU ZYX Euler angles (rad).

    ``q_ned = q_T ⊗ q_zyx(roll, pitch, yaw) ⊗ q_D`` with T (ENU→NED) a half turn about
    (1,1,0)/√2 and D (FRD→FLU) a half turn about x: ``quat(T R(roll, pitch, yaw) D)`` in
    closed form, the one ENU→NED attitude conversion (frames.quat_ned_from_euler_enu).
    """
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    bw = cr * cp * cy + sr * sp * sy
    bx = sr * cp * cy - cr * sp * sy
    by = cr * sp * cy + sr * cp * sy
    bz = cr * cp * sy - sr * sp * cy
    # q_T ⊗ b, q_T = (0, s, s, 0): the products of the general ⊗, zero terms included
    aw, ax, ay, az = 0.0, _S2, _S2, 0.0
    tw = aw * bw - ax * bx - ay * by - az * bz
    tx = aw * bx + ax * bw + ay * bz - az * by
    ty = aw * by - ax * bz + ay * bw + az * bx
    tz = aw * bz + ax * by - ay * bx + az * bw
    # (q_T ⊗ b) ⊗ q_D, q_D = (0, 1, 0, 0)
    q = np.empty(4)
    q[0] = tw * 0.0 - tx * 1.0 - ty * 0.0 - tz * 0.0
    q[1] = tw * 1.0 + tx * 0.0 + ty * 0.0 - tz * 0.0
    q[2] = tw * 0.0 - tx * 0.0 + ty * 0.0 + tz * 1.0
    q[3] = tw * 0.0 + tx * 0.0 - ty * 1.0 + tz * 0.0
    return with_w_nonnegative(q)


@kernel
def odometry_ned_kernel(
    p: np.ndarray, v: np.ndarray, att: np.ndarray, t_enu_ned: np.ndarray, d_frd_flu: np.ndarray
) -> np.ndarray:
    """One vehicle's ODOMETRY pose and velocity in MAVLink frames, (10,): NED position
    (m), the NED/FRD quaternion [w, x, y, z] and the body FRD velocity
    ``R_ned_frd(q)ᵀ v_ned`` (m/s, summed over the rows of R in order), from the ENU
    position p (3,) m, velocity v (3,) m/s and attitude att (3,) roll/pitch/yaw (rad)."""
    out = np.empty(10)
    out[0], out[1], out[2] = p[1], p[0], -p[2]
    vn0, vn1, vn2 = v[1], v[0], -v[2]
    q = quat_ned_from_euler_enu_kernel(att[0], att[1], att[2])
    out[3:7] = q
    r = rotm_from_quat_kernel(q[0], q[1], q[2], q[3])
    out[7] = r[0, 0] * vn0 + r[1, 0] * vn1 + r[2, 0] * vn2
    out[8] = r[0, 1] * vn0 + r[1, 1] * vn1 + r[2, 1] * vn2
    out[9] = r[0, 2] * vn0 + r[1, 2] * vn1 + r[2, 2] * vn2
    return out


@kernel
def lag_rates_frd_kernel(
    att: np.ndarray, cmd_att: np.ndarray, tau: np.ndarray
) -> tuple[float, float, float]:
    """Body rates (FRD, rad/s) approximated by the Euler-angle rates of a first-order
    attitude lag, ``(cmd_att − att)/tau`` with y and z negated (FLU → FRD); att, cmd_att
    (3,) roll/pitch/yaw (rad), tau (3,) time constants (s)."""
    r0 = (cmd_att[0] - att[0]) / tau[0]
    r1 = (cmd_att[1] - att[1]) / tau[1]
    r2 = (cmd_att[2] - att[2]) / tau[2]
    return r0, -r1, -r2
