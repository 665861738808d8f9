"""The DCBF filter's QP (DAQP, or OSQP): CLF + sampled-data CBF rows over the input polytope.

Variables x = [u (3), δ, σ] (docs/safety.md §4)::

    min ½‖u − u_nom‖² + ρ δ² + ρ_σ σ² + M σ
    s.t.  L_gV u − δ ≤ −L_fV − cV            (soft CLF, as the RCBF QP, Departures 10–11)
          gᵀu + σ ≥ r                       per sensed pair (:func:`offboard.dcbf.dcbf_rows`)
          A_U u ∈ [lo, hi]                  input polytope (:class:`offboard.dcbf.InputSet`)
          σ ≥ 0

Unlike the RCBF QP the input rows are never relaxed (σ acts on the barrier rows only), so
the answer is always realisable; if the solve fails the fallback brake is projected into the set.
"""

from __future__ import annotations

import math
import time

import numpy as np

from offboard.clf_rcbf import Brake, ClfTerms, QPResult, _ClfRowsQP, fallback_of
from offboard.dcbf import InputSet
from offboard.dcbf_kernel import rows_hold_kernel
from offboard.qp_rows_kernel import rows_finite_kernel
from swarm_common.enums import QPSolver, QPStatus
from swarm_common.fastnp import f64, rows3, vec3


class DcbfQP(_ClfRowsQP):
    """One agent's OSQP problem with room for ``max_pairs`` barrier rows."""

    def __init__(
        self, max_pairs: int, uset: InputSet, rho: float, clf_c: float,
        violation_weight: float = 100.0, eps: float = 1e-5, limit: int | None = None,
        solver: QPSolver | str = QPSolver.DAQP,
    ) -> None:
        """Room for ``max_pairs`` barrier rows, grown on demand up to ``limit`` rows
        (default: ``max_pairs``; :meth:`_ClfRowsQP.fit_rows`), solved by ``solver``."""
        self.uset = uset
        self.c = float(clf_c)
        self.lin_sigma = max(1e3, 50.0 * rho)
        self._start(max_pairs, limit, rho, violation_weight, eps, solver)

    def _setup(self, m: int) -> None:
        """(Re)build the OSQP problem with room for ``m`` barrier rows."""
        self.m = m
        eps = self._weights[2]
        uset = self.uset
        a_u, lo_u, hi_u = uset.rows()
        self.a_u, self.lo_u, self.hi_u = a_u, lo_u, hi_u
        nu = len(lo_u)
        self.nrow = nrow = 1 + m + nu + 1
        pat = np.zeros((nrow, 5))
        pat[0, 0:4] = 1.0
        pat[1 : 1 + m, 0:3] = 1.0
        pat[1 : 1 + m, 4] = 1.0
        pat[1 + m : 1 + m + nu, 0:3] = np.where(a_u != 0.0, 1.0, 0.0)
        pat[nrow - 1, 4] = 1.0
        self._mask_t = (pat != 0).T
        self._a = pat.copy()
        self._a[1 + m : 1 + m + nu, 0:3] = a_u
        self.l = np.full(nrow, -np.inf)
        self.u = np.full(nrow, np.inf)
        self.l[1 + m : 1 + m + nu] = lo_u
        self.u[1 + m : 1 + m + nu] = hi_u
        self.l[nrow - 1] = 0.0
        self.q = np.zeros(5)
        self.q[4] = self.lin_sigma
        self._defer_osqp(pat, self._a.T[self._mask_t], eps)

    def solve(
        self, u_nom: np.ndarray, clf: ClfTerms, g: np.ndarray, rhs: np.ndarray,
        h_min: float, brake: Brake, unheld: bool = False,
    ) -> QPResult:
        """Solve for u (always inside the input set); ``brake`` (3,) is the fallback, or a
        function giving it (:func:`offboard.clf_rcbf.fallback_of`). ``unheld``: the caller
        already found that u_nom breaks a row or the input set (the shortcut's test,
        :func:`~offboard.dcbf_kernel.rows_hold_kernel`, made in :mod:`offboard.dcbf_front`),
        so it is not made again."""
        t0 = time.perf_counter()
        self.fit_rows(len(rhs))
        k = min(len(rhs), self.m)
        if not unheld and rows_hold_kernel(self.a_u, self.lo_u, self.hi_u, g, rhs, k, u_nom):
            us = (time.perf_counter() - t0) * 1e6
            return QPResult(u_nom.copy(), QPStatus.INACTIVE, 0, us, h_min, clf.V, 0.0, 0.0,
                            False)
        if not rows_finite_kernel(vec3(u_nom), rows3(g), f64(rhs), k, vec3(clf.lgv),
                                  float(clf.lfv), float(clf.V)):
            u = self.uset.project(np.nan_to_num(fallback_of(brake), posinf=0.0, neginf=0.0))
            us = (time.perf_counter() - t0) * 1e6
            return QPResult(u, QPStatus.FALLBACK, -1, us, h_min, clf.V, 0.0, 0.0, True)
        u_c = self.uset.project(u_nom)
        clf_rhs = max(-clf.lfv - self.c * clf.V, float(clf.lgv.dot(u_c)))
        exact = self._one_row_exact(u_nom, clf, clf_rhs, g, rhs, k)
        if exact is not None:
            us = (time.perf_counter() - t0) * 1e6
            return QPResult(exact[0], QPStatus.SOLVED, 0, us, h_min, clf.V, exact[1], 0.0,
                            False)
        sv, x = self._solve_rows(u_nom, clf, clf_rhs, g, rhs, k)
        # the solver's answer up to its tolerance; project() is a no-op inside the set
        u = self.uset.project(x[0:3] if x is not None else np.nan_to_num(fallback_of(brake)))
        out = self._result(sv, x, u, h_min, clf)
        out.solve_us = (time.perf_counter() - t0) * 1e6
        return out

    def _one_row_exact(
        self, u_nom: np.ndarray, clf: ClfTerms, clf_rhs: float, g: np.ndarray,
        rhs: np.ndarray, k: int,
    ) -> tuple[np.ndarray, float] | None:
        """(u, δ): the QP's exact solution when one barrier row is active, alone or with
        the CLF row; None otherwise (OSQP solves it).

        If u_nom violates exactly one of the k rows, ``g_jᵀu ≥ r_j`` (g_j unit length),
        two active sets are tried, each solved from the KKT conditions of the QP (module
        docstring) and kept only if they hold:

        * the row alone: ``u = u_nom + λ g_j``, ``λ = r_j − g_jᵀu_nom``, δ = 0, if u keeps
          the CLF row without slack (``L_gV u ≤ clf_rhs``);
        * the row and the CLF row ``aᵀu − δ ≤ b`` (a = L_gV/‖L_gV‖, b = clf_rhs/‖L_gV‖, as
          the QP writes it): ``u = u_nom − ν a + λ g_j``, ``δ = ν/(2ρ)``, with
          ``ν = (aᵀu_nom − b + c (r_j − g_jᵀu_nom)) / (1 + 1/(2ρ) − c²)``, c = aᵀg_j, and
          ``λ = r_j − g_jᵀu_nom + ν c``; kept if ν ≥ 0.

        Either is kept only if λ ∈ [0, M] (M the slack's linear weight, so σ = 0 is
        optimal) and u satisfies every other row and the input set (checked); it is then
        the QP's unique minimiser, which OSQP would return to its tolerance. λ gets 1e-9
        m/s² more so that rounding cannot leave u a hair outside row j."""
        viol = rhs[:k] - g[:k] @ u_nom
        bad = np.flatnonzero(viol > 0.0)
        if len(bad) != 1:
            return None
        j = int(bad[0])
        gj = g[j]
        if abs(float(gj.dot(gj)) - 1.0) > 1e-9:
            return None
        lam = float(viol[j]) + 1e-9
        u = u_nom + lam * gj
        delta = 0.0
        if float(clf.lgv.dot(u)) > clf_rhs:  # the CLF row is active too
            nrm = math.sqrt(float(clf.lgv.dot(clf.lgv)))
            if nrm <= 1e-9:
                return None
            a = clf.lgv / nrm
            c = float(a.dot(gj))
            half_inv_rho = 0.5 / self._weights[0]
            nu = (float(a.dot(u_nom)) - clf_rhs / nrm + c * float(viol[j])) / (
                1.0 + half_inv_rho - c * c
            )
            if not nu >= 0.0:
                return None
            lam = float(viol[j]) + nu * c + 1e-9
            u = u_nom - nu * a + lam * gj
            delta = nu * half_inv_rho
        if not 0.0 <= lam <= self.lin_sigma:
            return None
        if not rows_hold_kernel(self.a_u, self.lo_u, self.hi_u, g, rhs, k, u):
            return None
        return u, delta
