"""The pairwise safety barrier of the paper (eq. 9), the one formula that the load-time
checks, the in-flight monitor and the run's verdict evaluate:

    h = ‖Δp‖² + 2τ ΔvᵀΔp − D²   (m²)

with Δp = p_i − p_j (m), Δv = v_i − v_j (m/s), the look-ahead τ (s) and the safety
distance D (m). h ≥ 0 is the safe set. The sign of the pair's order cancels in both
products, so Δp = p_j − p_i, Δv = v_j − v_i give the same h.
"""

from __future__ import annotations

import numpy as np


def barrier(dp: np.ndarray, dv: np.ndarray, tau: float, d_safe: float) -> np.ndarray:
    """h (m²) over the last axis of the relative positions ``dp`` and velocities ``dv``
    (…, 3): any leading shape, one h per vector pair."""
    return np.sum(dp * dp, axis=-1) + 2.0 * tau * np.sum(dv * dp, axis=-1) - d_safe**2
