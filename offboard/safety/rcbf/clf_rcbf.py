"""CLF–RCBF quadratic program (paper §4.2–4.4; Departures 10–14).

CLF (Departure 10): with ``e1 = z1 − p̂*``, ``e2 = z2 − v̂*`` and the sliding variable
``s = e2 + λ e1``::

    V = k_p ‖e1‖² + k_d ‖s‖²
    V̇ = 2k_p e1ᵀe2 + 2k_d sᵀ(u + w − â* + λ e2),   w = z3 + Φ(z1,z2)ζ̂

``L_gV = 2k_d sᵀ`` vanishes only on s = 0 where ``V̇ = −2k_pλ‖e1‖² ≤ −cV`` for c ≤ 2λ, so V
is a valid CLF. The nominal formation controller (shared by all methods)::

    u_nom = â* − w − λ e2 − k_s s − (k_p/k_d) e1     ⇒  V̇ = −2k_pλ‖e1‖² − 2k_d k_s‖s‖²

Anti-windup (docs/saturation.md §2): given the input box ``[lo, hi]`` the same law is written
``u_nom = f + fb`` with the feed-forward ``f = â* − w`` and ``fb = −k_v (e2 − v_r)``,
``k_v = λ + k_s``, ``v_r = −c e1``, ``c = (k_s λ + k_p/k_d)/k_v``; per axis the feed-forward
is served first (clipped to the box shrunk by :data:`AW_RESERVE`), the feedback gets what
is left ``[−b⁻, b⁺]``, and the error-velocity reference is limited (its direction kept) so
that stopping from it needs at most a share :data:`AW_BRAKE_SHARE` of the braking budget
``b_e`` along e1: ``‖v_r‖ ≤ sqrt(2 β b_e ‖e1‖)``. Inside the box and for small errors it is
the law above.

RCBF (Departure 12): ``h = ‖Δp‖² + 2τ Δvᵀ Δp − D²`` (§2.3, Δ = i − j) and the reciprocal
condition ``L_fB + L_gB u − γ/B ≤ 0`` with B = 1/h, which equals ``ḣ ≥ −γ h³``::

    ḣ = 2Δpᵀ Δv + 2τ (‖Δv‖² + Δpᵀ(a_i − a_j))

Pairs (Departure 13): every agent in sensing range; follower–follower pairs take half of
the budget each (``2τΔpᵀ a_i ≥ −½(2ΔpᵀΔv + 2τ‖Δv‖² + γh³)``), against a leader the
follower takes all of it with the leader's broadcast acceleration. Δp, Δv come from the
onboard relative sensing (available for non-neighbours, unlike estimates).

QP (§4.4), variables x = [u (3), δ, σ]::

    min ½‖u − u_nom‖² + ρ δ² + ρ_σ σ² + M σ
    s.t.  L_gV u − δ ≤ −L_fV − cV                (soft CLF, slack δ)
          n̂_jᵀ u + σ ≥ r_j      for every sensed pair (rows normalised, n̂ = Δp/‖Δp‖)
          u_lo ≤ u ≤ u_hi,  σ ≥ 0

σ is an exact-penalty relaxation (linear weight M = max(10³, 50ρ) above the rows'
multipliers, incl. the CLF row's 2ρδ; quadratic weight 100): σ = 0 whenever the
hard RCBF rows and the box are jointly feasible; otherwise the QP returns the
least-violating input and the step is counted as a fallback (Departure 14). If OSQP itself
fails, the fallback is braking ``u = clip(−w − k_b z2)``. u is never NaN.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import osqp
from scipy import sparse

from offboard.safety.clf_kernel import CLF_OUT, nominal_into
from offboard.safety.pair_kernel import barrier_kernel, tangential_kernel
from offboard.safety.qp_rows_kernel import tight_rows_kernel, write_rows_kernel
from offboard.safety.solvers.daqp_call import DAQP_INF, daqp_solve
from offboard.safety.solvers.osqp_call import update_solve
from swarm_common.enums import QPSolver, QPStatus
from swarm_common.fastnp import f64, finite, rows3, vec3

SOLVED = (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
# m/s²: a row counts as active at a solution when met within this (the rows are unit
# normalised); a DAQP or exact solution meets its active rows to rounding (the exact one
# to 1e-9), OSQP's polished one to well within it
ACTIVE_TOL_MPS2 = 1e-4

# a safety QP's fallback input (m/s²), or a function giving it: the filters pass the
# function, so the brake is formed only on the rare step that takes it
Brake = np.ndarray | Callable[[], np.ndarray]


def fallback_of(brake: Brake) -> np.ndarray:
    """The fallback input of a safety QP's ``solve``, formed now if given as a function."""
    return brake() if callable(brake) else brake


@dataclass
class ClfTerms:
    """V, L_fV, L_gV of the sliding-variable CLF and the nominal control."""

    V: float
    lfv: float
    lgv: np.ndarray
    u_nom: np.ndarray


AW_RESERVE = 0.1  # share of each axis' half-range the feed-forward leaves to feedback
AW_BRAKE_SHARE = 0.5  # β: share of the braking budget the error-velocity reference may need


def clf_terms_of_reference(
    z1: np.ndarray, z2: np.ndarray, xi: np.ndarray, tau_ff: float, w: np.ndarray, kp: float,
    kd: float, lam: float, ks: float, box: tuple[np.ndarray, np.ndarray] | None = None,
) -> ClfTerms:
    """The CLF terms and nominal control (module docstring; with ``box`` = (lo, hi) (m/s², per
    axis) the nominal control has anti-windup, docs/saturation.md §2, and lies in the box)
    of the estimate (z1 (m), z2 (m/s)) tracking the desired state
    ξ = [p*, v*, a*, j*] (12,): ``e1 = z1 − p*``, ``e2 = z2 − v*`` and the reference
    acceleration taken ``tau_ff`` (s) ahead, ``a* + tau_ff j*`` (m/s²). One compiled call
    (:func:`offboard.safety.clf_kernel.nominal_into`), the same bits as forming them in numpy."""
    lo, hi = box if box is not None else (NO_BOX, NO_BOX)
    out = np.empty(CLF_OUT)  # a new array from Python: cheaper than one the kernel boxes
    nominal_into(
        vec3(z1), vec3(z2), f64(xi), float(tau_ff), vec3(w), float(kp), float(kd),
        float(lam), float(ks), box is not None, vec3(lo), vec3(hi), AW_BRAKE_SHARE, AW_RESERVE,
        out,
    )
    return clf_terms_from(out)


def clf_terms_from(out: np.ndarray) -> ClfTerms:
    """The CLF kernels' (8,) output [V, L_fV, L_gV (3), u_nom (3)] as :class:`ClfTerms`."""
    return ClfTerms(V=float(out[0]), lfv=float(out[1]), lgv=out[2:5], u_nom=out[5:8])


NO_BOX = np.zeros(3)  # the kernels' box argument when the anti-windup box is off (never written)


def barrier(dp: np.ndarray, dv: np.ndarray, tau: float, d_safe: float) -> np.ndarray:
    """h_ij for rows of Δp = p_i − p_j, Δv = v_i − v_j (§2.3, §4.3):
    ``‖Δp‖² + 2τ ΔvᵀΔp − D²`` (m²), compiled
    (:func:`offboard.safety.pair_kernel.barrier_kernel`)."""
    return barrier_kernel(rows3(dp), rows3(dv), float(tau), float(d_safe))


def tangential_term(dp: np.ndarray, h: np.ndarray, gain: float, h_on: float) -> np.ndarray:
    """Deadlock breaker: a sideways push ``gain·max(0, 1 − h/h_on)·t̂`` per close pair.

    ``t̂ = n̂ × a / ‖·‖`` with a = e_z (e_x when Δp is nearly vertical); for the other agent
    of the pair Δp changes sign and so does t̂, so the two sidestep in opposite directions.
    Compiled (:func:`offboard.safety.pair_kernel.tangential_kernel`).
    """
    if gain <= 0.0 or len(h) == 0:
        return np.zeros(3)
    return tangential_kernel(rows3(dp), f64(h), float(gain), float(h_on))


@dataclass
class QPResult:
    """Outcome of one control QP."""

    u: np.ndarray
    status: QPStatus
    status_val: int
    solve_us: float
    h_min: float
    V: float
    slack: float  # CLF slack δ
    violation: float  # RCBF relaxation σ (0 when the hard problem is feasible)
    fallback: bool
    # a solved QP's rows active at u (_ClfRowsQP._tight): the indices of the safety rows
    # among the first k (None: not solved) and the number of input rows at a bound
    tight: np.ndarray | None = None
    tight_input: int = 0


class _ClfRowsQP:
    """The part of the safety QPs (:class:`SafetyQP`, ``offboard.safety.dcbf.qp.DcbfQP``) that is
    the same: variables x = [u (3), δ, σ], row 0 the CLF row normalised by ‖L_gV‖, rows
    1..m the safety rows ``g_jᵀu + σ ≥ r_j``; the subclass sets up the matrices and the
    input-set rows after them."""

    m: int
    limit: int  # the most rows the problem may grow to
    _weights: tuple[float, float, float]  # rho, violation weight, eps (for _setup)
    nrow: int
    q: np.ndarray
    l: np.ndarray
    u: np.ndarray
    _a: np.ndarray
    _mask_t: np.ndarray

    def _start(
        self, max_pairs: int, limit: int | None, rho: float, violation_weight: float, eps: float,
        solver: QPSolver | str = QPSolver.DAQP,
    ) -> None:
        """Keep the weights and the solver, set the growth limit (default ``max_pairs``),
        build the problem with room for ``max_pairs`` rows."""
        self._weights = (float(rho), float(violation_weight), float(eps))
        self.backend = QPSolver(solver)
        # the objective's Hessian diag(1, 1, 1, 2ρ, 2ρ_σ): dense for DAQP, sparse for OSQP
        self._h = np.diag([1.0, 1.0, 1.0, 2.0 * float(rho), 2.0 * float(violation_weight)])
        self.limit = int(max_pairs if limit is None else max(limit, max_pairs))
        self._build(int(max_pairs))

    def _build(self, m: int) -> None:
        """The subclass's problem with room for ``m`` rows (:meth:`_setup`), and DAQP's copy
        of it sized to match: the rows in use and their bounds clamped to ±DAQP_INF, written
        with the rows in :meth:`_solve_rows` (:func:`write_rows_kernel`)."""
        self._setup(m)
        self._a_daqp = np.empty_like(self._a)
        self._lo_daqp, self._hi_daqp = np.empty(len(self.l)), np.empty(len(self.u))

    def _setup(self, m: int) -> None:
        raise NotImplementedError

    def _defer_osqp(self, pattern: np.ndarray, a_data: np.ndarray | None, eps: float) -> None:
        """Keep the OSQP problem's setup data: the sparsity ``pattern`` (nrow, 5) of A, its
        values in OSQP's (column-major) order (None: the pattern's ones), and copies of q,
        l, u as they are now (the rows are written into them in place later). OSQP is
        set up from exactly this data the first time :attr:`solver` is used: DAQP answers
        almost every solve, and a problem grown on demand need not factorise until OSQP
        is called. The solver is the same as one set up here and not used until then."""
        self._osqp: osqp.OSQP | None = None
        self._osqp_data = (pattern, a_data, self.q.copy(), self.l.copy(), self.u.copy(), eps)

    @property
    def solver(self) -> osqp.OSQP:
        """The OSQP solver of the current problem, set up on first use (:meth:`_defer_osqp`)."""
        if self._osqp is None:
            pattern, a_data, q, lo, hi, eps = self._osqp_data
            amat = sparse.csc_matrix(pattern)
            if a_data is not None:
                amat.data[:] = a_data
            solver = osqp.OSQP()
            solver.setup(
                sparse.csc_matrix(self._h), q, amat, lo, hi,  # _h: the one Hessian (_start)
                eps_abs=eps, eps_rel=eps, warm_starting=True, polishing=True,
                verbose=False, max_iter=4000,
            )
            self._osqp = solver
        return self._osqp

    def fit_rows(self, rows: int) -> None:
        """Grow the problem (doubling, at most to ``limit``) when ``rows`` safety rows do
        not fit. A problem sized for every other agent of a large swarm would factorise
        hundreds of unused rows on every solve (125 agents: 250), though a follower senses
        a dozen or two; it starts small and grows on the first step that needs more. The
        rebuilt solver starts cold (no warm start) and is deterministic, so in-process and
        distributed runs stay equal."""
        if rows > self.m and self.m < self.limit:
            self._build(min(self.limit, max(rows, 2 * self.m)))

    def _solve_rows(
        self, u_nom: np.ndarray, clf: ClfTerms, clf_rhs: float, g: np.ndarray, rhs: np.ndarray,
        k: int,
    ) -> tuple[int, np.ndarray | None]:
        """Write the CLF row (``L_gV u − δ ≤ clf_rhs``) and the first k safety rows and
        solve: with DAQP (exact, :mod:`offboard.safety.solvers.daqp_call`) when it is the chosen
        solver,
        else, or when DAQP reports no optimum, with OSQP warm-started; (OSQP status value,
        x) with x None when the solve failed (a DAQP optimum reports OSQP's "solved")."""
        a, m = self._a, self.m
        # CLF row normalised by ‖L_gV‖: δ is the shortfall in m/s² along −ŝ, so ρδ² is
        # commensurate with ½‖u − u_nom‖² (ρ ~ 1–10 keeps it soft against the safety rows)
        nrm = math.sqrt(float(clf.lgv.dot(clf.lgv)))
        n = write_rows_kernel(
            a, self.l, self.u, self.q, vec3(clf.lgv), nrm, float(clf_rhs), rows3(g),
            f64(rhs), k, m, vec3(u_nom), self._a_daqp, self._lo_daqp, self._hi_daqp, DAQP_INF,
        )
        if self.backend is QPSolver.DAQP:  # the rows in use only (write_rows_kernel)
            x_exact = daqp_solve(self._h, self.q, self._a_daqp[:n], self._lo_daqp[:n],
                                 self._hi_daqp[:n], clamped=True)
            if x_exact is not None:
                return int(osqp.SolverStatus.OSQP_SOLVED), x_exact
        status, x = update_solve(self.solver, self.q, self.l, self.u, a.T[self._mask_t])
        sv = int(status)
        if status in SOLVED and x is not None and finite(x):
            return sv, np.asarray(x, dtype=float)
        self.solver.warm_start(x=np.zeros(5), y=np.zeros(self.nrow))
        return sv, None

    @staticmethod
    def _tight(out: QPResult, g: np.ndarray, rhs: np.ndarray, k: int, a_u: np.ndarray,
               lo: np.ndarray, hi: np.ndarray) -> QPResult:
        """``out`` (a solved QP's result) with the rows active at its u: the first k safety
        rows of g (unit rows), rhs and the input rows ``lo ≤ a_u u ≤ hi``
        (:func:`~offboard.safety.qp_rows_kernel.tight_rows_kernel`; reads only)."""
        idx = np.empty(k, dtype=np.int64)
        n, n_in = tight_rows_kernel(rows3(g), f64(rhs), k, float(out.violation), a_u, lo, hi,
                                    vec3(out.u), ACTIVE_TOL_MPS2, idx)
        out.tight, out.tight_input = idx[:n], int(n_in)
        return out

    @staticmethod
    def _result(
        sv: int, x: np.ndarray | None, u: np.ndarray, h_min: float, clf: ClfTerms
    ) -> QPResult:
        """QPResult of a solve: ``u`` is the solver's input made admissible, or the braking
        fallback made admissible when ``x`` is None."""
        if x is None:
            return QPResult(u, QPStatus.FALLBACK, sv, 0.0, h_min, clf.V, 0.0, 0.0, True)
        sigma = max(0.0, float(x[4]))
        relaxed = sigma > 1e-3
        status = QPStatus.RELAXED if relaxed else QPStatus.SOLVED
        return QPResult(u, status, sv, 0.0, h_min, clf.V, float(x[3]), sigma, relaxed)


class SafetyQP(_ClfRowsQP):
    """One agent's OSQP problem, set up once with room for ``max_pairs`` RCBF rows."""

    def __init__(
        self,
        max_pairs: int,
        u_lo: np.ndarray,
        u_hi: np.ndarray,
        rho: float,
        clf_c: float,
        violation_weight: float = 100.0,
        violation_linear: float | None = None,
        eps: float = 1e-4,
        brake_gain: float = 2.0,
        limit: int | None = None,
        solver: QPSolver | str = QPSolver.DAQP,
    ) -> None:
        """Room for ``max_pairs`` RCBF rows, grown on demand up to ``limit`` rows (default:
        ``max_pairs``; :meth:`_ClfRowsQP.fit_rows`), solved by ``solver``."""
        self.u_lo = np.asarray(u_lo, dtype=float)
        self.u_hi = np.asarray(u_hi, dtype=float)
        self.c = float(clf_c)
        self.brake_gain = brake_gain
        # exact penalty: M must exceed every multiplier, incl. the CLF row's 2ρδ (δ ≤ ~16 m/s²)
        self.lin_sigma = float(violation_linear or max(1e3, 50.0 * rho))
        self._box_rows = np.eye(3)  # the box as input rows (_tight)
        self._start(max_pairs, limit, rho, violation_weight, eps, solver)

    def _setup(self, m: int) -> None:
        """(Re)build the OSQP problem with room for ``m`` RCBF rows."""
        self.m = m
        eps = self._weights[2]
        nrow = 1 + m + 3 + 1
        self.nrow = nrow
        pat = np.zeros((nrow, 5))
        pat[0, 0:4] = 1.0
        pat[1 : 1 + m, 0:3] = 1.0
        pat[1 : 1 + m, 4] = 1.0
        for k in range(3):
            pat[1 + m + k, k] = 1.0
        pat[nrow - 1, 4] = 1.0
        self._mask_t = (pat != 0).T
        self._a = pat.copy()
        self.l = np.full(nrow, -np.inf)
        self.u = np.full(nrow, np.inf)
        self.l[1 + m : 4 + m] = self.u_lo
        self.u[1 + m : 4 + m] = self.u_hi
        self.l[nrow - 1] = 0.0
        self.q = np.zeros(5)
        self.q[4] = self.lin_sigma
        self._defer_osqp(pat, None, eps)

    def solve(
        self,
        u_nom: np.ndarray,
        clf: ClfTerms,
        n_hat: np.ndarray,
        rhs: np.ndarray,
        h: np.ndarray,
        brake: Brake,
    ) -> QPResult:
        """Solve for u; ``brake`` (3,) is the fallback if OSQP fails (then clipped), or a
        function giving it (:func:`fallback_of`)."""
        t0 = time.perf_counter()
        h_min = float(h.min()) if len(h) else float("inf")
        # Shortcut (exact): if the box-projected nominal input already satisfies every
        # RCBF row and the CLF row with δ = 0, it is the QP's optimum.
        u_c = np.minimum(np.maximum(u_nom, self.u_lo), self.u_hi)
        # The CLF row never demands more decrease than the box-projected nominal input
        # achieves: otherwise, with the box active, the heavy slack weight ρ turns the QP
        # into a bang-bang (sliding-mode) law on sign(s) that chatters between box corners.
        clf_rhs = max(-clf.lfv - self.c * clf.V, float(clf.lgv.dot(u_c)))
        if len(rhs) == 0 or bool((n_hat @ u_c >= rhs).all()):
            us = (time.perf_counter() - t0) * 1e6
            return QPResult(u_c, QPStatus.INACTIVE, 0, us, h_min, clf.V, 0.0, 0.0, False)
        self.fit_rows(len(rhs))
        m = self.m
        k = min(len(rhs), m)
        ok = np.isfinite(u_nom).all() and np.isfinite(rhs[:k]).all() and np.isfinite(
            clf.lgv).all() and np.isfinite(clf.lfv) and np.isfinite(clf.V)
        if not ok:
            u = np.clip(np.nan_to_num(fallback_of(brake), posinf=0.0, neginf=0.0), self.u_lo,
                        self.u_hi)
            us = (time.perf_counter() - t0) * 1e6
            return QPResult(u, QPStatus.FALLBACK, -1, us, h_min, clf.V, 0.0, 0.0, True)
        sv, x = self._solve_rows(u_nom, clf, clf_rhs, n_hat, rhs, k)
        u = np.clip(x[0:3] if x is not None else np.nan_to_num(fallback_of(brake)), self.u_lo,
                    self.u_hi)
        out = self._result(sv, x, u, h_min, clf)
        out.solve_us = (time.perf_counter() - t0) * 1e6
        if x is not None:  # after the clock: the record's bookkeeping is not solve time
            self._tight(out, n_hat, rhs, k, self._box_rows, self.u_lo, self.u_hi)
        return out

