"""The DCBF filter's QP (DAQP, or OSQP): CLF + sampled-data CBF rows over the input polytope.

Variables x = [u (3), δ, σ] (docs/safety.md §4)::

    min ½‖u − u_nom‖² + ρ δ² + ρ_σ σ² + M σ
    s.t.  L_gV u − δ ≤ −L_fV − cV            (soft CLF, as the RCBF QP, Departures 10–11)
          gᵀu + σ ≥ r                       per sensed pair
          (:func:`offboard.safety.dcbf.kernel.dcbf_rows_kernel`)
          A_U u ∈ [lo, hi]                  input polytope
          (:class:`offboard.safety.dcbf.model.ProjectedInputSet`)
          σ ≥ 0

Unlike the RCBF QP the input rows are never relaxed (σ acts on the barrier rows only), so
the answer is always realisable; if the solve fails the fallback brake is projected into the set.
"""

from __future__ import annotations

import time

import numpy as np

from offboard.safety.dcbf.exact_kernel import NO_EXACT, pre_solve_kernel
from offboard.safety.dcbf.kernel import rows_hold_kernel
from offboard.safety.dcbf.model import ProjectedInputSet
from offboard.safety.qp_rows_kernel import rows_finite_kernel
from offboard.safety.rcbf.clf_rcbf import Brake, ClfTerms, QPResult, _ClfRowsQP, fallback_of
from swarm_common.enums import QPSolver, QPStatus
from swarm_common.fastnp import f64, rows3, vec3


class DcbfQP(_ClfRowsQP):
    """One agent's OSQP problem with room for ``max_pairs`` barrier rows."""

    def __init__(
        self, max_pairs: int, uset: ProjectedInputSet, rho: float, clf_c: float,
        violation_weight: float = 100.0, eps: float = 1e-5, limit: int | None = None,
        solver: QPSolver | str = QPSolver.DAQP, trust: bool = False,
    ) -> None:
        """Room for ``max_pairs`` barrier rows, grown on demand up to ``limit`` rows
        (default: ``max_pairs``; :meth:`_ClfRowsQP.fit_rows`), solved by ``solver``.
        ``trust``: three more hard input rows, the trust region ``lo ≤ u ≤ hi`` of
        :meth:`set_trust` (offboard.safety.dcbf.trust); until set, no bound."""
        self.uset = uset
        self._trust = np.full((2, 3), np.inf) if trust else None
        if self._trust is not None:
            self._trust[0] = -np.inf
        self.c = float(clf_c)
        self.lin_sigma = max(1e3, 50.0 * rho)
        self._half_inv_rho = 0.5 / float(rho)  # the CLF slack's δ = ν/(2ρ) (pre_solve_kernel)
        self._start(max_pairs, limit, rho, violation_weight, eps, solver)

    def _setup(self, m: int) -> None:
        """(Re)build the OSQP problem with room for ``m`` barrier rows."""
        self.m = m
        eps = self._weights[2]
        uset = self.uset
        a_u, lo_u, hi_u = uset.rows()
        if self._trust is not None:  # the trust region's rows after the input set's
            a_u = np.vstack([a_u, np.eye(3)])
            lo_u = np.concatenate([lo_u, self._trust[0]])
            hi_u = np.concatenate([hi_u, self._trust[1]])
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

    def set_trust(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """The trust region's bounds ``lo ≤ u ≤ hi`` (3,) (m/s²) from now on (a QP built
        with ``trust``; hard rows like the input set's)."""
        if self._trust is None:
            raise RuntimeError("DcbfQP.set_trust: the QP was built without trust rows")
        self._trust[0], self._trust[1] = lo, hi
        nu = len(self.lo_u)
        self.lo_u[nu - 3 :], self.hi_u[nu - 3 :] = lo, hi
        first = 1 + self.m + nu - 3  # the rows' place in the solver's problem (_setup)
        self.l[first : first + 3], self.u[first : first + 3] = lo, hi

    def solve(
        self, u_nom: np.ndarray, clf: ClfTerms, g: np.ndarray, rhs: np.ndarray,
        h_min: float, brake: Brake, unheld: bool = False,
    ) -> QPResult:
        """Solve for u (always inside the input set); ``brake`` (3,) is the fallback, or a
        function giving it (:func:`offboard.safety.rcbf.clf_rcbf.fallback_of`). ``unheld``: the
        caller
        already found that u_nom breaks a row or the input set (the shortcut's test,
        :func:`~offboard.safety.dcbf.kernel.rows_hold_kernel`, made in
        :mod:`offboard.safety.dcbf.front`),
        so it is not made again."""
        t0 = time.perf_counter()
        self.fit_rows(len(rhs))
        k = min(len(rhs), self.m)
        if not unheld and rows_hold_kernel(self.a_u, self.lo_u, self.hi_u, g, rhs, k, u_nom):
            us = (time.perf_counter() - t0) * 1e6
            return QPResult(u_nom.copy(), QPStatus.INACTIVE, 0, us, h_min, clf.V, 0.0, 0.0,
                            False)
        u_nom3, g3, rhs1, lgv3 = vec3(u_nom), rows3(g), f64(rhs), vec3(clf.lgv)
        lfv, v = float(clf.lfv), float(clf.V)
        if not rows_finite_kernel(u_nom3, g3, rhs1, k, lgv3, lfv, v):
            u = self.uset.project(np.nan_to_num(fallback_of(brake), posinf=0.0, neginf=0.0))
            us = (time.perf_counter() - t0) * 1e6
            return QPResult(u, QPStatus.FALLBACK, -1, us, h_min, clf.V, 0.0, 0.0, True)
        viol = rhs[:k] - g[:k] @ u_nom  # BLAS's order: pre_solve_kernel takes it as it is
        u = np.empty(3)
        proj, cos_a, sin_a = self.uset.projection
        clf_rhs, delta = pre_solve_kernel(
            u_nom3, g3, rhs1, viol, k, lgv3, lfv, v, self.c, self._half_inv_rho,
            self.lin_sigma, self.a_u, self.lo_u, self.hi_u, proj, cos_a, sin_a, u,
        )
        if delta != NO_EXACT:  # one barrier row active, alone or with the CLF row: exact
            us = (time.perf_counter() - t0) * 1e6
            out = QPResult(u, QPStatus.SOLVED, 0, us, h_min, clf.V, delta, 0.0, False)
            return self._tight(out, g3, rhs1, k, self.a_u, self.lo_u, self.hi_u)
        sv, x = self._solve_rows(u_nom, clf, clf_rhs, g, rhs, k)
        # the solver's answer up to its tolerance; project() is a no-op inside the set
        u = self.uset.project(x[0:3] if x is not None else np.nan_to_num(fallback_of(brake)))
        out = self._result(sv, x, u, h_min, clf)
        out.solve_us = (time.perf_counter() - t0) * 1e6
        if x is not None:  # after the clock: the record's bookkeeping is not solve time
            self._tight(out, g3, rhs1, k, self.a_u, self.lo_u, self.hi_u)
        return out
