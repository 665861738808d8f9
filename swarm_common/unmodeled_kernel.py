"""Compiled products of the unmodeled-dynamics regressor Φ (:mod:`swarm_common.unmodeled`,
paper §2.2): Φ ζ and (Φᵀ e, ‖Φ‖_F²) without building Φ, the one definition that the
simulator's physics kernel and the observer's kernels call (``tests/unit/
test_unmodeled_kernels.py`` checks them against the matrix).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel


@kernel
def ground_effect_kernel(z: float, h: float) -> float:
    """Φ's ground-effect entry exp(−max(z, 0)/h) at height z (m), h (m); nan stays nan."""
    zc = 0.0 if z < 0.0 else z
    return math.exp(-zc / h)


@kernel
def unmodeled_accel_kernel(
    z: float, vx: float, vy: float, vz: float, zeta: np.ndarray, h: float
) -> tuple[float, float, float]:
    """f̃ = Φ(p, v) ζ (m/s²) of :func:`regressor`'s columns without building Φ: height z
    (m), velocity (vx, vy, vz) (m/s), ζ (6,) (bias m/s², linear drag 1/s, quadratic drag
    1/m, cubic damping s/m², ground effect m/s², cross-coupling 1/s), h (m)."""
    speed = math.sqrt(vx * vx + vy * vy + vz * vz)
    lin = zeta[1] + zeta[2] * speed
    fx = zeta[0] - lin * vx - zeta[3] * (vx * vx * vx) - zeta[5] * vy
    fy = zeta[0] - lin * vy - zeta[3] * (vy * vy * vy) + zeta[5] * vx
    fz = zeta[0] - lin * vz - zeta[3] * (vz * vz * vz) + zeta[4] * ground_effect_kernel(z, h)
    return fx, fy, fz


@kernel
def regressor_t_times_kernel(
    z: float, vx: float, vy: float, vz: float, e: np.ndarray, h: float
) -> tuple[np.ndarray, float]:
    """(Φᵀ e (6,), ‖Φ‖_F²) of :func:`regressor` at height z (m), velocity v (m/s), for a
    3-vector e, without building Φ."""
    ex, ey, ez = e[0], e[1], e[2]
    v2 = vx * vx + vy * vy + vz * vz
    nv = math.sqrt(v2)
    ve = vx * ex + vy * ey + vz * ez
    ge = ground_effect_kernel(z, h)
    x3, y3, z3 = vx * vx * vx, vy * vy * vy, vz * vz * vz
    phte = np.empty(6)
    phte[0] = ex + ey + ez
    phte[1] = -ve
    phte[2] = -nv * ve
    phte[3] = -(x3 * ex + y3 * ey + z3 * ez)
    phte[4] = ge * ez
    phte[5] = -vy * ex + vx * ey
    fro2 = 3.0 + v2 + v2 * v2 + (x3 * x3 + y3 * y3 + z3 * z3) + ge * ge + vx * vx + vy * vy
    return phte, fro2

