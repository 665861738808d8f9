"""Compiled physics step of the swarm (:class:`vehicle_sim.physics.dynamics.SwarmDynamics`, issue
11).

:func:`step_kernel` is one physics step of all N vehicles in one compiled loop: the
exact first-order attitude and thrust lags, the thrust acceleration R e3 F / m − g e_z,
the lumped disturbance Φ(p, v) ζ + d(t)/m (:func:`lumped_accel_kernel`), semi-implicit
Euler, ground contact, the spawn fixture (held vehicles), and the pair distances with the
collision bookkeeping (:mod:`vehicle_sim.physics.contacts_kernel`). The class around it
keeps the state, the commands and the names.

The operations and their order are those of the numpy formulation it replaced, with
these exceptions, each a last-bit difference at most
(``tests/unit/vehicle_sim/test_dynamics_kernel.py`` steps the previous numpy step side by side):

* ``exp`` is the C library's (numpy's AVX-512 ``exp`` differs from it in the last bit for
  a few percent of arguments); ``sin``/``cos`` agree with numpy's bit for bit;
* cubes are products ``v·v·v`` (numpy's ``v**3`` is its vectorised ``pow``);
* ‖v‖² is summed as numpy's ``einsum("ij,ij->i")`` does on 3-vectors, (x² + z²) + y²
  (its SIMD horizontal sum); the pair distances as ``np.add.reduce``, (x² + y²) + z².

No random numbers here (ζ is drawn by the class); no fastmath (swarm_common.jit): every
process that runs the kernel computes the same bits, so in-process and distributed runs
stay equal. World frame ENU, z up; body FLU; Euler ZYX (rad).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.frames_kernel import py_max, py_min
from swarm_common.jit import kernel
from swarm_common.unmodeled_kernel import unmodeled_accel_kernel
from vehicle_sim.physics.contacts_kernel import contacts_into


@kernel
def thrust_accel_kernel(att: np.ndarray, thrust: np.ndarray, mass: float) -> np.ndarray:
    """(N,3) acceleration from thrust alone, R(φ,θ,ψ) e3 F / m (m/s²).

    att (N,3) roll, pitch, yaw (rad); thrust (N,) F (N); mass m (kg).
    """
    n = att.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        cr, cp, cy = math.cos(att[i, 0]), math.cos(att[i, 1]), math.cos(att[i, 2])
        sr, sp, sy = math.sin(att[i, 0]), math.sin(att[i, 1]), math.sin(att[i, 2])
        k = thrust[i] / mass
        out[i, 0] = (cy * sp * cr + sy * sr) * k
        out[i, 1] = (sy * sp * cr - cy * sr) * k
        out[i, 2] = (cp * cr) * k
    return out


@kernel
def lumped_accel_kernel(
    p: np.ndarray, v: np.ndarray, zeta: np.ndarray, ge_height: float, amp: float,
    mass: float, omega: float, t: float,
) -> np.ndarray:
    """(N,3) lumped disturbance Φ(p, v) ζ + d(t)/m (m/s²).

    p (N,3) position (m), v (N,3) velocity (m/s), zeta (N,6) the true ζ of
    :func:`swarm_common.unmodeled.regressor`'s columns (bias m/s², linear drag 1/s,
    quadratic drag 1/m, cubic damping s/m², ground effect m/s², cross-coupling 1/s);
    ge_height h (m) of exp(−max(z, 0)/h); d(t) = A [cos ωt, sin ωt, sin ωt] with amp A (N),
    omega ω (rad/s), t (s); mass m (kg).
    """
    n = p.shape[0]
    out = np.empty((n, 3))
    wt = omega * t
    dc = amp * math.cos(wt) / mass
    ds = amp * math.sin(wt) / mass
    for i in range(n):
        _lumped_row(p, v, zeta, ge_height, dc, ds, i, out)
    return out


@kernel
def _lumped_row(
    p: np.ndarray, v: np.ndarray, zeta: np.ndarray, ge_height: float, dc: float, ds: float,
    i: int, out: np.ndarray,
) -> None:
    """Row ``i`` of :func:`lumped_accel_kernel` into ``out[i]`` (dc, ds: d(t)/m, m/s²)."""
    fx, fy, fz = unmodeled_accel_kernel(p[i, 2], v[i, 0], v[i, 1], v[i, 2], zeta[i], ge_height)
    out[i, 0] = fx + dc
    out[i, 1] = fy + ds
    out[i, 2] = fz + ds


@kernel
def step_kernel(
    p: np.ndarray, v: np.ndarray, att: np.ndarray, thrust: np.ndarray,
    cmd_att: np.ndarray, cmd_thrust: np.ndarray, held: np.ndarray, zeta: np.ndarray,
    a_att: np.ndarray, a_f: float, mass: float, g: float, dt: float, ge_height: float,
    amp: float, omega: float, t: float, in_contact: np.ndarray, radius: float,
    dist_out: np.ndarray, pairs_out: np.ndarray, count: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, float]:
    """One physics step of ``dt`` (s) from time ``t`` (s) for all N vehicles.

    State in: p (N,3) m, v (N,3) m/s, att (N,3) rad, thrust (N,) N; commands cmd_att (N,3)
    rad (already clamped), cmd_thrust (N,) N; held (N,) bool: the vehicle keeps p, v
    (its attitude and thrust lags still run); zeta (N,6) true ζ; a_att (3,) = exp(−dt/τ)
    per Euler axis, a_f = exp(−dt/τ_F); mass (kg), g (m/s²), ge_height (m), amp (N),
    omega (rad/s) as in :func:`lumped_accel_kernel`; in_contact (N,N) bool, the pairs
    closer than ``radius`` (m) after the previous step.

    Returns new arrays (p, v, att, thrust), the number K of pairs i < j entering contact
    this step and the minimum pair distance (m; :func:`min_upper_kernel` of dist). Written
    in place (no new arrays to box per step): ``in_contact``, the pairs in contact after
    this step, and ``count`` (1,) int64, their number (:func:`contacts_into`);
    ``dist_out`` (N,N), the pair distances (m), or of shape (0, 0) for none (then a large
    swarm's contacts come from a grid, O(N log N)); the first K rows of
    ``pairs_out`` (≥ N(N−1)/2, 2) int64, the pairs entering contact, row by row::

        att' = c + (att − c) a_att,  F' = F_c + (F − F_c) a_f
        v' = v + (R(att') e3 F'/m − g e_z + Φ(p, v) ζ + d(t)/m) dt,  p' = v' dt + p
        z' < 0: z' = 0, v'_z = max(v'_z, 0), v'_x = v'_x·0, v'_y = v'_y·0
    """
    n = p.shape[0]
    att_n = np.empty((n, 3))
    thr_n = np.empty(n)
    for i in range(n):
        for k in range(3):
            c = cmd_att[i, k]
            att_n[i, k] = c + (att[i, k] - c) * a_att[k]
        thr_n[i] = cmd_thrust[i] + (thrust[i] - cmd_thrust[i]) * a_f
    acc = thrust_accel_kernel(att_n, thr_n, mass)
    wt = omega * t
    dc = amp * math.cos(wt) / mass
    ds = amp * math.sin(wt) / mass
    lump = np.empty((n, 3))
    for i in range(n):
        _lumped_row(p, v, zeta, ge_height, dc, ds, i, lump)
    p_n = np.empty((n, 3))
    v_n = np.empty((n, 3))
    for i in range(n):
        acc[i, 2] -= g
        if held[i]:
            for k in range(3):
                v_n[i, k] = v[i, k]
                p_n[i, k] = p[i, k]
            continue
        for k in range(3):
            vk = v[i, k] + (acc[i, k] + lump[i, k]) * dt
            v_n[i, k] = vk
            p_n[i, k] = vk * dt + p[i, k]
        if p_n[i, 2] < 0.0:
            p_n[i, 2] = 0.0
            vz = v_n[i, 2]
            v_n[i, 2] = 0.0 if vz < 0.0 else vz  # np.maximum(vz, 0): nan stays nan
            v_n[i, 0] *= 0.0  # friction: a landed vehicle stops
            v_n[i, 1] *= 0.0
    no_dist = dist_out.shape[0] == 0 and dist_out.shape[1] == 0
    if (in_contact.shape[0] != n or in_contact.shape[1] != n
            or not (no_dist or (dist_out.shape[0] == n and dist_out.shape[1] == n))
            or pairs_out.shape[0] < n * (n - 1) // 2 or pairs_out.shape[1] != 2
            or count.shape[0] != 1):
        raise ValueError("step_kernel: contact, distance or pair buffers of the wrong shape")
    n_new, d_min = contacts_into(p_n, in_contact, radius, dist_out, pairs_out, count)
    return p_n, v_n, att_n, thr_n, n_new, d_min


@kernel
def steps_kernel(
    p: np.ndarray, v: np.ndarray, att: np.ndarray, thrust: np.ndarray,
    cmd_att: np.ndarray, cmd_thrust: np.ndarray, held: np.ndarray, zeta: np.ndarray,
    a_att: np.ndarray, a_f: float, mass: float, g: float, dt: float, ge_height: float,
    amp: float, omega: float, t: float, step_count: int, n_steps: int,
    in_contact: np.ndarray, radius: float, dist_out: np.ndarray, pairs_out: np.ndarray,
    pair_step_out: np.ndarray, count: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, float, float]:
    """``n_steps`` ≥ 1 calls of :func:`step_kernel` in one (the commands held): a control
    period's physics sub-steps with one call from Python and four arrays boxed instead of
    four per sub-step. Sub-step s ≥ 1 starts at ``(step_count + s)·dt`` (s), the time
    :class:`~vehicle_sim.physics.dynamics.SwarmDynamics` gives it after each step; the first at
    ``t``.

    Returns the state after the last sub-step (p, v, att, thrust), the number K of pairs
    entering contact over all sub-steps, the minimum pair distance over the sub-steps (m;
    Python's ``min`` of theirs, in order) and that of the last sub-step. The first K rows
    of ``pairs_out`` (≥ n_steps·N(N−1)/2, 2) hold the pairs and those of
    ``pair_step_out`` (≥ n_steps·N(N−1)/2,) the sub-step (0-based) each entered in;
    ``in_contact``, ``count`` and ``dist_out`` (unless of shape (0, 0)) are those of the
    last sub-step.
    """
    n = p.shape[0]
    per = n * (n - 1) // 2
    if n_steps < 1 or pairs_out.shape[0] < n_steps * per or pair_step_out.shape[0] < n_steps * per:
        raise ValueError("steps_kernel: n_steps < 1 or pair buffers too short")
    md = np.inf
    dmin = np.inf
    k = 0
    for s in range(n_steps):
        ts = t if s == 0 else (step_count + s) * dt
        p, v, att, thrust, n_new, dmin = step_kernel(
            p, v, att, thrust, cmd_att, cmd_thrust, held, zeta, a_att, a_f, mass, g, dt,
            ge_height, amp, omega, ts, in_contact, radius, dist_out, pairs_out[k:], count,
        )
        for r in range(k, k + n_new):
            pair_step_out[r] = s
        k += n_new
        if dmin < md:  # min(md, dmin): a nan never replaces the running minimum
            md = dmin
    return p, v, att, thrust, k, md, dmin


@kernel
def set_command_kernel(
    cmd_att: np.ndarray, cmd_thrust: np.ndarray, i: int, roll: float, pitch: float,
    yaw: float, thrust: float, tilt_max: float, f_max: float,
) -> None:
    """Vehicle i's commanded attitude (rad) and thrust (N) written into cmd_att (N,3) and
    cmd_thrust (N,): ignored if any value is non-finite (the previous command kept); roll
    and pitch clamped to ±tilt_max, thrust to [0, f_max], with Python's min/max
    semantics."""
    if not (math.isfinite(roll) and math.isfinite(pitch) and math.isfinite(yaw)
            and math.isfinite(thrust)):
        return
    cmd_att[i, 0] = py_min(tilt_max, py_max(-tilt_max, roll))
    cmd_att[i, 1] = py_min(tilt_max, py_max(-tilt_max, pitch))
    cmd_att[i, 2] = yaw
    cmd_thrust[i] = py_min(f_max, py_max(0.0, thrust))


@kernel
def set_commands_kernel(
    cmd_att: np.ndarray, cmd_thrust: np.ndarray, roll: np.ndarray, pitch: np.ndarray,
    yaw: np.ndarray, thrust: np.ndarray, tilt_max: float, f_max: float,
) -> None:
    """:func:`set_command_kernel` for every vehicle i at once ((N,) arrays)."""
    for i in range(roll.shape[0]):
        set_command_kernel(cmd_att, cmd_thrust, i, roll[i], pitch[i], yaw[i], thrust[i],
                           tilt_max, f_max)
