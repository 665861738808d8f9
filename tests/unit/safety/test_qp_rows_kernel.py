"""The safety QPs' compiled data bookkeeping (offboard.safety.qp_rows_kernel) against the numpy
slice assignments and finiteness tests it replaced, on random rows: the same matrix,
bounds and cost (nan and inf included) within rounding (tests/reference/close.py: two
implementations), and the same guard verdicts."""

from __future__ import annotations

import math

import numpy as np
from reference.close import assert_close

from offboard.safety.qp_rows_kernel import rows_finite_kernel, write_rows_kernel
from offboard.safety.solvers.daqp_call import DAQP_INF


def _write_numpy(
    a: np.ndarray, lo: np.ndarray, hi: np.ndarray, q: np.ndarray, lgv: np.ndarray,
    nrm: float, clf_rhs: float, g: np.ndarray, rhs: np.ndarray, k: int, m: int,
    u_nom: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The previous ``_ClfRowsQP._solve_rows`` writes, and DAQP's clamped bounds."""
    if nrm > 1e-9:
        a[0, 0:3] = lgv / nrm
        hi[0] = clf_rhs / nrm
    else:
        a[0, 0:3] = 0.0
        hi[0] = np.inf
    a[0, 3] = -1.0
    a[1 : 1 + k, 0:3] = g[:k]
    a[1 + k : 1 + m, 0:3] = 0.0
    lo[1 : 1 + k] = rhs[:k]
    lo[1 + k : 1 + m] = -np.inf
    q[0:3] = -u_nom
    return np.maximum(lo, -DAQP_INF), np.minimum(hi, DAQP_INF)


def test_rows_written_as_numpy_wrote_them() -> None:
    rng = np.random.default_rng(8)
    for trial in range(500):
        m = int(rng.integers(1, 12))
        nu = int(rng.integers(0, 9))
        rows = 1 + m + nu + 1
        a0 = rng.normal(size=(rows, 5))
        lo0 = np.where(rng.random(rows) < 0.3, -np.inf, rng.normal(size=rows))
        hi0 = np.where(rng.random(rows) < 0.3, np.inf, rng.normal(size=rows) + 5.0)
        q0 = rng.normal(size=5)
        k = int(rng.integers(0, m + 1))
        g = rng.normal(size=(int(rng.integers(k, k + 3)), 3))
        rhs = rng.normal(size=len(g)) * 10.0 ** rng.integers(-3, 4)
        if trial % 7 == 0 and k:
            rhs[0] = [np.nan, np.inf, -np.inf][trial % 3]
        lgv = rng.normal(size=3) * (1e-12 if trial % 5 == 0 else 1.0)
        nrm = math.sqrt(float(lgv @ lgv))
        clf_rhs, u_nom = float(rng.normal()), rng.normal(size=3)
        want = [a0.copy(), lo0.copy(), hi0.copy(), q0.copy()]
        lo_c_want, hi_c_want = _write_numpy(want[0], want[1], want[2], want[3], lgv, nrm,
                                            clf_rhs, g, rhs, k, m, u_nom)
        got = [a0.copy(), lo0.copy(), hi0.copy(), q0.copy()]
        lo_c, hi_c = np.empty(rows), np.empty(rows)
        write_rows_kernel(got[0], got[1], got[2], got[3], lgv, nrm, clf_rhs, g, rhs, k, m,
                          u_nom, lo_c, hi_c, DAQP_INF)
        for x, y in zip(got, want, strict=True):
            assert_close(x, y, trial)
        assert_close(lo_c, lo_c_want, trial)
        assert_close(hi_c, hi_c_want, trial)


def test_finite_guard_is_the_numpy_guard() -> None:
    rng = np.random.default_rng(9)
    for trial in range(2000):
        k = int(rng.integers(0, 6))
        g, rhs = rng.normal(size=(k + 2, 3)), rng.normal(size=k + 2)
        u_nom, lgv = rng.normal(size=3), rng.normal(size=3)
        lfv, v = float(rng.normal()), float(rng.random())
        bad = [np.nan, np.inf, -np.inf][trial % 3]
        where = int(rng.integers(0, 7))
        if where == 0:
            u_nom[trial % 3] = bad
        elif where == 1 and k:
            g[int(rng.integers(0, k + 2)), trial % 3] = bad  # rows past k are not checked
        elif where == 2:
            rhs[int(rng.integers(0, k + 2))] = bad
        elif where == 3:
            lgv[trial % 3] = bad
        elif where == 4:
            lfv = bad
        elif where == 5:
            v = bad
        want = bool(np.isfinite(u_nom).all() and np.isfinite(rhs[:k]).all()
                    and np.isfinite(g[:k]).all() and np.isfinite(lgv).all()
                    and math.isfinite(lfv) and math.isfinite(v))
        assert rows_finite_kernel(u_nom, g, rhs, k, lgv, lfv, v) is want, trial
