"""Compiled setpoint conversion and inner-loop model (:mod:`offboard.inner_loop.attitude`;
§2.2, §5.1).

* :func:`setpoint_kernel`: virtual control u → (roll, pitch, yaw, F) within the tilt and
  thrust limits (:func:`swarm_common.frames_kernel.accel_to_attitude_kernel`, the kernel
  behind :func:`swarm_common.frames.accel_to_attitude`), the NED/FRD wire quaternion
  rounded to float32
  (:func:`swarm_common.frames_kernel.quat_ned_from_euler_enu_kernel`) and the normalised thrust;
* :func:`accel_from_attitude_kernel`: ``R e3 F/m − g e_z`` (ENU);
* :func:`inner_loop_kernel`: the sub-steps of the first-order attitude/thrust lags;
* :func:`command_kernel`: the three above for one control period of a command, with the
  clipping check and the period's mean realised control (one call per agent step).

The operations and their order are those of the Python formulation they replaced (the
same products and sums of floats), so results agree with it to rounding
(``tests/unit/agent/test_attitude_kernel.py``), and every process computes the same bits.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.frames_kernel import (
    accel_to_attitude_kernel,
    py_max,
    py_min,
    quat_ned_from_euler_enu_kernel,
)
from swarm_common.jit import kernel


@kernel
def setpoint_kernel(
    u: np.ndarray, yaw: float, gravity: float, mass: float, tilt_max_rad: float,
    thrust_max_n: float,
) -> tuple[float, float, float, float, np.ndarray, float]:
    """u (3,) m/s² (ENU) → (roll, pitch, yaw (rad), F (N), q_ned (4,) float32, F/F_max).

    Angles and F of frames.accel_to_attitude (vertical part ≥ 0.1 g, tilt ≤ tilt_max_rad,
    F ≤ thrust_max_n), q_ned the wire quaternion rounded to float32, F/F_max clipped to
    [0, 1] (frames.thrust_to_norm; the caller rounds it to float32).
    """
    roll, pitch, yaw_c, f = accel_to_attitude_kernel(
        u, yaw, gravity, mass, tilt_max_rad, thrust_max_n, 0.1
    )
    q = quat_ned_from_euler_enu_kernel(roll, pitch, yaw_c).astype(np.float32)
    tn = py_min(1.0, py_max(0.0, f / thrust_max_n))
    return roll, pitch, yaw_c, f, q, tn


@kernel
def accel_from_attitude_kernel(
    roll: float, pitch: float, yaw: float, thrust_n: float, mass: float, g: float
) -> np.ndarray:
    """Virtual control (3,) m/s² realised by an attitude (rad) and thrust (N):
    ``R e3 F/m − g e_z`` (ENU, §2.2)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    k = thrust_n / mass
    out = np.empty(3)
    out[0] = (cy * sp * cr + sy * sr) * k
    out[1] = (sy * sp * cr - cy * sr) * k
    out[2] = cp * cr * k - g
    return out


@kernel
def inner_loop_kernel(
    r: float, p: float, y: float, f: float, roll_c: float, pitch_c: float, yc: float,
    thrust_c: float, tilt_max: float, f_max: float, a_rp: float, a_y: float, a_f: float,
    m: float, g: float, n_sub: int,
) -> tuple[np.ndarray, float, float, float, float]:
    """(rows (n_sub,3) m/s², r, p, y (rad), F (N)) after ``n_sub`` sub-steps (§5.1).

    From the attitude (r, p, y) and thrust f towards the command (roll_c, pitch_c, yc,
    thrust_c), roll and pitch clipped to ±tilt_max (rad) and thrust to [0, f_max] (N)
    (Python's min/max semantics), each sub-step exactly: ``x ← x_c + (x − x_c) a`` with
    ``a = exp(−dt_sub/τ)`` (a_rp roll and pitch, a_y yaw, a_f thrust); row s is
    ``R e3 F/m − g e_z`` (mass m kg, gravity g m/s²) at the end of sub-step s.
    """
    rc = py_min(tilt_max, py_max(-tilt_max, roll_c))
    pc = py_min(tilt_max, py_max(-tilt_max, pitch_c))
    fc = py_min(f_max, py_max(0.0, thrust_c))
    rows = np.empty((n_sub, 3))
    for s in range(n_sub):
        r = rc + (r - rc) * a_rp
        p = pc + (p - pc) * a_rp
        y = yc + (y - yc) * a_y
        f = fc + (f - fc) * a_f
        cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                                  math.cos(y), math.sin(y))
        k = f / m
        rows[s, 0] = (cy * sp * cr + sy * sr) * k
        rows[s, 1] = (sy * sp * cr - cy * sr) * k
        rows[s, 2] = cp * cr * k - g
    return rows, r, p, y, f


@kernel
def command_kernel(
    u: np.ndarray, yaw: float, gravity: float, mass: float, tilt_max_rad: float,
    thrust_max_n: float, att: np.ndarray, a_rp: float, a_y: float, a_f: float,
    clip_tol: float, rows_out: np.ndarray, mean_out: np.ndarray, q_out: np.ndarray,
) -> tuple[float, float, float, float, float, bool]:
    """One control period of a command u (3,) m/s² (ENU) in one call:
    (roll, pitch, yaw (rad), F (N), F/F_max) of :func:`setpoint_kernel`, its q_ned written
    into ``q_out`` (4,) float32 (the caller's new array: none to box), and whether the
    setpoint realises an acceleration farther than ``clip_tol`` (m/s²) from u on some axis
    (False if that is nan, as numpy's max gives it). Written in place:
    ``rows_out`` (n_sub,3) m/s², the rows of :func:`inner_loop_kernel` from the inner
    loop's state ``att`` (4,) [roll, pitch, yaw (rad), F (N)] towards that setpoint
    (clipped there to the tilt and thrust limits); ``att``, the new state; ``mean_out``
    (3,), the rows' mean (m/s², summed row after row, as numpy's reduce over the first
    axis does). The same kernels and operations as the separate calls, so the same bits;
    the outputs are written in place so that a step boxes no new arrays for them."""
    n_sub = rows_out.shape[0]
    if (n_sub < 1 or rows_out.shape[1] != 3 or att.shape[0] != 4 or mean_out.shape[0] != 3
            or q_out.shape[0] != 4):
        raise ValueError("command_kernel: outputs of the wrong shape")
    roll, pitch, yaw_c, f, q, tn = setpoint_kernel(
        u, yaw, gravity, mass, tilt_max_rad, thrust_max_n
    )
    for k in range(4):
        q_out[k] = q[k]
    real = accel_from_attitude_kernel(roll, pitch, yaw_c, f, mass, gravity)
    worst, nan = 0.0, False
    for k in range(3):
        dk = abs(real[k] - u[k])
        if math.isnan(dk):
            nan = True
        elif dk > worst:
            worst = dk
    clipped = not nan and worst > clip_tol
    rows, r, p, y, f_new = inner_loop_kernel(
        att[0], att[1], att[2], att[3], roll, pitch, yaw_c, f, tilt_max_rad, thrust_max_n,
        a_rp, a_y, a_f, mass, gravity, n_sub,
    )
    att[0], att[1], att[2], att[3] = r, p, y, f_new
    for s in range(n_sub):
        for k in range(3):
            rows_out[s, k] = rows[s, k]
    for k in range(3):
        mean_out[k] = rows[0, k]
    for s in range(1, n_sub):
        for k in range(3):
            mean_out[k] = mean_out[k] + rows[s, k]
    for k in range(3):
        mean_out[k] = mean_out[k] / n_sub
    return roll, pitch, yaw_c, f, tn, clipped
