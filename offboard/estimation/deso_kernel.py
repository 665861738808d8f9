"""Compiled DESO period (paper §3; Departures 5–8; docs/estimation.md; issue 11).

:func:`deso_step_kernel` is one period of :meth:`offboard.estimation.deso.DESO.update` with relative
information: the data sums b1, ḃ1 over the neighbours used, the innovations e1, e2 of
Departure 6, the convergence gate, one step of the adaptive law and the exact affine map
``X⁺ = A_S X + G (u + f̂)`` of the period. :func:`coast_kernel` is the dead-reckoned period
(:meth:`~offboard.estimation.deso.DESO.coast`), :func:`model_accel_kernel`,
:func:`observer_regressor_t_times` and :func:`adapt_step_kernel` the adaptive model of
:mod:`offboard.estimation.deso_adaptive`. The matrices A_S, G, D and the weights W_ij stay numpy
(matrix exponential, cached per neighbour set in the class); these kernels take them as
contiguous float64 arrays.

The operations and their order are those of the numpy formulation they replaced, but for
two: powers are products (``v**3``, ``v**6`` were C ``pow``), and the matrix-vector products
and dot products are summed left to right (numpy's ``@``, ``einsum`` and ``dot`` went to
BLAS / its own loops). The results agree with that formulation to rounding
(``tests/unit/estimation/test_deso_kernel.py`` keeps it as the oracle), and every process that runs
the kernels computes the same bits (in-process and distributed runs stay equal).

The limits of the adaptive law and of the gate are defined here, not imported: a compiled
kernel freezes the globals it reads, and numba's cache is keyed by this file only, so a
limit changed elsewhere would not reach a cached kernel. :mod:`offboard.estimation.deso_adaptive`
and
:mod:`offboard.estimation.deso` re-export them.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel
from swarm_common.unmodeled_kernel import regressor_t_times_kernel, unmodeled_accel_kernel

# Adaptive law (docs/estimation.md): ζ̂ stays in a box of physically meaningful values
# (bias, drag ≥ 0, cubic damping ≥ 0, ground effect ≥ 0, cross-coupling), m/s² per unit
ZETA_LO = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, -1.0])
ZETA_HI = np.array([1.0, 1.0, 0.5, 0.1, 2.0, 1.0])
V_EVAL_MAX = 10.0  # m/s, speed at which Φ is evaluated (norm saturated; physical max speed)
F_HAT_MAX = 3.0  # m/s², ‖f̂‖ = ‖Φζ̂‖ used inside the observer model is saturated to this
GATE_E1 = 0.3  # m, adaptation runs only while ‖e1‖ ≤ GATE_E1 ...
GATE_E2 = 1.0  # m/s, ... and ‖e2‖ ≤ GATE_E2 ...
GATE_HOLD_S = 1.0  # s, ... have held continuously this long (the observer has converged)


# neighbours a usage mask can hold (:func:`used_mask`); a DESO with more takes the Python way
MASK_NEIGHBOURS = 62


@kernel
def used_mask(nbrs: np.ndarray, valid: np.ndarray, have: np.ndarray) -> int:
    """Bit r set where neighbour ``nbrs[r]`` (scenario index; at most
    :data:`MASK_NEIGHBOURS` of them) has a valid measurement and a usable estimate
    (``valid``, ``have`` (N,) bool): the neighbour set of a DESO update as one integer, a
    cache key that needs no tuple built in Python. Raises ValueError for an index outside
    either mask."""
    m = 0
    for r in range(nbrs.shape[0]):
        j = nbrs[r]
        if not (0 <= j < valid.shape[0] and j < have.shape[0]):
            raise ValueError("used_mask: a neighbour outside the masks")
        if valid[j] and have[j]:
            m |= 1 << r
    return m


@kernel
def _v_eval(z2: np.ndarray) -> tuple[float, float, float]:
    """Velocity at which Φ is evaluated: ``z2`` with its norm saturated to V_EVAL_MAX (m/s);
    zero if the norm is not finite."""
    vx, vy, vz = z2[0], z2[1], z2[2]
    nv = math.sqrt(vx * vx + vy * vy + vz * vz)
    if not math.isfinite(nv):
        return 0.0, 0.0, 0.0
    if nv > V_EVAL_MAX:
        s = V_EVAL_MAX / nv
        return vx * s, vy * s, vz * s
    return vx, vy, vz


@kernel
def model_accel_kernel(z1: np.ndarray, z2: np.ndarray, zeta: np.ndarray, h: float) -> np.ndarray:
    """f̂ = Φ(z1, z2) ζ̂ (3,) m/s² (:func:`swarm_common.unmodeled_kernel.unmodeled_accel_kernel`),
    ‖v‖ saturated to V_EVAL_MAX and ‖f̂‖ to F_HAT_MAX (paper §2.2; z1 m, z2 m/s, h
    ground-effect height m)."""
    vx, vy, vz = _v_eval(z2)
    fx, fy, fz = unmodeled_accel_kernel(z1[2], vx, vy, vz, zeta, h)
    nf = math.sqrt(fx * fx + fy * fy + fz * fz)
    if nf > F_HAT_MAX:
        s = F_HAT_MAX / nf
        fx, fy, fz = fx * s, fy * s, fz * s
    out = np.empty(3)
    out[0], out[1], out[2] = fx, fy, fz
    return out


@kernel
def observer_regressor_t_times(
    z1: np.ndarray, z2: np.ndarray, e: np.ndarray, h: float
) -> tuple[np.ndarray, float]:
    """(Φᵀ e (6,), ‖Φ‖_F²) at (z1, z2) with ‖v‖ saturated as in :func:`model_accel_kernel`
    (:func:`swarm_common.unmodeled_kernel.regressor_t_times_kernel`; e m/s for the e2 of the
    adaptive law, paper §3)."""
    vx, vy, vz = _v_eval(z2)
    return regressor_t_times_kernel(z1[2], vx, vy, vz, e, h)


@kernel
def adapt_step_kernel(
    zeta: np.ndarray, phte: np.ndarray, fro2: float, mu: float, sigma: float, dt: float
) -> np.ndarray:
    """One period of the adaptive law (paper §3, Departures 5 and 8)::

        ζ̂⁺ = Π_box( ζ̂ − dt μ [ Φᵀe2 / (1 + ‖Φ‖_F²) + σ ζ̂ ] )

    projected per component onto [ZETA_LO, ZETA_HI]; a copy of ζ̂ unchanged if the step is
    not finite (mu 1/s-scale gain, sigma σ-modification, dt s).
    """
    n = zeta.shape[0]
    step = np.empty(n)
    for i in range(n):
        step[i] = phte[i] / (1.0 + fro2) + sigma * zeta[i]
        if not math.isfinite(step[i]):
            return zeta.copy()
    c = dt * mu
    out = np.empty(n)
    for i in range(n):
        out[i] = min(max(zeta[i] - c * step[i], ZETA_LO[i]), ZETA_HI[i])
    return out


@kernel
def lumped_into(
    z1: np.ndarray, z2: np.ndarray, zeta: np.ndarray, h: float, z3: np.ndarray,
    out: np.ndarray,
) -> None:
    """The lumped-disturbance estimate of :meth:`offboard.estimation.deso.DESO.lumped` into ``out``
    (2,3), the caller's new array (none to box): row 0 f̂ = :func:`model_accel_kernel`
    (m/s²), row 1 ``z3 + f̂`` (m/s², the same additions as numpy's)."""
    f = model_accel_kernel(z1, z2, zeta, h)
    for k in range(3):
        out[0, k] = f[k]
        out[1, k] = z3[k] + f[k]


@kernel
def coast_kernel(
    z1: np.ndarray, z2: np.ndarray, z3: np.ndarray, zeta: np.ndarray, u_sub: np.ndarray,
    h: float, delta: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(z1, z2) dead-reckoned over the period's sub-steps with the model, z3 and ζ̂ held::

        a = z3 + f̂(z1, z2) + u_s,  z1 ← z1 + δ z2 + ½δ² a,  z2 ← z2 + δ a

    (u_sub (S,3) m/s², δ the sub-step s; :meth:`offboard.estimation.deso.DESO.coast`).
    """
    p = z1.copy()
    v = z2.copy()
    half_dd = 0.5 * (delta * delta)
    acc = np.empty(3)
    for s in range(u_sub.shape[0]):
        f = model_accel_kernel(p, v, zeta, h)
        for k in range(3):
            acc[k] = z3[k] + f[k] + u_sub[s, k]
        for k in range(3):
            p[k] = p[k] + delta * v[k] + half_dd * acc[k]
            v[k] = v[k] + delta * acc[k]
    return p, v


# Layout of the array deso_step_kernel returns (the new state and the innovations)
OUT_Z1 = slice(0, 3)  # z1 (m)
OUT_Z2 = slice(3, 6)  # z2 (m/s)
OUT_Z3 = slice(6, 9)  # z3 (m/s²)
OUT_E1 = slice(9, 12)  # e1 (m)
OUT_E2 = slice(12, 15)  # e2 (m/s)
OUT_ZETA = slice(15, 21)  # ζ̂ (6,)
OUT_CONVERGED = 21  # the gate's timer (s)
OUT_LEN = 22


@kernel
def deso_step_kernel(
    a_s: np.ndarray, g: np.ndarray, dmat: np.ndarray, pu: np.ndarray, idx: np.ndarray,
    peer_rows: np.ndarray, rel_pos: np.ndarray, rel_vel: np.ndarray,
    z1: np.ndarray, z2: np.ndarray, z3: np.ndarray, zeta: np.ndarray, u_sub: np.ndarray,
    f_hat: np.ndarray, h: float, mu: float, sigma: float, dt: float, converged_s: float,
    out: np.ndarray,
) -> None:
    """One DESO period with relative information, written into ``out`` (OUT_LEN,) (the
    caller's new array: none to box): [z1, z2, z3, e1, e2, ζ̂, converged_s] after it
    (slices ``OUT_*``).

    a_s (15,15), g (15,3S) the period map of the neighbour set and dmat D = Σ_j W_ij (3,3);
    pu (k,3,3) the W_ij of the k neighbours used, idx (k,) their scenario indices (int64);
    peer_rows (N,≥6) the agents' estimates by scenario index, ẑ_j1 (m) in columns 0–2 and
    ẑ_j2 (m/s) in 3–5 (:mod:`offboard.estimation.peer_table`'s rows); rel_pos, rel_vel
    (N,3) measured r_ij = p_j − p_i (m), ṙ_ij (m/s); z1, z2, z3 (3,) and ζ̂ (6,) the state
    at t_k; u_sub (S,3) the virtual control per sub-step and f̂ (3,) = Φ(z1,z2)ζ̂ held over
    the period (m/s²); h ground-effect height (m); μ, σ the adaptive gains; dt the period
    (s); converged_s the gate's timer (s). Departure 6::

        b1 = Σ_j W_ij (ẑ_j1 − r_ij),  ḃ1 = Σ_j W_ij (ẑ_j2 − ṙ_ij)
        e1 = D z1 − b1,               e2 = D z2 − ḃ1

    With μ > 0 the gate advances (‖e1‖ ≤ GATE_E1 and ‖e2‖ ≤ GATE_E2 held for GATE_HOLD_S)
    and, open, ζ̂ takes one step of the adaptive law (:func:`adapt_step_kernel`); with μ = 0
    the timer is left as it is. Then ``X⁺ = A_S X + G (u_s + f̂)_s`` with
    X = [z1, z2, z3, b1, ḃ1] (its first 9 rows: the b1 rows of X⁺ are not used).
    """
    n_sub = u_sub.shape[0]
    if g.shape[1] != 3 * n_sub or peer_rows.shape[1] < 6 or out.shape[0] != OUT_LEN:
        raise ValueError("deso_step_kernel: u_sub rows != sub-steps of G, rows too short, "
                         "or out not of OUT_LEN")
    for k in range(idx.shape[0]):
        if not (0 <= idx[k] < peer_rows.shape[0] and idx[k] < rel_pos.shape[0]
                and idx[k] < rel_vel.shape[0]):
            raise ValueError("deso_step_kernel: a neighbour index outside the rows")
    x = np.empty(15)
    for i in range(3):
        x[i] = z1[i]
        x[3 + i] = z2[i]
        x[6 + i] = z3[i]
        b1 = 0.0
        b1d = 0.0
        for k in range(idx.shape[0]):
            j = idx[k]
            for c in range(3):
                w = pu[k, i, c]
                b1 += w * (peer_rows[j, c] - rel_pos[j, c])
                b1d += w * (peer_rows[j, 3 + c] - rel_vel[j, c])
        x[9 + i] = b1
        x[12 + i] = b1d
        d1 = dmat[i, 0] * z1[0] + dmat[i, 1] * z1[1] + dmat[i, 2] * z1[2]
        d2 = dmat[i, 0] * z2[0] + dmat[i, 1] * z2[1] + dmat[i, 2] * z2[2]
        out[9 + i] = d1 - b1  # e1
        out[12 + i] = d2 - b1d  # e2
    e1, e2 = out[9:12], out[12:15]
    new_zeta = zeta
    if mu > 0.0:
        n1 = math.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
        n2 = math.sqrt(e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2])
        if n1 <= GATE_E1 and n2 <= GATE_E2:
            converged_s += dt
        else:
            converged_s = 0.0
        if converged_s >= GATE_HOLD_S - 1e-9:
            phte, fro2 = observer_regressor_t_times(z1, z2, e2, h)
            new_zeta = adapt_step_kernel(zeta, phte, fro2, mu, sigma, dt)
    for i in range(6):
        out[15 + i] = new_zeta[i]
    out[OUT_CONVERGED] = converged_s
    w_in = np.empty(3 * n_sub)
    for s in range(n_sub):
        for i in range(3):
            w_in[3 * s + i] = u_sub[s, i] + f_hat[i]
    for r in range(9):
        ax = 0.0
        for c in range(15):
            ax += a_s[r, c] * x[c]
        gw = 0.0
        for c in range(3 * n_sub):
            gw += g[r, c] * w_in[c]
        out[r] = ax + gw
