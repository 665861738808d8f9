"""The RCBF filter's rows of one step in one compiled call (``Method.RCBF``, paper §4.3–4.4,
Departures 12–13).

:func:`rcbf_rows_kernel` forms the rows ``n̂ᵀu ≥ r`` pair by pair;
:func:`rcbf_filter_rows_kernel` chains, in one call, what the filter used to do from
Python: the barrier (:func:`offboard.safety.pair_kernel.barrier_kernel`), the deadlock breaker
(:func:`offboard.safety.pair_kernel.tangential_kernel`), the budget share per pair and the rows.

The rows' 3-element dot products are summed left to right and ``h³`` is ``h·h·h``. The
numpy formulation they replaced (``einsum`` and ``h**3``) handed those to numpy's SIMD
loops, whose order of summation, and whose ``pow``, depend on the processor numpy finds;
so the rows now agree with it to rounding, not bit for bit, and are the same on every
machine (docs/performance.md, tenth round).
"""

from __future__ import annotations

import math

import numpy as np

from offboard.safety.pair_kernel import FULL_SHARE, SPLIT_SHARE, barrier_kernel, tangential_kernel
from swarm_common.jit import kernel

# layout of the parameter array (rcbf_params)
P_TAU = 0  # look-ahead τ of the barrier (s)
P_D_SAFE = 1  # safety distance D (m)
P_GAMMA = 2  # class-K gain γ of ḣ ≥ −γh³ (1/(m⁴ s))
P_MARGIN = 3  # tightening of every row against solver tolerance (m/s²)
P_SIDE_GAIN = 4  # deadlock breaker gain (m/s²)
P_SIDE_H = 5  # barrier value below which it acts (m²)
N_PARAMS = 6

RCBF_ROW_MARGIN = 1e-3  # m/s², the rows' default tightening (P_MARGIN)


def rcbf_params(
    tau_s: float, d_safe: float, gamma: float, side_gain: float, side_h: float,
    margin: float = RCBF_ROW_MARGIN,
) -> np.ndarray:
    """The parameter array of :func:`rcbf_filter_rows_kernel` (units at the ``P_*``)."""
    out = np.empty(N_PARAMS)
    out[P_TAU], out[P_D_SAFE], out[P_GAMMA] = tau_s, d_safe, gamma
    out[P_MARGIN], out[P_SIDE_GAIN], out[P_SIDE_H] = margin, side_gain, side_h
    return out


@kernel
def rcbf_rows_kernel(
    dp: np.ndarray, dv: np.ndarray, w_i: np.ndarray, a_other: np.ndarray, share: np.ndarray,
    h: np.ndarray, tau: float, gamma: float, margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(n̂ (M,3), r (M,)) of the rows ``n̂ᵀu ≥ r`` (Departures 12–13):
    ``2τΔpᵀ(u + w_i − a_j) ≥ −share·(2ΔpᵀΔv + 2τ‖Δv‖² + γh³)``, divided by 2τ‖Δp‖
    (‖Δp‖ floored at 1e-6 m) and tightened by ``margin`` (m/s²). Δp (m), Δv (m/s) rows;
    w_i (3,), a_other (M,3) (m/s²); share (M,); h (M,) the barrier (m²); τ (s)."""
    m = dp.shape[0]
    n_hat = np.empty((m, 3))
    rhs = np.empty(m)
    two_tau = 2.0 * tau
    for i in range(m):
        px, py, pz = dp[i, 0], dp[i, 1], dp[i, 2]
        vx, vy, vz = dv[i, 0], dv[i, 1], dv[i, 2]
        base = 2.0 * (px * vx + py * vy + pz * vz) + two_tau * (vx * vx + vy * vy + vz * vz)
        base += gamma * (h[i] * h[i] * h[i])
        nrm = max(math.sqrt(px * px + py * py + pz * pz), 1e-6)
        nx, ny, nz = px / nrm, py / nrm, pz / nrm
        n_hat[i, 0], n_hat[i, 1], n_hat[i, 2] = nx, ny, nz
        offset = (nx * (w_i[0] - a_other[i, 0]) + ny * (w_i[1] - a_other[i, 1])
                  + nz * (w_i[2] - a_other[i, 2]))
        rhs[i] = -share[i] * base / (two_tau * nrm) - offset + margin
    return n_hat, rhs


@kernel
def rcbf_filter_rows_kernel(
    dp: np.ndarray, dv: np.ndarray, lead: np.ndarray, a_other: np.ndarray, w_safe: np.ndarray,
    params: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(n̂, r, h, sidestep) of one RCBF step. ``lead`` (M,) bool: the other is a leader
    (the whole budget, ``FULL_SHARE``; else ``SPLIT_SHARE``, of
    :mod:`offboard.safety.pair_kernel`); a_other (M,3)
    its acceleration taken as known (m/s²); w_safe (3,) the own disturbance estimate,
    saturated (m/s²); ``params`` of :func:`rcbf_params`."""
    m = dp.shape[0]
    h = barrier_kernel(dp, dv, params[P_TAU], params[P_D_SAFE])
    side = np.zeros(3)
    if m > 0:
        side = tangential_kernel(dp, h, params[P_SIDE_GAIN], params[P_SIDE_H])
    share = np.empty(m)
    for i in range(m):
        share[i] = FULL_SHARE if lead[i] else SPLIT_SHARE
    n_hat, rhs = rcbf_rows_kernel(dp, dv, w_safe, a_other, share, h, params[P_TAU],
                                  params[P_GAMMA], params[P_MARGIN])
    return n_hat, rhs, h, side
