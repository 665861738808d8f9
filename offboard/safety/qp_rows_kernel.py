"""Compiled bookkeeping of the safety QPs' data (:class:`offboard.safety.rcbf.clf_rcbf._ClfRowsQP`).

:func:`write_rows_kernel` writes this step's CLF row and safety rows into the QP's
constraint matrix, bounds and linear cost, and DAQP's copy of the problem (the rows in use,
the bounds clamped to ±1e30), in one call instead of a dozen numpy slice assignments per solve;
:func:`rows_finite_kernel` is the QPs' finiteness guard in one call. Both copy and compare
floats only (one division per element of the CLF row, as numpy's), so the QP data are the
same bits as before (``tests/unit/safety/test_qp_rows_kernel.py``).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel


@kernel
def write_rows_kernel(
    a: np.ndarray, lo: np.ndarray, hi: np.ndarray, q: np.ndarray, lgv: np.ndarray,
    lgv_norm: float, clf_rhs: float, g: np.ndarray, rhs: np.ndarray, k: int, m: int,
    u_nom: np.ndarray, a_daqp: np.ndarray, lo_daqp: np.ndarray, hi_daqp: np.ndarray,
    inf_clamp: float,
) -> int:
    """Row 0: the CLF row ``L_gV/‖L_gV‖ u − δ ≤ clf_rhs/‖L_gV‖`` (no row when
    ``lgv_norm`` ≤ 1e-9: zero coefficients, no upper bound); rows 1..k: ``g_j u + σ ≥ r_j``;
    rows k+1..m unused (zero coefficients, no lower bound); ``q[0:3] = −u_nom``. a (rows,5),
    lo, hi, q (5,) are written in place (the columns and rows not named keep their
    values).

    DAQP's copy of the problem leaves the unused rows k+1..m out: the first n rows of
    a_daqp (rows,5), lo_daqp and hi_daqp (rows,) receive rows 0..k and m+1.. of a, lo and
    hi, in their order, the bounds clamped to ±inf_clamp (nan kept); returns n. An unused
    row bounds nothing, yet DAQP works on every row it is given: a problem grown to 256
    rows for a follower that senses twenty cost it about three times as much per solve."""
    if lgv_norm > 1e-9:
        for c in range(3):
            a[0, c] = lgv[c] / lgv_norm
        hi[0] = clf_rhs / lgv_norm
    else:
        for c in range(3):
            a[0, c] = 0.0
        hi[0] = math.inf
    a[0, 3] = -1.0
    for r in range(k):
        for c in range(3):
            a[1 + r, c] = g[r, c]
        lo[1 + r] = rhs[r]
    for r in range(k, m):
        for c in range(3):
            a[1 + r, c] = 0.0
        lo[1 + r] = -math.inf
    for c in range(3):
        q[c] = -u_nom[c]
    n = 0
    for r in range(lo.shape[0]):
        if k < r <= m:
            continue
        for c in range(a.shape[1]):
            a_daqp[n, c] = a[r, c]
        x = lo[r]
        lo_daqp[n] = -inf_clamp if x < -inf_clamp else x
        x = hi[r]
        hi_daqp[n] = inf_clamp if x > inf_clamp else x
        n += 1
    return n


@kernel
def rows_finite_kernel(
    u_nom: np.ndarray, g: np.ndarray, rhs: np.ndarray, k: int, lgv: np.ndarray, lfv: float,
    v: float,
) -> bool:
    """True if u_nom (3,), the first k rows of g (M,3) and rhs (M,), L_gV (3,), L_fV and V
    are all finite."""
    for c in range(3):
        if not (math.isfinite(u_nom[c]) and math.isfinite(lgv[c])):
            return False
    for r in range(k):
        if not math.isfinite(rhs[r]):
            return False
        for c in range(g.shape[1]):
            if not math.isfinite(g[r, c]):
                return False
    return math.isfinite(lfv) and math.isfinite(v)


@kernel
def tight_rows_kernel(
    g: np.ndarray, rhs: np.ndarray, k: int, sigma: float, a_u: np.ndarray, lo_u: np.ndarray,
    hi_u: np.ndarray, u: np.ndarray, tol: float, tight: np.ndarray,
) -> tuple[int, int]:
    """The rows active at a solution (u (3,), relaxation σ), for the record: ``tight[n]``
    (n < the first returned count) the indices r < k of the safety rows ``g_rᵀu + σ ≥ r_r``
    (g (M,3), rhs (M,), m/s²) met within ``tol`` (``g_rᵀu + σ − r_r ≤ tol``, a relaxed
    row too), in order; the second count the input rows ``lo ≤ A_U u ≤ hi`` (a_u (U,3))
    at a bound within ``tol``. Reads only: the solution is not touched."""
    n = 0
    for r in range(k):
        if g[r, 0] * u[0] + g[r, 1] * u[1] + g[r, 2] * u[2] + sigma - rhs[r] <= tol:
            tight[n] = r
            n += 1
    n_in = 0
    for r in range(a_u.shape[0]):
        y = a_u[r, 0] * u[0] + a_u[r, 1] * u[1] + a_u[r, 2] * u[2]
        if y >= hi_u[r] - tol or y <= lo_u[r] + tol:
            n_in += 1
    return n, n_in
