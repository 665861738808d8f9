"""Compiled synthetic sensing (:mod:`offboard.estimation.sensing`; paper §3 inputs, Departure 6).

:func:`measure_into` is :meth:`offboard.estimation.sensing.Sensor.measure` without its random draws:
the caller draws the (N,8) standard normals and the N uniforms with its numpy Generator
(same shapes, same order, so a seed gives the same noise) and passes them in; the kernel
computes the relative geometry, the noisy measurements and the validity mask row by row.
With ``noise_draws = "in_range"`` the sensor calls :func:`range_index` then
:func:`measure_in_range_into` instead, which write only the rows in range into outputs kept
between calls; both compute their rows with :func:`_rows_into`.
:func:`hold_kernel` is the bookkeeping of :meth:`offboard.estimation.sensing.DropoutHold.pairs`.

The operations and their order are those of the numpy formulation they replaced, the
three-term dot products included: :func:`dot3` sums them as numpy's ``einsum("ij,ij->i")``
does for rows of three (its two-lane loop: ``(a0 b0 + a2 b2) + a1 b1``). So the results
are numpy's bit for bit (``tests/unit/estimation/test_sensing_kernel.py``; to rounding, should a
numpy sum otherwise), and every process computes the same bits.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel


@kernel
def dot3(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """a·b of two 3-vectors in the order of numpy's einsum: ``(a0 b0 + a2 b2) + a1 b1``."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@kernel
def measure_into(
    p: np.ndarray, v: np.ndarray, i: int, noise: np.ndarray, drop: np.ndarray,
    sb: float, sr: float, sd: float, sdd: float, range_m: float, dropout: float,
    valid: np.ndarray, gm: np.ndarray, gdm: np.ndarray, dm: np.ndarray, ddm: np.ndarray,
    rel_p: np.ndarray, rel_v: np.ndarray,
) -> None:
    """Writes (valid (N,) bool, g (N,3), ġ (N,3), d (N,), ḋ (N,), p_j − p_i (N,3),
    v_j − v_i (N,3)) measured by agent ``i`` into ``valid, gm, gdm, dm, ddm, rel_p,
    rel_v``, every element; the last two from the measured ones, ``g̃ d̃`` (m) and
    ``ġ̃ d̃ + g̃ ḋ̃`` (m/s).

    p, v (N,3) ground-truth ENU positions (m) and velocities (m/s); noise (N,8) standard
    normals (columns 0-2 bearing, 3-5 bearing rate, 6 distance, 7 range rate) and drop (N,)
    uniforms in [0,1), row j agent j's; sb (rad), sr (rad/s),
    sd (m), sdd (m/s) noise standard deviations;
    range_m sensing range (m); dropout per-pair dropout probability.

    Per row j, with r = p_j − p_i, w = v_j − v_i: ``d = ‖r‖`` (1 for j = i), ``g = r/d``
    (row i: (1,0,0)), ``ḋ = gᵀw``, ``ġ = (w − g ḋ)/d`` (module docstring of
    :mod:`offboard.estimation.sensing`); measured ``g̃ = (g + σ_b n)/‖g + σ_b n‖``, ``ġ + σ_r n``,
    ``d + σ_d n``, ``ḋ + σ_ḋ n``; valid iff ``d ≤ range``, ``drop ≥ dropout`` and j ≠ i.
    A row out of range (``d > range``, j ≠ i) is invalid and all zeros: nothing reads an
    invalid row's measurements, and at a thousand agents computing them was most of a
    follower's sensing (its true distance, written too until issue 44, was 8 kB of
    writes per follower and step there).

    The caller allocates the outputs: a kernel that returned seven new arrays would pay
    for boxing each of them in Python (about 0.3 µs apiece), three times the cost of
    ``np.empty``. Rows are not bounds-checked: the caller checks the shapes
    (:meth:`offboard.estimation.sensing.Sensor.measure`).
    """
    _rows_into(p, v, i, _EVERY_AGENT, p.shape[0], False, noise, drop, sb, sr, sd, sdd, range_m,
               dropout, valid, gm, gdm, dm, ddm, rel_p, rel_v)


# :func:`_rows_into`'s index of every agent, row r agent r's (a constant: no array per call)
_EVERY_AGENT = np.zeros(0, dtype=np.int64)


@kernel
def _rows_into(
    p: np.ndarray, v: np.ndarray, i: int, idx: np.ndarray, k: int, own: bool,
    noise: np.ndarray, drop: np.ndarray, sb: float, sr: float, sd: float, sdd: float,
    range_m: float, dropout: float, valid: np.ndarray, gm: np.ndarray, gdm: np.ndarray,
    dm: np.ndarray, ddm: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray,
) -> None:
    """Rows ``j = idx[r]``, r < ``k``, of :func:`measure_into` (its docstring), row j with
    noise row r of ``noise`` (·,8) and dropout draw ``drop[r]``; with ``own``, then agent
    ``i``'s own row with zero noise and a draw of 1. ``idx`` :data:`_EVERY_AGENT` (empty)
    means row r is agent r's. The one computation of a measured row,
    for both :func:`measure_into` and :func:`measure_in_range_into`, written out in the loop:
    a row function inlined into it made numba count references to six output arrays on
    every row (docs/performance.md)."""
    for r in range(k + 1 if own else k):
        if r < k:
            j = idx[r] if idx.shape[0] else r
            n0, n1, n2, n3 = noise[r, 0], noise[r, 1], noise[r, 2], noise[r, 3]
            n4, n5, n6, n7 = noise[r, 4], noise[r, 5], noise[r, 6], noise[r, 7]
            dr = drop[r]
        else:
            j = i
            n0 = n1 = n2 = n3 = n4 = n5 = n6 = n7 = 0.0
            dr = 1.0
        r0, r1, r2 = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
        d = math.sqrt(dot3(r0, r1, r2, r0, r1, r2))
        if j != i and d > range_m:  # out of range: invalid, its row zeros (nobody reads it)
            valid[j] = False
            dm[j] = 0.0
            ddm[j] = 0.0
            for c in range(3):
                gm[j, c] = 0.0
                gdm[j, c] = 0.0
                rel_p[j, c] = 0.0
                rel_v[j, c] = 0.0
            continue
        w0, w1, w2 = v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], v[j, 2] - v[i, 2]
        if j == i:
            d = 1.0
        g0, g1, g2 = r0 / d, r1 / d, r2 / d
        if j == i:
            g0 = 1.0  # placeholder row for itself (marked invalid)
        gd = dot3(g0, g1, g2, w0, w1, w2)
        # bearing noise: isotropic perturbation, renormalised (its along-g part is 2nd order)
        b0 = g0 + n0 * sb
        b1 = g1 + n1 * sb
        b2 = g2 + n2 * sb
        nb = math.sqrt(dot3(b0, b1, b2, b0, b1, b2))
        gm[j, 0] = b0 / nb
        gm[j, 1] = b1 / nb
        gm[j, 2] = b2 / nb
        gdm[j, 0] = (w0 - g0 * gd) / d + n3 * sr
        gdm[j, 1] = (w1 - g1 * gd) / d + n4 * sr
        gdm[j, 2] = (w2 - g2 * gd) / d + n5 * sr
        dm[j] = d + n6 * sd
        ddm[j] = gd + n7 * sdd
        valid[j] = (d <= range_m) and (dr >= dropout) and j != i
        for c in range(3):
            rel_p[j, c] = gm[j, c] * dm[j]
            rel_v[j, c] = gdm[j, c] * dm[j] + gm[j, c] * ddm[j]


@kernel
def range_index(p: np.ndarray, i: int, range_m: float, idx: np.ndarray) -> int:
    """The agents in agent ``i``'s range, for :func:`measure_in_range_into`: writes their
    indices j ≠ i with true distance ≤ ``range_m`` (m) into ``idx`` (≥ N,) in index order
    and returns their count. The distance is :func:`_rows_into`'s, so the two agree on who
    is in range. It reads the truth and writes only the indices: at a thousand agents the
    distances it also wrote were 8 kB per follower and step, read by nobody."""
    n = p.shape[0]
    k = 0
    for j in range(n):
        r0, r1, r2 = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
        d = math.sqrt(dot3(r0, r1, r2, r0, r1, r2))
        if j != i and d <= range_m:
            idx[k] = j
            k += 1
    return k


@kernel
def measure_in_range_into(
    p: np.ndarray, v: np.ndarray, i: int, noise: np.ndarray, drop: np.ndarray,
    idx: np.ndarray, k: int, prev: np.ndarray, n_prev: int,
    sb: float, sr: float, sd: float, sdd: float, range_m: float, dropout: float,
    valid: np.ndarray, gm: np.ndarray, gdm: np.ndarray, dm: np.ndarray, ddm: np.ndarray,
    rel_p: np.ndarray, rel_v: np.ndarray,
) -> int:
    """:func:`measure_into` for ``noise_draws = "in_range"`` into outputs kept between
    calls, at a cost that follows the agents in range, not N: row ``idx[r]`` (the first
    ``k`` of :func:`range_index`) gets noise row r and draw r; the rows in range at the
    call before (``prev[:n_prev]``) are first reset to an out-of-range row's zeros; the own
    row is rewritten. Every other row already holds an out-of-range row's zeros, so the
    outputs equal :func:`measure_into`'s given the in-range rows' draws in their agents'
    rows (zero noise and a draw of 1, never dropped, in the others'), element for element.
    Writes ``idx[:k]`` into ``prev`` and returns k, the next call's ``n_prev``."""
    for r in range(n_prev):
        j = prev[r]
        valid[j] = False
        dm[j] = ddm[j] = 0.0
        for c in range(3):
            gm[j, c] = gdm[j, c] = rel_p[j, c] = rel_v[j, c] = 0.0
    _rows_into(p, v, i, idx, k, True, noise, drop, sb, sr, sd, sdd, range_m, dropout, valid,
               gm, gdm, dm, ddm, rel_p, rel_v)
    for r in range(k):
        prev[r] = idx[r]
    return k


@kernel
def hold_kernel(
    t: float, valid: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray, last_seen: np.ndarray,
    last_rp: np.ndarray, last_rv: np.ndarray, index: int, hold_s: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(sel, rp, rv, n_held) of :meth:`offboard.estimation.sensing.DropoutHold.pairs` (enabled).

    Updates the last sighting of every valid pair in place (last_seen (N,) s, last_rp,
    last_rv (N,3) m, m/s); a pair j ≠ ``index`` not valid at ``t`` (s) but seen within
    ``hold_s`` (s) is held: ``rp_j = rp_last + (t − t_last) rv_last``, ``rv_j = rv_last``.
    sel: indices of the valid or held pairs, ascending; rp, rv: rel_p, rel_v (N,3) with the
    held rows replaced (copies); n_held: how many pairs are held.
    """
    n = valid.shape[0]
    rp = rel_p.copy()
    rv = rel_v.copy()
    keep = np.zeros(n, dtype=np.bool_)
    n_held = 0
    n_sel = 0
    for j in range(n):
        if valid[j]:
            last_seen[j] = t
            for k in range(3):
                last_rp[j, k] = rel_p[j, k]
                last_rv[j, k] = rel_v[j, k]
            keep[j] = True
        elif j != index and t - last_seen[j] <= hold_s:
            age = t - last_seen[j]
            for k in range(3):
                rp[j, k] = last_rp[j, k] + age * last_rv[j, k]
                rv[j, k] = last_rv[j, k]
            keep[j] = True
            n_held += 1
        if keep[j]:
            n_sel += 1
    sel = np.empty(n_sel, dtype=np.int64)
    s = 0
    for j in range(n):
        if keep[j]:
            sel[s] = j
            s += 1
    return sel, rp, rv, n_held


@kernel
def pair_rows(
    sel: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray, dp_out: np.ndarray,
    dv_out: np.ndarray,
) -> None:
    """Δp and Δv of the pairs ``sel`` (M,) (scenario indices, int64) from the (N,3)
    measured p_j − p_i (m) and v_j − v_i (m/s), written into the first M rows of
    ``dp_out`` and ``dv_out`` (≥ M, 3): their negations, Δp = p_i − p_j and
    Δv = v_i − v_j, the safety filters' input (``-rel_p[sel]`` in one call, no new array)."""
    m = sel.shape[0]
    if dp_out.shape[0] < m or dv_out.shape[0] < m:
        raise ValueError("pair_rows: outputs with fewer rows than the pairs")
    for r in range(m):
        j = sel[r]
        if not (0 <= j < rel_p.shape[0] and j < rel_v.shape[0]):
            raise ValueError("pair_rows: an index outside the measurements")
        for c in range(3):
            dp_out[r, c] = -rel_p[j, c]
            dv_out[r, c] = -rel_v[j, c]
