"""The compiled per-pair terms (offboard.safety.pair_kernel) against their numpy formulations.

The oracles are the previous numpy implementations, kept verbatim. The kernels sum dot
products left to right, ``einsum`` and BLAS in their own orders: equal to rounding.
"""

from __future__ import annotations

import math

import numpy as np

from offboard.safety.rcbf.clf_rcbf import barrier, tangential_term


def barrier_numpy(dp: np.ndarray, dv: np.ndarray, tau: float, d_safe: float) -> np.ndarray:
    return (np.einsum("ij,ij->i", dp, dp) + 2.0 * tau * np.einsum("ij,ij->i", dv, dp)
            - d_safe**2)


def tangential_numpy(dp: np.ndarray, h: np.ndarray, gain: float, h_on: float) -> np.ndarray:
    out = np.zeros(3)
    if gain <= 0.0 or len(h) == 0:
        return out
    for k in np.nonzero(h < h_on)[0]:
        wgt = min(1.0 - float(h[k]) / h_on, 1.0)
        nx, ny, nz = (float(c) for c in dp[k])
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nn < 1e-9:
            continue
        t = np.array([0.0, nz, -ny]) if abs(nz) > 0.9 * nn else np.array([ny, -nx, 0.0])
        out += (gain * wgt / max(float(np.sqrt(t @ t)), 1e-9)) * t
    return out


def test_barrier_equals_numpy() -> None:
    rng = np.random.default_rng(5)
    for m in range(0, 12):
        dp, dv = rng.normal(0, 2, (m, 3)), rng.normal(0, 1, (m, 3))
        assert np.allclose(barrier(dp, dv, 0.5, 1.0), barrier_numpy(dp, dv, 0.5, 1.0),
                           rtol=1e-13, atol=1e-13)
    # a non-contiguous view and a float32 input are accepted (copied for the kernel)
    big = rng.normal(0, 2, (6, 6))
    assert np.allclose(barrier(big[:, ::2], big[:, 1::2], 0.3, 1.2),
                       barrier_numpy(big[:, ::2], big[:, 1::2], 0.3, 1.2), rtol=1e-13)
    f32 = rng.normal(0, 2, (4, 3)).astype(np.float32)
    assert np.allclose(barrier(f32, f32, 0.3, 1.2),
                       barrier_numpy(f32.astype(float), f32.astype(float), 0.3, 1.2), rtol=1e-13)


def test_tangential_term_equals_numpy() -> None:
    rng = np.random.default_rng(6)
    for trial in range(300):
        m = int(rng.integers(0, 8))
        dp = rng.normal(0, 1.5, (m, 3))
        if m and trial % 5 == 0:
            dp[0] = [0.01, 0.0, 1.0]  # nearly vertical: the e_x branch
        if m > 1 and trial % 7 == 0:
            dp[1] = 0.0  # coincident: skipped
        h = barrier_numpy(dp, rng.normal(0, 1, (m, 3)), 0.5, 1.0)
        gain = float(rng.choice([0.0, 1.0, 2.5]))
        got = tangential_term(dp, h, gain, 3.0)
        ref = tangential_numpy(dp, h, gain, 3.0)
        assert np.allclose(got, ref, rtol=1e-13, atol=1e-13), trial
    # the push is sideways: orthogonal to every active Δp when one pair is active
    dp = np.array([[1.0, 0.2, 0.1]])
    side = tangential_term(dp, np.array([0.5]), 1.0, 3.0)
    assert abs(float(side @ dp[0])) < 1e-12 and np.linalg.norm(side) > 0.5
