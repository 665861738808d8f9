"""The unmodeled-dynamics model f̃ = Φ(p, v) ζ (paper §2.2): one definition.

The simulator integrates it with the true per-vehicle ζ; the DESO's adaptive law
(paper §3) estimates ζ̂ with the same regressor. Both sides must agree on Φ, so it lives
here, with the other shared definitions: :func:`regressor`, the matrix (numpy, for the
feasibility bounds and the tests), and the two products the per-step kernels need,
compiled in :mod:`swarm_common.unmodeled_kernel`: ``unmodeled_accel_kernel`` (Φ ζ, the
simulator's physics and the observer's model) and ``regressor_t_times_kernel`` (Φᵀ e and
‖Φ‖_F², the adaptive law).
"""

from __future__ import annotations

import numpy as np

N_ZETA = 6


def regressor(p: np.ndarray, v: np.ndarray, ground_effect_height: float) -> np.ndarray:
    """Φ(p, v): (..., 3, 6) regressor of the unmodeled dynamics f̃ = Φ ζ (paper §2.2).

    Columns: constant bias (1,1,1); linear drag −v; quadratic drag −‖v‖v;
    nonlinear (cubic) damping −v∘v∘v; ground effect exp(−z/h) e_z; cross-coupling e_z × v.
    """
    p = np.asarray(p, dtype=float)
    v = np.asarray(v, dtype=float)
    shape = np.broadcast_shapes(p.shape, v.shape)
    out = np.zeros((*shape[:-1], 3, N_ZETA))
    out[..., :, 0] = 1.0
    out[..., :, 1] = -v
    out[..., :, 2] = -np.linalg.norm(v, axis=-1, keepdims=True) * v
    out[..., :, 3] = -(v**3)
    out[..., 2, 4] = np.exp(-np.maximum(p[..., 2], 0.0) / ground_effect_height)
    out[..., 0, 5] = -v[..., 1]
    out[..., 1, 5] = v[..., 0]
    return out
