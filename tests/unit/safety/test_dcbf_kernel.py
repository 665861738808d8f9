"""The compiled DCBF rows (offboard.safety.dcbf.kernel) against the numpy formulation they
replaced, on random pairs: the same rows to rounding (the kernel cubes by products and sums
gᵀu_ref left to right, where numpy used its vectorised power and BLAS), so the compiled
filter is the same filter.

The oracle below is the previous numpy implementation of ``dcbf_rows`` kept verbatim (vector
operations over all pairs at once, ``einsum`` dot products, ``@`` for gᵀu_ref); the gradient
of the rows against finite differences of the lag model is in test_dcbf.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from reference.close import assert_close
from reference.dcbf_rows import dcbf_rows, ground_rows, predict

from offboard.safety.dcbf.kernel import other_term_kernel, rows_hold_kernel
from offboard.safety.dcbf.model import LagCoefficients
from offboard.safety.dcbf.model import ProjectedInputSet as InputSet

TAU = np.array([0.15, 0.15, 0.03])


def _norm(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", x, x))


def rows_numpy(
    dp: np.ndarray, dv: np.ndarray, a0: np.ndarray, u_ref: np.ndarray, a_other: np.ndarray,
    share: np.ndarray, lag: LagCoefficients, tau_s: float, d_safe: float | np.ndarray,
    gamma1: float, gamma3: float, accel_err: float,
) -> tuple[np.ndarray, np.ndarray]:
    pr = predict(dp, dv, a0, u_ref, a_other, lag, tau_s, d_safe)
    h0 = (np.einsum("ij,ij->i", dp, dp) + 2.0 * tau_s * np.einsum("ij,ij->i", dv, dp)
          - d_safe**2)
    cp, cv, ca = lag.sens[0], lag.sens[1], lag.sens[2]
    hd_both = 2.0 * (cp * pr.dv + cv * pr.dp) + 2.0 * tau_s * (
        2.0 * cv * pr.dv + cp * pr.da + ca * pr.dp
    )
    h_both = 2.0 * cp * pr.dp + 2.0 * tau_s * (cv * pr.dp + cp * pr.dv)
    e_hd, u_hd, e_h, u_h = hd_both[0], hd_both[1], h_both[0], h_both[1]
    m_h = _norm(e_h) * accel_err
    h_lo = pr.h - m_h
    k_h = (gamma1 + 3.0 * gamma3 * h_lo**2)[:, None]
    c1 = pr.hdot - _norm(e_hd) * accel_err + gamma1 * h_lo + gamma3 * h_lo**3
    drop = lag.T * (gamma1 * h0 + gamma3 * h0**3)
    drop = np.where(h0 > 0.0, np.minimum(drop, 0.5 * h0), drop)
    c2 = pr.h - m_h - (h0 - drop)
    g = np.concatenate([u_hd + k_h * u_h, u_h])
    c = np.concatenate([c1, c2])
    sh = np.concatenate([share, share])
    nrm = np.maximum(_norm(g), 1e-9)
    return g / nrm[:, None], (g @ u_ref - sh * c) / nrm


@pytest.mark.parametrize("per_pair_distance", [False, True])
def test_compiled_rows_equal_numpy_rows(per_pair_distance: bool) -> None:
    rng = np.random.default_rng(11)
    lag = LagCoefficients.of(TAU, 0.15 + 0.02)
    for trial in range(300):
        m = int(rng.integers(0, 9))
        # pairs from touching (h0 < 0) to far, closing and opening
        dp = rng.normal(0.0, 2.0, (m, 3)) * rng.uniform(0.1, 2.0)
        dv = rng.normal(0.0, 1.5, (m, 3))
        a0, u_ref = rng.normal(0.0, 3.0, 3), rng.normal(0.0, 3.0, 3)
        a_other = rng.normal(0.0, 2.0, (m, 3))
        share = rng.choice([0.5, 1.0], m)
        d_safe: float | np.ndarray = (
            rng.uniform(0.5, 1.5, m) if per_pair_distance else 1.0
        )
        args = (dp, dv, a0, u_ref, a_other, share, lag, 0.5, d_safe, 1.0, 0.05,
                float(rng.uniform(0.0, 1.0)))
        g, rhs = dcbf_rows(*args)
        g_ref, rhs_ref = rows_numpy(*args)
        assert g.shape == (2 * m, 3) and rhs.shape == (2 * m,), trial
        assert np.allclose(g, g_ref, rtol=1e-12, atol=1e-12), trial
        assert np.allclose(rhs, rhs_ref, rtol=1e-11, atol=1e-11), trial


def test_degenerate_row_keeps_the_numpy_guard() -> None:
    """A pair whose rows have no gradient (zero lag sensitivity) gives g = 0 rows scaled by
    the 1e-9 floor, as before, not nan."""
    lag = LagCoefficients.of(TAU, 0.0)  # horizon 0: the command cannot act yet
    dp, dv = np.array([[2.0, 0.0, 0.0]]), np.zeros((1, 3))
    args = (dp, dv, np.zeros(3), np.zeros(3), np.zeros((1, 3)), np.ones(1), lag, 0.5, 1.0,
            1.0, 0.05, 0.3)
    g, rhs = dcbf_rows(*args)
    g_ref, rhs_ref = rows_numpy(*args)
    assert np.isfinite(g).all() and np.isfinite(rhs).all()
    assert_close(g, g_ref)  # two implementations: within rounding (close.py)
    assert_close(rhs, rhs_ref)


class _OtherTermNumpy:
    """The previous numpy ``DcbfFilter._other_term`` with its per-index state."""

    def __init__(self, n: int, dt: float, smooth: float) -> None:
        self.dt, self.smooth = dt, smooth
        self.prev_dv, self.prev_ok = np.zeros((n, 3)), np.zeros(n, dtype=bool)
        self.rel_acc, self.rel_ok = np.zeros((n, 3)), np.zeros(n, dtype=bool)

    def __call__(self, pairs: np.ndarray, predicted: np.ndarray, dv: np.ndarray,
                 other: np.ndarray, w_safe: np.ndarray, a_mean: np.ndarray) -> np.ndarray:
        n = len(pairs)
        out = other.copy() - w_safe
        rows = (~predicted).nonzero()[0]
        js = pairs[rows]
        have = self.prev_ok[js]
        self.rel_ok[js[~have]] = False
        r_h, j_h = rows[have], js[have]
        if len(r_h):
            da = (dv[r_h] - self.prev_dv[j_h]) / self.dt
            old_ok = self.rel_ok[j_h]
            smooth = self.smooth * self.rel_acc[j_h] + (1.0 - self.smooth) * da
            da = np.where(old_ok[:, None], smooth, da)
            self.rel_acc[j_h] = da
            self.rel_ok[j_h] = True
            out[r_h] = a_mean - da
        self.prev_ok[:] = False
        self.prev_ok[js] = True
        self.prev_dv[js] = dv[rows]
        assert out.shape == (n, 3)
        return out


def test_other_term_kernel_equals_numpy_over_a_run_of_steps() -> None:
    """40 steps of random pair sets (gaps, predicted rows) through both implementations:
    the same output and the same state (the flags exactly, the floats within rounding,
    tests/reference/close.py: two implementations)."""
    n, dt, smooth = 9, 0.02, 0.5
    ref = _OtherTermNumpy(n, dt, smooth)
    prev_dv, prev_ok = np.zeros((n, 3)), np.zeros(n, dtype=bool)
    rel_acc, rel_ok = np.zeros((n, 3)), np.zeros(n, dtype=bool)
    rng = np.random.default_rng(7)
    for step in range(40):
        pairs = np.sort(rng.choice(np.arange(1, n), int(rng.integers(0, n)), replace=False))
        m = len(pairs)
        predicted = rng.random(m) < 0.2
        dv, other = rng.normal(0, 1, (m, 3)), rng.normal(0, 2, (m, 3))
        w_safe, a_mean = rng.normal(0, 0.3, 3), rng.normal(0, 2, 3)
        got = other_term_kernel(pairs.astype(np.int64), predicted, dv, other, w_safe, a_mean,
                                dt, smooth, prev_dv, prev_ok, rel_acc, rel_ok)
        want = ref(pairs, predicted, dv, other, w_safe, a_mean)
        assert_close(got, want, step)
        assert np.array_equal(prev_ok, ref.prev_ok) and np.array_equal(rel_ok, ref.rel_ok)
        assert_close(prev_dv[prev_ok], ref.prev_dv[prev_ok], step)
        assert_close(rel_acc[rel_ok], ref.rel_acc[rel_ok], step)


def test_rows_hold_kernel_is_the_qp_shortcut_test() -> None:
    rng = np.random.default_rng(8)
    a_u = rng.normal(0, 1, (11, 3))
    lo, hi = -np.abs(rng.normal(3, 1, 11)), np.abs(rng.normal(3, 1, 11))
    lo[3] = -np.inf
    for _ in range(2000):
        k = int(rng.integers(0, 5))
        g, rhs, u = rng.normal(0, 1, (k + 2, 3)), rng.normal(-1, 1, k + 2), rng.normal(0, 1, 3)
        want = bool(((a_u @ u <= hi) & (a_u @ u >= lo)).all() and (g[:k] @ u >= rhs[:k]).all())
        # BLAS and left-to-right sums may differ in the last bit at an exact tie only
        assert rows_hold_kernel(a_u, lo, hi, g, rhs, k, u) == want


def project_numpy(uset: InputSet, u: np.ndarray) -> np.ndarray:
    """The numpy formulation ``InputSet.project`` had before it was compiled."""
    out = np.array(u, dtype=float)
    s = uset.shrink
    out[2] = min(max(out[2], uset.uz_min + s), uset.uz_max - s)
    out[0:2] = np.clip(out[0:2], -uset.uh_max + s, uset.uh_max - s)
    k = uset.sides
    c = uset.tan_tilt * math.cos(math.pi / k)
    r = (uset.g + out[2]) * c - s
    ang = 2.0 * math.pi * np.arange(k) / k
    worst = float((np.cos(ang) * out[0] + np.sin(ang) * out[1]).max())
    if worst > r:
        out[0:2] *= max(r, 0.0) / worst
    return out


def test_input_set_projection_kernel_equals_the_numpy_formulation() -> None:
    """InputSet.project (compiled) equals its former numpy formulation (within rounding,
    tests/reference/close.py: two implementations) on
    points inside, outside and on the edges of the set, for several cone sides, and on
    non-finite points (NaN and inf treated as numpy treats them); a finite result is in
    the set."""
    rng = np.random.default_rng(21)
    for sides in (3, 8, 16):
        uset = InputSet.from_vehicle(1.5, 9.81, 30.0, 35.0, 8.0, sides)
        pts = list(rng.normal(0.0, 6.0, (300, 3))) + list(rng.normal(0.0, 0.5, (100, 3)))
        pts += [np.array([uset.uh_max, -uset.uh_max, uset.uz_max]),
                np.array([0.0, 0.0, uset.uz_min - 5.0]), np.zeros(3)]
        for u in pts:
            got = uset.project(u)
            assert_close(got, project_numpy(uset, u), (sides, u))
            assert uset.contains(got, tol=1e-12)
        for bad in ([np.nan, 0.0, 0.0], [0.0, np.inf, 1.0], [1.0, 2.0, -np.inf],
                    [np.inf, -np.inf, np.nan]):
            u = np.array(bad)
            assert_close(uset.project(u), project_numpy(uset, u), bad)  # nan where numpy's


def ground_rows_numpy(z: float, vz: float, a0z: float, wz: float, floor: float,
                      lag: LagCoefficients, tau_s: float, gamma1: float,
                      accel_err: float) -> tuple[np.ndarray, np.ndarray]:
    """The numpy formulation ``ground_rows`` (tests/reference/dcbf_rows.py) had before it was
    compiled."""
    t, k = lag.T, 2
    z_free = z + vz * t + lag.iia[k] * a0z + 0.5 * wz * t * t
    v_free = vz + lag.ia[k] * a0z + wz * t
    a_free = lag.ea[k] * a0z + wz
    cz, cv, ca = float(lag.cp[k]), float(lag.cv[k]), float(lag.ca[k])
    h_free = z_free - floor + tau_s * v_free
    m_h = accel_err * (0.5 * t * t + tau_s * t)
    h0 = z - floor + tau_s * vz
    drop = t * gamma1 * h0
    drop = min(drop, 0.5 * h0) if h0 > 0.0 else drop
    k1 = cv + tau_s * ca + gamma1 * (cz + tau_s * cv)
    r1 = -(v_free + tau_s * a_free - accel_err * (t + tau_s) + gamma1 * (h_free - m_h)) / k1
    k2 = cz + tau_s * cv
    r2 = (h0 - drop - (h_free - m_h)) / k2
    g = np.zeros((2, 3))
    g[:, 2] = 1.0
    return g, np.array([r1, r2])


def test_ground_rows_kernel_equals_the_numpy_formulation() -> None:
    """Within rounding (tests/reference/close.py: two implementations)."""
    rng = np.random.default_rng(22)
    for _ in range(400):
        lag = LagCoefficients.of(rng.uniform(0.05, 0.4, 3), rng.uniform(0.05, 0.5))
        args = (float(rng.uniform(-0.5, 4.0)), float(rng.normal(0, 2)), float(rng.normal(0, 3)),
                float(rng.normal(0, 1)), float(rng.uniform(0.1, 1.0)), lag,
                float(rng.uniform(0.1, 1.0)), float(rng.uniform(0.5, 5.0)),
                float(rng.uniform(0.0, 2.0)))
        g, r = ground_rows(*args)
        g0, r0 = ground_rows_numpy(*args)
        assert_close(g, g0, args)
        assert_close(r, r0, args)
