"""Compiled physics step of the swarm (:class:`vehicle_sim.physics.dynamics.SwarmDynamics`, issue
11).

:func:`step_kernel` is one physics step of all N vehicles in one compiled loop: the
exact first-order attitude and thrust lags, the thrust acceleration R e3 F / m − g e_z,
the lumped disturbance Φ(p, v) ζ + d(t)/m (:func:`lumped_accel_kernel`), semi-implicit
Euler, ground contact, the spawn fixture (held vehicles), and the pair distances with the
collision bookkeeping. The class around it keeps the state, the commands and the names.

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
def _pair_dist(p: np.ndarray, i: int, j: int) -> float:
    """‖p_i − p_j‖ (m), summed as ``np.add.reduce``: (x² + y²) + z²; every distance of
    this module (the matrix, the contacts, the grid)."""
    dx = p[i, 0] - p[j, 0]
    dy = p[i, 1] - p[j, 1]
    dz = p[i, 2] - p[j, 2]
    return math.sqrt((dx * dx + dy * dy) + dz * dz)


@kernel
def pair_distances_kernel(p: np.ndarray) -> np.ndarray:
    """(N,N) distance matrix ‖p_i − p_j‖ (m) of positions p (N,3) (m)."""
    n = p.shape[0]
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = _pair_dist(p, i, j)
    return out


@kernel
def min_upper_kernel(d: np.ndarray) -> float:
    """Minimum of the strict upper triangle of the (N,N) matrix ``d`` (nan if any is nan;
    +inf for N < 2)."""
    n = d.shape[0]
    m = np.inf
    for i in range(n):
        for j in range(i + 1, n):
            x = d[i, j]
            if x < m or x != x:
                m = x
                if x != x:
                    return m
    return m


# above this many vehicles a step without a distance matrix finds its close pairs on a grid
GRID_MIN = 64
# the grid's cell side: the least nearest-neighbour distance of GRID_SAMPLES vehicles plus
# GRID_SLACK_M (m), at least the collision radius
GRID_SAMPLES = 8
GRID_SLACK_M = 0.25


@kernel
def contacts_into(p: np.ndarray, in_contact: np.ndarray, radius: float, dist_out: np.ndarray,
                  pairs_out: np.ndarray, count: np.ndarray) -> tuple[int, float]:
    """The contacts (distance < ``radius``, m, i ≠ j) of ``p`` (N,3) into ``in_contact``
    (N,N) bool and the minimum pair distance. The pairs entering contact (not in
    ``in_contact`` before) go to the first rows of ``pairs_out`` as (i, j), i < j, in row
    order. Returns their number and the minimum over the pairs i < j (the
    :func:`min_upper_kernel` of the distance matrix: nan if any is nan; +inf for N < 2).
    ``count`` (1,) int64: the pairs in contact before, then after.

    With ``dist_out`` (N,N): one pass over the pairs i < j that also writes
    :func:`pair_distances_kernel` of ``p`` into it, each distance computed once and written
    to both of its cells (the other order's differences are the exact negations, so the
    same bits). With ``dist_out`` of shape (0, 0) and N > :data:`GRID_MIN`:
    :func:`_grid_contacts`, O(N log N), the same contacts, pairs and minimum, bit for bit
    (each pair's distance in the same arithmetic), no matrix."""
    n = p.shape[0]
    if dist_out.shape[0] != n:
        done, n_new, m = _grid_contacts(p, in_contact, radius, pairs_out, count)
        if done:
            return n_new, m
    n_new = 0
    m = np.inf
    full = dist_out.shape[0] == n
    inside = 0
    for i in range(n):
        in_contact[i, i] = False
        if full:
            dist_out[i, i] = _pair_dist(p, i, i)  # 0, or nan
        for j in range(i + 1, n):
            d = _pair_dist(p, i, j)
            c = d < radius
            if c and not in_contact[i, j]:
                pairs_out[n_new, 0] = i
                pairs_out[n_new, 1] = j
                n_new += 1
            if c:
                inside += 1
            in_contact[i, j] = c
            in_contact[j, i] = c
            if full:
                dist_out[i, j] = d
                dist_out[j, i] = d
            if m == m and (d < m or d != d):  # the first nan stays (min_upper_kernel)
                m = d
    count[0] = inside
    return n_new, m


@kernel
def _grid_contacts(p: np.ndarray, in_contact: np.ndarray, radius: float, pairs_out: np.ndarray,
                   count: np.ndarray) -> tuple[bool, int, float]:
    """:func:`contacts_into` without a distance matrix: (done, new pairs, minimum); done
    False (nothing written) where it cannot decide, and the caller passes over every pair.

    The vehicles are sorted into cubic cells of side h = max(radius, near + GRID_SLACK_M),
    ``near`` the least nearest-neighbour distance of GRID_SAMPLES vehicles, at least the
    minimum over all pairs. Every pair closer than h lies in the same or adjacent cells,
    the closest pair and every contact among them, so the minimum over those pairs is the
    minimum over all. Not done for N ≤ GRID_MIN, a coordinate that is not finite, or cells
    too many to number."""
    n = p.shape[0]
    if n <= GRID_MIN:
        return False, 0, np.inf
    lo = np.empty(3)
    hi = np.empty(3)
    for k in range(3):
        lo[k] = np.inf
        hi[k] = -np.inf
    for i in range(n):
        for k in range(3):
            x = p[i, k]
            if not math.isfinite(x):
                return False, 0, np.inf
            lo[k] = min(lo[k], x)
            hi[k] = max(hi[k], x)
    # the cell side: the nearest neighbour of any vehicle bounds the minimum above, so the
    # least of GRID_SAMPLES vehicles' nearest (O(N) each) gives cells that hold the closest
    # pair; the slack keeps a cell from being smaller than the contacts need
    near = np.inf
    for s in range(GRID_SAMPLES):
        i = (s * n) // GRID_SAMPLES
        for j in range(n):
            if j != i:
                near = min(near, _pair_dist(p, i, j))
    h = max(radius, near + GRID_SLACK_M)
    dims = np.empty(3, dtype=np.int64)
    total = 1.0
    for k in range(3):
        dims[k] = int((hi[k] - lo[k]) / h) + 3
        total *= dims[k]
    if total > 4e18:
        return False, 0, np.inf
    keys = np.empty(n, dtype=np.int64)
    cell = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for k in range(3):
            cell[i, k] = int((p[i, k] - lo[k]) / h) + 1
        keys[i] = (cell[i, 0] * dims[1] + cell[i, 1]) * dims[2] + cell[i, 2]
    # the vehicles by cell: a table of each cell's first row when the cells are few (a
    # counting sort), else sorted keys searched by bisection
    dense = total <= 16 * n + 4096
    cells = int(total) + 1 if dense else 1
    start = np.zeros(cells, dtype=np.int64)
    if dense:
        for i in range(n):
            start[keys[i] + 1] += 1
        for q in range(1, cells):
            start[q] += start[q - 1]
        order = np.empty(n, dtype=np.int64)
        fill = start.copy()
        for i in range(n):
            order[fill[keys[i]]] = i
            fill[keys[i]] += 1
        sorted_keys = keys  # not read
    else:
        order = np.argsort(keys, kind="mergesort")
        sorted_keys = keys[order]
    m = np.inf
    cand_i = np.empty(64, dtype=np.int64)
    cand_j = np.empty(64, dtype=np.int64)
    k_c = 0
    for i in range(n):
        for a in range(-1, 2):
            for b in range(-1, 2):
                # the three cells (x + a, y + b, z - 1 .. z + 1) are one run of the rows
                first = ((cell[i, 0] + a) * dims[1] + cell[i, 1] + b) * dims[2] + cell[i, 2] - 1
                if dense:
                    r, end = start[first], start[first + 3]
                else:
                    r = np.searchsorted(sorted_keys, first)
                    end = np.searchsorted(sorted_keys, first + 3)
                while r < end:
                    j = order[r]
                    r += 1
                    if j <= i:
                        continue
                    d = _pair_dist(p, i, j)
                    if d < m:
                        m = d
                    if d < radius:
                        if k_c == cand_i.shape[0]:
                            cand_i = np.concatenate((cand_i, np.empty(k_c, np.int64)))
                            cand_j = np.concatenate((cand_j, np.empty(k_c, np.int64)))
                        cand_i[k_c] = i
                        cand_j[k_c] = j
                        k_c += 1
    if not m < h:
        return False, 0, np.inf
    # the contacts now, in row order (i, then j)
    rank = np.argsort(cand_i[:k_c] * n + cand_j[:k_c], kind="mergesort")
    n_new = 0
    for q in range(k_c):
        i, j = cand_i[rank[q]], cand_j[rank[q]]
        if not in_contact[i, j]:
            pairs_out[n_new, 0] = i
            pairs_out[n_new, 1] = j
            n_new += 1
    if count[0] > 0:  # some pair was in contact: clear every flag (rare)
        for i in range(n):
            for j in range(n):
                in_contact[i, j] = False
    for q in range(k_c):
        i, j = cand_i[q], cand_j[q]
        in_contact[i, j] = True
        in_contact[j, i] = True
    count[0] = k_c
    return True, n_new, m


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
