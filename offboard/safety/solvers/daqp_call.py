"""DAQP's solve for the safety QPs (issue 11): the solver adapter beside
:mod:`offboard.safety.solvers.osqp_call`, one per solver (``[controller] qp_solver``).

DAQP (Arnström, Bemporad, Axehill) is a dual active-set method for small dense strictly
convex QPs: it starts from the unconstrained minimiser and adds violated rows (removing
rows whose multipliers change sign) until every row holds, so its answer is the QP's
optimum on the final active set, exact to rounding, after a handful of iterations. On the
safety QPs (5 variables, tens of rows) it takes 5–14 iterations and ≈ 5 µs per solve,
where OSQP's ADMM takes 200–500 iterations and ≈ 100–250 µs (docs/performance.md)."""

from __future__ import annotations

import daqp
import numpy as np

from swarm_common.fastnp import finite

DAQP_INF = 1e30  # DAQP reads a bound at or beyond ±1e30 as absent
DAQP_OPTIMAL = 1  # DAQP's exit flag of an optimal solution


def daqp_solve(
    h: np.ndarray, q: np.ndarray, a: np.ndarray, lo: np.ndarray, hi: np.ndarray,
    clamped: bool = False,
) -> np.ndarray | None:
    """x minimising ``½xᵀHx + qᵀx`` subject to ``lo ≤ A x ≤ hi`` (H (n,n) positive
    definite, A (m,n) C-contiguous float64, infinite bounds allowed), or None when DAQP does
    not report an optimum (then the caller's other solver runs). ``clamped``: the bounds
    are already within ±DAQP_INF (the QPs write them so:
    :func:`offboard.safety.qp_rows_kernel.write_rows_kernel`)."""
    if not clamped:
        lo, hi = np.maximum(lo, -DAQP_INF), np.minimum(hi, DAQP_INF)
    x, _fval, flag, _info = daqp.solve(h, q, a, hi, lo)
    if flag != DAQP_OPTIMAL:
        return None
    out = np.asarray(x, dtype=float)
    return out if finite(out) else None
