"""offboard.safety.solvers.osqp_call: the extension-object path answers what OSQP's public API
answers,
bit for bit (and the public API is what it falls back to without ``_solver``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import osqp
import scipy.sparse as sp

from offboard.safety.solvers.osqp_call import update_solve

P = sp.csc_matrix(np.diag([1.0, 2.0, 3.0]))
A = sp.csc_matrix(np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [1.0, 0.0, -1.0]]))


def _solver() -> osqp.OSQP:
    s = osqp.OSQP()
    s.setup(P=P, q=np.zeros(3), A=A, l=np.full(3, -1.0), u=np.full(3, 1.0), verbose=False,
            eps_abs=1e-8, eps_rel=1e-8)
    return s


class _PublicOnly:
    """The wrapper's public calls only (no ``_solver`` attribute)."""

    def __init__(self, inner: osqp.OSQP) -> None:
        self.inner = inner

    def update(self, **kw: Any) -> None:
        self.inner.update(**kw)

    def solve(self, **kw: Any) -> Any:
        return self.inner.solve(**kw)


def test_extension_path_equals_the_public_api_over_a_sequence_of_updates() -> None:
    fast, public, fallback = _solver(), _solver(), _solver()
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = rng.normal(size=3)
        lo = np.array([rng.uniform(0.2, 1.0), -np.inf, rng.uniform(-2.0, -1.0)])
        hi = np.array([np.inf, rng.uniform(0.5, 2.0), rng.uniform(1.0, 2.0)])
        ax = A.data * rng.uniform(0.8, 1.2, size=A.nnz)
        status, x = update_solve(fast, q, lo, hi, ax)
        public.update(q=q, l=lo, u=hi, Ax=ax)
        res = public.solve(raise_error=False)
        status_fb, x_fb = update_solve(_PublicOnly(fallback), q, lo, hi, ax)  # type: ignore[arg-type]
        assert status == res.info.status_val == status_fb
        assert x is not None and np.array_equal(x, res.x) and np.array_equal(x, x_fb)
