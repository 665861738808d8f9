"""Compiled steps of the DCBF QP before its solver (issue 11):
:class:`offboard.safety.dcbf.qp.DcbfQP`.

When the nominal input breaks a barrier row or the input set, :meth:`DcbfQP.solve` needs,
before any solver runs, the CLF row's bound (from u_nom projected into the input set) and
the exact solution with one active barrier row (docs/safety.md §4). In numpy these were
two dozen small array operations, each a Python call; :func:`pre_solve_kernel` makes them
in one. It takes the rows' violations ``r − g u_nom`` as numpy computes them (``@`` is
BLAS's dgemv, whose order of summation is its own and differs between processors), and
repeats every other operation, and its order, of the numpy formulation it replaced: 3-vector
dot products summed left to right (as numpy's ``dot`` of two 3-vectors sums them), no
fused multiply-adds (numba contracts none without ``fastmath``). So the answers are the
same bits as before (``tests/unit/safety/test_dcbf_exact_kernel.py``).
"""

from __future__ import annotations

import math

import numpy as np

from offboard.safety.dcbf.kernel import _dot3, project_into, rows_hold_kernel
from swarm_common.jit import kernel

NO_EXACT = -1.0  # pre_solve_kernel's δ when the one-row solution does not apply


@kernel
def pre_solve_kernel(
    u_nom: np.ndarray, g: np.ndarray, rhs: np.ndarray, viol: np.ndarray, k: int,
    lgv: np.ndarray, lfv: float, v: float, clf_c: float, half_inv_rho: float,
    lin_sigma: float, a_u: np.ndarray, lo_u: np.ndarray, hi_u: np.ndarray,
    proj: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray, u_out: np.ndarray,
) -> tuple[float, float]:
    """(clf_rhs, δ) of the QP (x = [u, δ, σ]) with finite data; u_out (3,) gets u.

    * ``clf_rhs = max(−L_fV − c V, L_gV·P(u_nom))`` (m/s²·(L_gV units)), P the projection
      into the input set (:func:`~offboard.safety.dcbf.kernel.project_into`, ``proj`` its
      scalars uz_lo, uz_hi, uh_lo, uh_hi, cone_c, g, shrink): the CLF row never asks for
      more than the projected nominal input already gives.
    * δ ≥ 0 and u the QP's exact minimiser when exactly one of the k rows ``g_jᵀu ≥ r_j``
      (g_j unit length) is violated (``viol = r − g u_nom`` > 0 for j alone); else
      δ = ``NO_EXACT`` and u_out is unspecified (a solver runs).

    Two active sets are tried, each solved from the KKT conditions of the QP
    (:mod:`offboard.safety.dcbf.qp`) and kept only if they hold:

    * the row alone: ``u = u_nom + λ g_j``, ``λ = r_j − g_jᵀu_nom``, δ = 0, if u keeps the
      CLF row without slack (``L_gV u ≤ clf_rhs``);
    * the row and the CLF row ``aᵀu − δ ≤ b`` (a = L_gV/‖L_gV‖, b = clf_rhs/‖L_gV‖, as
      the QP writes it): ``u = u_nom − ν a + λ g_j``, ``δ = ν/(2ρ)``, with
      ``ν = (aᵀu_nom − b + c (r_j − g_jᵀu_nom)) / (1 + 1/(2ρ) − c²)``, c = aᵀg_j, and
      ``λ = r_j − g_jᵀu_nom + ν c``; kept if ν ≥ 0.

    Either is kept only if λ ∈ [0, lin_sigma] (the slack's linear weight, so σ = 0 is
    optimal) and u satisfies every other row and the input set (checked); it is then the
    QP's unique minimiser, which a solver would return to its tolerance. λ gets 1e-9 m/s²
    more so that rounding cannot leave u a hair outside row j."""
    for c in range(3):
        u_out[c] = u_nom[c]
    project_into(u_out, proj, cos_a, sin_a)
    lo = -lfv - clf_c * v
    proj_dot = _dot3(lgv, u_out)
    clf_rhs = proj_dot if proj_dot > lo else lo  # Python's max(lo, proj_dot)
    j = -1
    for r in range(k):
        if viol[r] > 0.0:
            if j >= 0:
                return clf_rhs, NO_EXACT
            j = r
    if j < 0:
        return clf_rhs, NO_EXACT
    gj = g[j]
    if abs(_dot3(gj, gj) - 1.0) > 1e-9:
        return clf_rhs, NO_EXACT
    vj = viol[j]
    lam = vj + 1e-9
    for c in range(3):
        u_out[c] = u_nom[c] + lam * gj[c]
    delta = 0.0
    if _dot3(lgv, u_out) > clf_rhs:  # the CLF row is active too
        nrm = math.sqrt(_dot3(lgv, lgv))
        if nrm <= 1e-9:
            return clf_rhs, NO_EXACT
        a0, a1, a2 = lgv[0] / nrm, lgv[1] / nrm, lgv[2] / nrm
        cg = a0 * gj[0] + a1 * gj[1] + a2 * gj[2]
        a_dot_u = a0 * u_nom[0] + a1 * u_nom[1] + a2 * u_nom[2]
        nu = (a_dot_u - clf_rhs / nrm + cg * vj) / (1.0 + half_inv_rho - cg * cg)
        if not nu >= 0.0:
            return clf_rhs, NO_EXACT
        lam = vj + nu * cg + 1e-9
        u_out[0] = (u_nom[0] - nu * a0) + lam * gj[0]
        u_out[1] = (u_nom[1] - nu * a1) + lam * gj[1]
        u_out[2] = (u_nom[2] - nu * a2) + lam * gj[2]
        delta = nu * half_inv_rho
    if not (lam >= 0.0 and lam <= lin_sigma):
        return clf_rhs, NO_EXACT
    if not rows_hold_kernel(a_u, lo_u, hi_u, g, rhs, k, u_out):
        return clf_rhs, NO_EXACT
    return clf_rhs, delta
