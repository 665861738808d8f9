"""Frames, quaternions and the thrust/attitude mapping: the one conversion boundary.

Inside the control math and the dynamics everything is the paper's world frame:
ENU-style, z up, body FLU (x forward, y left, z up), Euler ZYX ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
On the MAVLink wire everything is NED / FRD, quaternions ``[w, x, y, z]``.
Only this module converts between the two (see docs/conventions.md).

    v_ned = T v_enu,   T = [[0,1,0],[1,0,0],[0,0,-1]]
    R_ned_frd = T R_enu_flu D,   D = diag(1, -1, -1)   (FRD -> FLU)

Thrust on the wire is normalised: ``thrust_norm = F / F_max`` (linear), so hover is
``m g / F_max`` (= 0.3337 for the 1.8 kg, 52.92 N vehicle of the paper).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.fastnp import f64, vec3
from swarm_common.frames_kernel import (
    accel_to_attitude_kernel,
    euler_enu_from_quat_ned_kernel,
    euler_enu_from_quats_ned_kernel,
    lag_rates_frd_kernel,
    odometry_ned_kernel,
    quat_from_rotm_kernel,
    quat_ned_from_euler_enu_kernel,
    rotm_from_euler_kernel,
    rotm_from_quat_kernel,
)
from swarm_common.jit import CallSite

T_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
D_FRD_FLU = np.diag([1.0, -1.0, -1.0])
# the conversions' call sites (swarm_common.jit.CallSite): their functions pass floats,
# float64 C-order arrays (through ascontiguousarray or fastnp.vec3) and the two
# constants above, whatever the caller passed
_ROTM = CallSite(rotm_from_euler_kernel)
_QUAT_NED = CallSite(quat_ned_from_euler_enu_kernel)
_ODOMETRY = CallSite(odometry_ned_kernel)
_LAG_RATES = CallSite(lag_rates_frd_kernel)
_EULER = CallSite(euler_enu_from_quat_ned_kernel)
_EULERS = CallSite(euler_enu_from_quats_ned_kernel)
_TO_ATTITUDE = CallSite(accel_to_attitude_kernel)
_SWAP_XY = np.array([1, 0, 2])


def enu_to_ned(v: np.ndarray) -> np.ndarray:
    """Vector(s) (..., 3) from ENU to NED (the map is its own inverse)."""
    out = np.asarray(v, dtype=float)[..., _SWAP_XY]  # a copy: (y, x, z)
    np.negative(out[..., 2], out=out[..., 2])  # the same -z as a negation, not a stack
    return out


def ned_to_enu(v: np.ndarray) -> np.ndarray:
    """Vector(s) (..., 3) from NED to ENU."""
    return enu_to_ned(v)


def rotm_from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """ZYX Euler angles -> rotation matrix (body to world; compiled:
    :func:`~swarm_common.frames_kernel.rotm_from_euler_kernel`)."""
    return _ROTM.call(float(roll), float(pitch), float(yaw))


def euler_from_rotm(r: np.ndarray) -> tuple[float, float, float]:
    """Rotation matrix -> ZYX Euler (roll, pitch, yaw)."""
    pitch = math.asin(max(-1.0, min(1.0, -float(r[2, 0]))))
    roll = math.atan2(float(r[2, 1]), float(r[2, 2]))
    yaw = math.atan2(float(r[1, 0]), float(r[0, 0]))
    return roll, pitch, yaw


def quat_from_rotm(r: np.ndarray) -> np.ndarray:
    """Rotation matrix -> unit quaternion [w, x, y, z] with w >= 0 (compiled:
    :func:`~swarm_common.frames_kernel.quat_from_rotm_kernel`)."""
    m = f64(r)
    if m.shape != (3, 3):
        raise ValueError(f"rotation matrix of shape {m.shape}, not (3, 3)")
    return quat_from_rotm_kernel(m)


def rotm_from_quat(q: np.ndarray) -> np.ndarray:
    """Unit quaternion [w, x, y, z] -> rotation matrix (compiled: frames_kernel)."""
    w, x, y, z = (float(c) for c in q)
    return rotm_from_quat_kernel(w, x, y, z)


def quat_ned_from_euler_enu(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """ENU/FLU Euler attitude -> NED/FRD quaternion [w, x, y, z] (what MAVLink carries):
    ``quat(T R D)``, w ≥ 0, in closed form (compiled:
    ``frames_kernel.quat_ned_from_euler_enu_kernel``; the controller's setpoints and the
    simulator's telemetry both use it)."""
    return _QUAT_NED.call(float(roll), float(pitch), float(yaw))


def odometry_ned(p: np.ndarray, v: np.ndarray, att: np.ndarray) -> np.ndarray:
    """(10,) ODOMETRY pose and velocity of one vehicle from its ENU state (3,) each:
    NED position (m), NED/FRD quaternion [w, x, y, z] and body FRD velocity (m/s)
    (compiled: :func:`~swarm_common.frames_kernel.odometry_ned_kernel`)."""
    return _ODOMETRY.call(vec3(p), vec3(v), vec3(att), T_ENU_NED, D_FRD_FLU)


def lag_rates_frd(
    att: np.ndarray, cmd_att: np.ndarray, tau: np.ndarray
) -> tuple[float, float, float]:
    """FRD body rates (rad/s) of a first-order attitude lag from the ENU/FLU attitude
    ``att`` to ``cmd_att`` (roll, pitch, yaw; rad) with time constants ``tau`` (s): the
    Euler-angle rates ``(cmd_att − att)/tau``, y and z negated (compiled:
    :func:`~swarm_common.frames_kernel.lag_rates_frd_kernel`)."""
    return _LAG_RATES.call(vec3(att), vec3(cmd_att), vec3(tau))


def euler_enu_from_quat_ned(q: np.ndarray) -> tuple[float, float, float]:
    """NED/FRD quaternion [w, x, y, z] -> ENU/FLU Euler (roll, pitch, yaw).

    Normalised, ``R_enu = T_ENU_NED R(q) D_FRD_FLU``, then :func:`euler_from_rotm`
    (compiled: :func:`swarm_common.frames_kernel.euler_enu_from_quat_ned_kernel`).
    """
    qa = f64(q)
    if qa.shape != (4,):
        raise ValueError(f"quaternion of shape {qa.shape}, not (4,)")
    return _EULER.call(qa, T_ENU_NED, D_FRD_FLU)


def euler_enu_from_quats_ned(q: np.ndarray) -> np.ndarray:
    """(N,3) [roll, pitch, yaw] of :func:`euler_enu_from_quat_ned` for each row of the
    (N,4) quaternions ``q`` (one compiled call; the same bits row by row)."""
    qa = f64(q)
    if qa.ndim != 2 or qa.shape[1] != 4:
        raise ValueError(f"quaternions of shape {qa.shape}, not (N, 4)")
    return _EULERS.call(qa, T_ENU_NED, D_FRD_FLU)


def valid_quaternion(q: np.ndarray, tol: float = 0.05) -> bool:
    """Finite and within ``tol`` of unit norm (MAVLink setpoints are rejected otherwise).

    Pure Python on purpose: it runs for every setpoint received, and numpy's per-call
    overhead on a 4-vector was the simulator's largest single cost in a profile.
    """
    try:
        w, x, y, z = (float(c) for c in q)
    except (TypeError, ValueError):
        return False
    if not all(math.isfinite(c) for c in (w, x, y, z)):
        return False
    return abs(math.sqrt(w * w + x * x + y * y + z * z) - 1.0) < tol


def accel_to_attitude(
    u: np.ndarray,
    yaw: float,
    gravity: float,
    mass: float,
    tilt_max_rad: float,
    thrust_max_n: float,
    min_vertical_frac: float = 0.1,
) -> tuple[float, float, float, float]:
    """Virtual control u (paper 2.2: ``u = R[0,0,F]/m - g e_z``) -> (roll, pitch, yaw, F).

    Limits, in order: the thrust's vertical part is at least ``min_vertical_frac * g``
    (no inverted flight); the tilt is at most ``tilt_max_rad`` (horizontal part scaled,
    vertical part kept); ``F <= thrust_max_n`` (the whole vector scaled).
    The compiled :func:`swarm_common.frames_kernel.accel_to_attitude_kernel`.
    """
    ua = f64(u)
    if ua.shape != (3,):
        raise ValueError(f"virtual control of shape {ua.shape}, not (3,)")
    return _TO_ATTITUDE.call(
        ua, float(yaw), float(gravity), float(mass),
        float(tilt_max_rad), float(thrust_max_n), float(min_vertical_frac),
    )


def thrust_accel(roll: float, pitch: float, yaw: float, thrust_n: float, mass: float) -> np.ndarray:
    """Acceleration produced by thrust alone: ``R e3 F / m`` (ENU)."""
    return rotm_from_euler(roll, pitch, yaw)[:, 2] * (thrust_n / mass)


def thrust_to_norm(thrust_n: float, thrust_max_n: float) -> float:
    """Newtons -> MAVLink normalised thrust in [0, 1] (linear map)."""
    return min(1.0, max(0.0, thrust_n / thrust_max_n))


def norm_to_thrust(thrust_norm: float, thrust_max_n: float) -> float:
    """MAVLink normalised thrust in [0, 1] -> newtons."""
    return float(thrust_norm) * thrust_max_n
