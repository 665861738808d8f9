"""Compiled per-pair terms every safety filter uses: the barrier h_ij (§2.3, §4.3) and the
tangential deadlock breaker (:func:`offboard.safety.rcbf.clf_rcbf.tangential_term`).

Pair by pair in one compiled loop, with the operations of the numpy formulations they
replaced; 3-element dot products are summed left to right (numpy's ``einsum`` loop sums in
another order), so the two agree to rounding (``tests/unit/safety/test_pair_kernel.py``).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel

# the share of a pair's avoidance budget one agent takes (§4.4, Departure 13): all of it
# where the other does not share it (a leader, or an agent that no longer cooperates),
# else half (follower–follower pairs split it)
FULL_SHARE = 1.0
SPLIT_SHARE = 0.5


@kernel
def pair_h(d0: float, d1: float, d2: float, w0: float, w1: float, w2: float,
           two_tau: float, dd: float) -> float:
    """h = ‖Δp‖² + 2τ ΔvᵀΔp − D² (m²) of one pair: Δp = (d0, d1, d2) (m), Δv = (w0, w1,
    w2) (m/s), ``two_tau`` = 2τ (s), ``dd`` = D² (m²); the sums left to right, as numpy's
    sum over a row of three."""
    pp = d0 * d0 + d1 * d1 + d2 * d2
    vp = w0 * d0 + w1 * d1 + w2 * d2
    return pp + two_tau * vp - dd


@kernel
def barrier_kernel(dp: np.ndarray, dv: np.ndarray, tau: float, d_safe: float) -> np.ndarray:
    """h_ij = ‖Δp‖² + 2τ ΔvᵀΔp − D² (m²) per row of Δp (m), Δv (m/s); τ (s), D (m)."""
    m = dp.shape[0]
    h = np.empty(m)
    two_tau = 2.0 * tau
    dd = d_safe**2
    for i in range(m):
        h[i] = pair_h(dp[i, 0], dp[i, 1], dp[i, 2], dv[i, 0], dv[i, 1], dv[i, 2], two_tau, dd)
    return h


@kernel
def tangential_kernel(dp: np.ndarray, h: np.ndarray, gain: float, h_on: float) -> np.ndarray:
    """Σ over pairs with h < h_on of ``gain·min(1 − h/h_on, 1)·t̂`` (m/s²), t̂ = Δp × e_z
    normalised (Δp × e_x when Δp is within ≈ 26° of vertical); pairs with ‖Δp‖ < 1e-9 m
    are skipped."""
    out = np.zeros(3)
    if gain <= 0.0:
        return out
    for k in range(h.shape[0]):
        if not h[k] < h_on:
            continue
        wgt = min(1.0 - h[k] / h_on, 1.0)
        nx, ny, nz = dp[k, 0], dp[k, 1], dp[k, 2]
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nn < 1e-9:
            continue
        if abs(nz) > 0.9 * nn:  # t = n × e_x
            t0, t1, t2 = 0.0, nz, -ny
        else:  # t = n × e_z
            t0, t1, t2 = ny, -nx, 0.0
        s = gain * wgt / max(math.sqrt(t0 * t0 + t1 * t1 + t2 * t2), 1e-9)
        out[0] += s * t0
        out[1] += s * t1
        out[2] += s * t2
    return out
