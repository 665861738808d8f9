"""The DESO's adaptive model (paper §2.2 and §3; Departures 5 and 8; docs/estimation.md):
the unmodeled-dynamics model Φ(z1, z2) ζ̂ the observer integrates, the regressor product
Φᵀe2 that drives ζ̂, and one period of the projected, normalised adaptive law. Pure
functions over numpy arrays (m, m/s, m/s²).
"""

from __future__ import annotations

import math

import numpy as np

# Adaptive law (docs/estimation.md): ζ̂ stays in a box of physically meaningful values
# (bias, drag ≥ 0, cubic damping ≥ 0, ground effect ≥ 0, cross-coupling), m/s² per unit
ZETA_LO = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, -1.0])
ZETA_HI = np.array([1.0, 1.0, 0.5, 0.1, 2.0, 1.0])
ZETA_BOUND = float(np.linalg.norm(np.maximum(-ZETA_LO, ZETA_HI)))  # ‖ζ̂‖ in the box (2.55)
V_EVAL_MAX = 10.0  # m/s, speed at which Φ is evaluated (norm saturated; physical max speed)
F_HAT_MAX = 3.0  # m/s², ‖f̂‖ = ‖Φζ̂‖ used inside the observer model is saturated to this


def _v_eval(z2: np.ndarray) -> tuple[float, float, float]:
    """Velocity at which Φ is evaluated: ``z2`` with its norm saturated to V_EVAL_MAX."""
    vx, vy, vz = (float(c) for c in z2)
    nv = math.sqrt(vx * vx + vy * vy + vz * vz)
    if not math.isfinite(nv):
        return 0.0, 0.0, 0.0
    if nv > V_EVAL_MAX:
        s = V_EVAL_MAX / nv
        return vx * s, vy * s, vz * s
    return vx, vy, vz


def model_accel(z1: np.ndarray, z2: np.ndarray, zeta: np.ndarray, h: float) -> np.ndarray:
    """f̂ = Φ(z1, z2) ζ̂ without building Φ (fast path of :func:`regressor`), with ‖v‖
    saturated to V_EVAL_MAX and ‖f̂‖ to F_HAT_MAX (m/s²)."""
    vx, vy, vz = _v_eval(z2)
    z0, z1_, z2_, z3_, z4, z5 = (float(c) for c in zeta)
    nv = math.sqrt(vx * vx + vy * vy + vz * vz)
    ge = math.exp(-max(float(z1[2]), 0.0) / h)
    k = z1_ + z2_ * nv
    fx = z0 - k * vx - z3_ * vx**3 - z5 * vy
    fy = z0 - k * vy - z3_ * vy**3 + z5 * vx
    fz = z0 - k * vz - z3_ * vz**3 + z4 * ge
    nf = math.sqrt(fx * fx + fy * fy + fz * fz)
    if nf > F_HAT_MAX:
        s = F_HAT_MAX / nf
        fx, fy, fz = fx * s, fy * s, fz * s
    return np.array([fx, fy, fz])


def regressor_t_times(
    z1: np.ndarray, z2: np.ndarray, e: np.ndarray, h: float
) -> tuple[np.ndarray, float]:
    """(Φᵀ e (6,), ‖Φ‖_F²) without building Φ (‖v‖ saturated like :func:`model_accel`)."""
    vx, vy, vz = _v_eval(z2)
    ex, ey, ez = float(e[0]), float(e[1]), float(e[2])
    v2 = vx * vx + vy * vy + vz * vz
    nv = math.sqrt(v2)
    ve = vx * ex + vy * ey + vz * ez
    ge = math.exp(-max(float(z1[2]), 0.0) / h)
    phte = np.array(
        [ex + ey + ez, -ve, -nv * ve, -(vx**3 * ex + vy**3 * ey + vz**3 * ez), ge * ez,
         -vy * ex + vx * ey]
    )
    fro2 = 3.0 + v2 + v2 * v2 + (vx**6 + vy**6 + vz**6) + ge * ge + vx * vx + vy * vy
    return phte, fro2


def adapt_step(
    zeta: np.ndarray, phte: np.ndarray, fro2: float, mu: float, sigma: float, dt: float
) -> np.ndarray:
    """One period of the adaptive law (paper §3, Departures 5 and 8; docs/estimation.md)::

        ζ̂⁺ = Π_box( ζ̂ − dt μ [ Φᵀe2 / (1 + ‖Φ‖_F²) + σ ζ̂ ] )

    Normalised gradient with σ-modification, projected (per component, which is the
    Euclidean projection onto a box) onto [ZETA_LO, ZETA_HI]. Whatever e2 and Φ are,
    ‖Φᵀe2‖/(1 + ‖Φ‖²) ≤ ‖e2‖/2, so one step moves ζ̂ by at most dt μ (‖e2‖/2 + σ‖ζ̂‖)
    and ζ̂ never leaves the box.
    """
    step = phte / (1.0 + fro2) + sigma * zeta
    if not np.isfinite(step).all():
        return zeta
    return np.clip(zeta - dt * mu * step, ZETA_LO, ZETA_HI)
