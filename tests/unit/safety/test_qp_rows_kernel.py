"""The safety QPs' compiled data bookkeeping (offboard.safety.qp_rows_kernel) against the numpy
slice assignments and finiteness tests it replaced, on random rows: the same matrix,
bounds and cost (nan and inf included) within rounding (tests/reference/close.py: two
implementations), DAQP's copy without the unused rows, and the same guard verdicts; and
DAQP's answer on that copy against its answer on the whole problem."""

from __future__ import annotations

import math

import numpy as np
from reference.close import assert_close

from offboard.safety.qp_rows_kernel import rows_finite_kernel, write_rows_kernel
from offboard.safety.solvers.daqp_call import DAQP_INF, daqp_solve


def _write_numpy(
    a: np.ndarray, lo: np.ndarray, hi: np.ndarray, q: np.ndarray, lgv: np.ndarray,
    nrm: float, clf_rhs: float, g: np.ndarray, rhs: np.ndarray, k: int, m: int,
    u_nom: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The previous ``_ClfRowsQP._solve_rows`` writes, and DAQP's copy: the rows but the
    unused k+1..m, their bounds clamped."""
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
    keep = np.r_[0 : k + 1, m + 1 : len(lo)]
    return a[keep], np.maximum(lo[keep], -DAQP_INF), np.minimum(hi[keep], DAQP_INF)


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
        a_c_want, lo_c_want, hi_c_want = _write_numpy(want[0], want[1], want[2], want[3],
                                                      lgv, nrm, clf_rhs, g, rhs, k, m, u_nom)
        got = [a0.copy(), lo0.copy(), hi0.copy(), q0.copy()]
        a_c, lo_c, hi_c = np.full((rows, 5), 7.0), np.full(rows, 7.0), np.full(rows, 7.0)
        n = write_rows_kernel(got[0], got[1], got[2], got[3], lgv, nrm, clf_rhs, g, rhs, k,
                              m, u_nom, a_c, lo_c, hi_c, DAQP_INF)
        for x, y in zip(got, want, strict=True):
            assert_close(x, y, trial)
        assert n == rows - (m - k), trial
        assert_close(a_c[:n], a_c_want, trial)
        assert_close(lo_c[:n], lo_c_want, trial)
        assert_close(hi_c[:n], hi_c_want, trial)
        assert (a_c[n:] == 7.0).all() and (lo_c[n:] == 7.0).all(), trial  # nothing past n


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


def test_daqp_answers_the_copy_as_the_whole_problem() -> None:
    """The unused rows bound nothing: DAQP finds the same optimum (or the same failure)
    without them, on problems shaped as the dcbf QP's (a CLF row, k unit barrier rows with
    σ, m − k unused, the input rows, σ ≥ 0), many with rows active."""
    rng = np.random.default_rng(44)
    h = np.diag([1.0, 1.0, 1.0, 20.0, 2000.0])
    active = 0
    for trial in range(3000):
        k, nu = int(rng.integers(0, 40)), int(rng.integers(3, 12))
        m = k + int(rng.integers(0, 100))
        rows = 1 + m + nu + 1
        a, lo, hi = np.zeros((rows, 5)), np.full(rows, -np.inf), np.full(rows, np.inf)
        q = np.zeros(5)
        lgv = rng.normal(size=3)
        g = rng.normal(size=(k, 3))
        g /= np.linalg.norm(g, axis=1)[:, None]
        a[1 : 1 + m, 4] = 1.0
        a[1 + m : 1 + m + nu, 0:3] = rng.normal(size=(nu, 3))
        lo[1 + m : 1 + m + nu], hi[1 + m : 1 + m + nu] = -8.0, 8.0
        a[rows - 1, 4], lo[rows - 1], q[4] = 1.0, 0.0, 1000.0
        a_c, lo_c, hi_c = np.empty((rows, 5)), np.empty(rows), np.empty(rows)
        n = write_rows_kernel(a, lo, hi, q, lgv, float(np.linalg.norm(lgv)),
                              float(rng.normal()), g, rng.normal(size=k) * 2.0, k, m,
                              rng.normal(size=3) * 3.0, a_c, lo_c, hi_c, DAQP_INF)
        whole = daqp_solve(h, q, a, lo, hi)
        copy = daqp_solve(h, q, a_c[:n], lo_c[:n], hi_c[:n], clamped=True)
        assert (whole is None) == (copy is None), trial
        if whole is not None and copy is not None:
            assert_close(copy, whole, trial)
            active += int(np.any(a[: 1 + k, 0:3] @ whole[0:3] < lo[: 1 + k] + 1e-9))
    assert active > 300  # the rows bound the answer in a good share of the problems
