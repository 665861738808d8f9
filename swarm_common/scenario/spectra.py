"""Eigenvalues of and solves with the graph matrices of a formation (the bearing Laplacian
and its follower block, :mod:`swarm_common.scenario.graphs`; docs/graphs.md).

* :func:`smallest_eig`: the rigidity checks' smallest eigenvalue, dense up to
  :data:`DENSE_MAX`, else by shift-invert Lanczos over a sparse LU, dense again where
  Lanczos does not converge in :data:`ARPACK_MAXITER` restarts;
* :func:`spectrum`: every eigenvalue of a symmetric matrix up to :data:`DENSE_SPECTRUM_MAX`,
  only its two ends above it;
* :func:`follower_solve`: L_ff⁻¹ rhs, dense up to :data:`DENSE_SPECTRUM_MAX`, a sparse LU
  above it;
* :func:`zero_tol`: the threshold below which an eigenvalue counts as zero.

The dense problems cost O(n³) time and O(n²) memory (a 2,048-agent formation's L_ff is of
order 5,760: 18 s per eigen-decomposition); below the thresholds the results are the dense
ones, bit for bit.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh, splu

EIG_TOL = 1e-9  # eigenvalue counted as zero below EIG_TOL · max(1, Gershgorin bound)
DENSE_MAX = 60  # matrices up to this size are checked densely
# matrices up to this order get every eigenvalue and dense solves (spectrum, follower_solve);
# a formation of up to 500 agents stays below it (3F rows), and its bits with it
DENSE_SPECTRUM_MAX = 1500
SHIFT = -0.1  # shift-invert point (below the spectrum of a positive semidefinite matrix)
# Lanczos restarts before smallest_eig falls back to the dense eigenvalues: the generated
# grids and spheres of 2,048 agents converge in 2-5, a ring's follower block of 2,048
# (hundreds of eigenvalues within 1 % of 1.7e-7) in none of scipy's default 57,600 (370 s)
ARPACK_MAXITER = 100


def smallest_eig(m: sp.spmatrix, deflate: np.ndarray | None = None) -> float:
    """Smallest eigenvalue of ``m + Q Qᵀ`` (``Q = deflate``, orthonormal columns, or none),
    ``m`` symmetric positive semidefinite: dense up to DENSE_MAX, else shift-invert Lanczos
    about SHIFT with the rank-``q`` term applied by the Woodbury identity (sparse LU only);
    dense again when Lanczos has not converged in ARPACK_MAXITER restarts (a cluster of
    nearly equal smallest eigenvalues: at most 6,144 rows, MAX_AGENTS' three per agent, about
    10 s and 0.3 GB)."""
    n = m.shape[0]
    q = np.zeros((n, 0)) if deflate is None else np.asarray(deflate, float)
    if n <= DENSE_MAX:
        return float(np.linalg.eigvalsh(m.toarray() + q @ q.T)[0])
    try:
        return _lanczos_smallest(m, q)
    except ArpackNoConvergence:
        return float(np.linalg.eigvalsh(m.toarray() + q @ q.T)[0])


def _lanczos_smallest(m: sp.spmatrix, q: np.ndarray) -> float:
    """:func:`smallest_eig` by shift-invert Lanczos (ArpackNoConvergence past
    ARPACK_MAXITER restarts)."""
    n = m.shape[0]
    a = (m - SHIFT * sp.identity(n)).tocsc()
    lu = splu(a)
    ainv_q = lu.solve(q) if q.shape[1] else q
    cap = np.eye(q.shape[1]) + q.T @ ainv_q

    def solve(x: np.ndarray) -> np.ndarray:
        y = lu.solve(np.asarray(x, float).reshape(-1))
        return y - ainv_q @ np.linalg.solve(cap, q.T @ y) if q.shape[1] else y

    op = LinearOperator((n, n), matvec=lambda x: m @ x + q @ (q.T @ x), dtype=float)
    opinv = LinearOperator((n, n), matvec=solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(n)
    ev = eigsh(op, k=1, sigma=SHIFT, which="LM", OPinv=opinv, v0=v0, return_eigenvectors=False,
               maxiter=ARPACK_MAXITER)
    return float(ev[0])


def _dense(a: sp.spmatrix | np.ndarray) -> np.ndarray:
    """``a`` as a dense float array (itself when it is one)."""
    return np.asarray(a, dtype=float) if isinstance(a, np.ndarray) else a.toarray()


def spectrum(m: sp.spmatrix | np.ndarray, dense_max: int | None = None) -> np.ndarray:
    """Eigenvalues, ascending, of the symmetric positive semidefinite matrix ``m`` (dense
    or sparse): all of them (numpy's ``eigvalsh``) up to order ``dense_max``; above it only
    the two ends [λ_min, λ_max], by Lanczos over the sparse matrix (:func:`smallest_eig`'s
    shift-invert for λ_min; from a fixed start vector, so every run gets the same bits;
    numpy's dense eigenvalues where Lanczos does not converge in ARPACK_MAXITER restarts).
    ``dense_max`` None: :data:`DENSE_SPECTRUM_MAX`."""
    n = m.shape[0]
    if n == 0:
        return np.zeros(0)
    if n <= (DENSE_SPECTRUM_MAX if dense_max is None else dense_max):
        return np.linalg.eigvalsh(_dense(m))
    s = sp.csr_matrix(m)
    lo = smallest_eig(s)
    v0 = np.random.default_rng(0).standard_normal(n)
    try:
        hi = float(eigsh(s, k=1, which="LA", v0=v0, return_eigenvectors=False,
                         maxiter=ARPACK_MAXITER)[0])
    except ArpackNoConvergence:  # a cluster at the top too: numpy's, as smallest_eig does
        hi = float(np.linalg.eigvalsh(s.toarray())[-1])
    return np.array([lo, hi])


def follower_solve(
    l_ff: sp.spmatrix | np.ndarray, rhs: sp.spmatrix | np.ndarray,
    dense_max: int | None = None,
) -> np.ndarray:
    """L_ff⁻¹ rhs (dense result) for a positive definite ``l_ff``: numpy's dense solve up to
    order ``dense_max`` (its bits; None: :data:`DENSE_SPECTRUM_MAX`), a sparse LU (SuperLU)
    above it."""
    if l_ff.shape[0] <= (DENSE_SPECTRUM_MAX if dense_max is None else dense_max):
        return np.linalg.solve(_dense(l_ff), _dense(rhs))
    out = splu(sp.csc_matrix(l_ff)).solve(np.asfortranarray(_dense(rhs)))
    return np.asarray(out, dtype=float)


def leader_map(l_ff: sp.spmatrix | np.ndarray, l_fl: sp.spmatrix | np.ndarray) -> np.ndarray:
    """K = −L_ff⁻¹ L_fl (3F × 3L), with p*_f = K p_L (paper §2.1), by
    :func:`follower_solve`: the one map from the leaders to the followers' desired
    positions (the feasibility check's and the formation's). ``l_ff`` must be positive
    definite (the caller has checked it)."""
    return -follower_solve(l_ff, l_fl)


def zero_tol(m: sp.spmatrix) -> float:
    """Threshold below which an eigenvalue of ``m`` counts as zero (Gershgorin-scaled)."""
    bound = float(np.max(np.abs(m).sum(axis=1))) if m.shape[0] else 0.0
    return EIG_TOL * max(1.0, bound)
