"""The DESO's adaptive model (paper §2.2 and §3; Departures 5 and 8; docs/estimation.md):
the unmodeled-dynamics model Φ(z1, z2) ζ̂ the observer integrates, the regressor product
Φᵀe2 that drives ζ̂, and one period of the projected, normalised adaptive law. Functions
over numpy arrays (m, m/s, m/s²); the arithmetic is the compiled kernels of
:mod:`offboard.estimation.deso_kernel` (which also define the limits, re-exported here), so the
observer and these entry points compute the same bits.
"""

from __future__ import annotations

import numpy as np

from offboard.estimation.deso_kernel import (
    F_HAT_MAX,
    V_EVAL_MAX,
    ZETA_HI,
    ZETA_LO,
    adapt_step_kernel,
    model_accel_kernel,
    observer_regressor_t_times,
)
from swarm_common.fastnp import f64

__all__ = [
    "F_HAT_MAX", "V_EVAL_MAX", "ZETA_BOUND", "ZETA_HI", "ZETA_LO", "adapt_step", "model_accel",
    "regressor_t_times",
]

ZETA_BOUND = float(np.linalg.norm(np.maximum(-ZETA_LO, ZETA_HI)))  # ‖ζ̂‖ in the box (2.55)


def model_accel(z1: np.ndarray, z2: np.ndarray, zeta: np.ndarray, h: float) -> np.ndarray:
    """f̂ = Φ(z1, z2) ζ̂ without building Φ (fast path of :func:`regressor`), with ‖v‖
    saturated to V_EVAL_MAX and ‖f̂‖ to F_HAT_MAX (m/s²)."""
    return model_accel_kernel(f64(z1), f64(z2), f64(zeta), float(h))


def regressor_t_times(
    z1: np.ndarray, z2: np.ndarray, e: np.ndarray, h: float
) -> tuple[np.ndarray, float]:
    """(Φᵀ e (6,), ‖Φ‖_F²) without building Φ (‖v‖ saturated like :func:`model_accel`)."""
    phte, fro2 = observer_regressor_t_times(f64(z1), f64(z2), f64(e), float(h))
    return phte, float(fro2)


def adapt_step(
    zeta: np.ndarray, phte: np.ndarray, fro2: float, mu: float, sigma: float, dt: float
) -> np.ndarray:
    """One period of the adaptive law (paper §3, Departures 5 and 8; docs/estimation.md)::

        ζ̂⁺ = Π_box( ζ̂ − dt μ [ Φᵀe2 / (1 + ‖Φ‖_F²) + σ ζ̂ ] )

    Normalised gradient with σ-modification, projected (per component, which is the
    Euclidean projection onto a box) onto [ZETA_LO, ZETA_HI]. Whatever e2 and Φ are,
    ‖Φᵀe2‖/(1 + ‖Φ‖²) ≤ ‖e2‖/2, so one step moves ζ̂ by at most dt μ (‖e2‖/2 + σ‖ζ̂‖)
    and ζ̂ never leaves the box. A step that is not finite leaves ζ̂ as it is (a copy).
    """
    return adapt_step_kernel(
        f64(zeta), f64(phte), float(fro2), float(mu), float(sigma), float(dt)
    )
