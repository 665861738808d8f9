"""The pairwise safety barrier of the paper (eq. 9), the one formula that the load-time
checks, the in-flight monitor and the run's verdict evaluate:

    h = ‖Δp‖² + 2τ ΔvᵀΔp − D²   (m²)

with Δp = p_i − p_j (m), Δv = v_i − v_j (m/s), the look-ahead τ (s) and the safety
distance D (m). h ≥ 0 is the safe set. The sign of the pair's order cancels in both
products, so Δp = p_j − p_i, Δv = v_j − v_i give the same h.

With a vertical scale κ ≥ 1 (``controller.dcbf_vertical_scale``, docs/safety.md §4c) the
barrier is that of the scaled relative state S Δp, S Δv, S = diag(1, 1, 1/κ): at rest the
safe set is outside the ellipsoid of semi-axes (D, D, κD), because a quadrotor's downwash
makes a neighbour straight below unsafe at distances that are fine sideways.
"""

from __future__ import annotations

import numpy as np


def vertically_scaled(x: np.ndarray, vertical_scale: float) -> np.ndarray:
    """S x for the last axis of ``x`` (…, 3), S = diag(1, 1, 1/κ): a copy with the z
    component divided by κ = ``vertical_scale`` (x itself when κ = 1)."""
    if vertical_scale == 1.0:
        return x
    out = np.array(x, dtype=float, copy=True)
    out[..., 2] /= vertical_scale
    return out


def barrier(
    dp: np.ndarray, dv: np.ndarray, tau: float, d_safe: float, vertical_scale: float = 1.0,
) -> np.ndarray:
    """h (m²) over the last axis of the relative positions ``dp`` and velocities ``dv``
    (…, 3): any leading shape, one h per vector pair. ``vertical_scale`` κ ≥ 1: the
    barrier of S Δp, S Δv (module docstring); κ = 1, the paper's, computes exactly that."""
    if vertical_scale != 1.0:
        dp, dv = vertically_scaled(dp, vertical_scale), vertically_scaled(dv, vertical_scale)
    return np.sum(dp * dp, axis=-1) + 2.0 * tau * np.sum(dv * dp, axis=-1) - d_safe**2
