"""The compiled DCBF rows (offboard.dcbf_kernel) against the numpy formulation they
replaced, on random pairs: the same rows to rounding (the kernel cubes by products and sums
gᵀu_ref left to right, where numpy used its vectorised power and BLAS), so the compiled
filter is the same filter.

The oracle below is the previous numpy implementation of ``dcbf_rows`` kept verbatim (vector
operations over all pairs at once, ``einsum`` dot products, ``@`` for gᵀu_ref); the gradient
of the rows against finite differences of the lag model is in test_dcbf.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from offboard.dcbf import LagCoefficients, dcbf_rows, predict

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
    assert np.array_equal(g, g_ref) and np.allclose(rhs, rhs_ref, rtol=1e-12, atol=1e-12)
