"""The septic rest-to-rest profile of a mission leg (dimensionless).

sigma(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 - 20 tau^7 on tau in [0, 1]: sigma(0) = 0,
sigma(1) = 1 and its 1st to 3rd derivatives vanish at both ends, so velocity, acceleration
and jerk are continuous where one leg ends and the next (or a hold) begins. Outside [0, 1]
it is clamped (sigma = 0 or 1, derivatives 0).

Its derivatives factor as sigma' = 140 u^3, sigma'' = -840 w u^2 and
sigma''' = -840 u (1/4 - 5 w^2), with u = tau (1 - tau) = 1/4 - w^2 and w = tau - 1/2; so the peaks
in closed form: |sigma'| at w = 0, |sigma''| at w^2 = 1/20, |sigma'''| at w = 0.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarm_common.jit import kernel

__all__ = [
    "POWERS", "SIGMA1_PEAK", "SIGMA2_PEAK", "SIGMA3_PEAK", "sigma_jet", "sigma_jet_kernel",
    "sigma_jets",
]

# max over [0, 1] of |sigma'| = 140 (1/4)^3, |sigma''| = 840 |w| (1/4 - w^2)^2 at w^2 = 1/20,
# |sigma'''| = 840 (1/4)^2 at w = 0 (the other extremum, w^2 = 3/20, gives only 42)
SIGMA1_PEAK: float = 140.0 / 64.0
SIGMA2_PEAK: float = 840.0 * math.sqrt(1.0 / 20.0) * (1.0 / 4.0 - 1.0 / 20.0) ** 2
SIGMA3_PEAK: float = 840.0 / 16.0


def _sigma(t: Any) -> Any:
    """sigma by Horner's rule; used on [0, 1/2] only (sigma(t) = 1 - sigma(1 - t) above, which
    keeps the rounding near t = 1 at ~1e-16 instead of the cancellation of its terms)."""
    return t**4 * (35.0 + t * (-84.0 + t * (70.0 - 20.0 * t)))


def sigma_jet(tau: float) -> tuple[float, float, float, float]:
    """(sigma, sigma', sigma'', sigma''') at ``tau`` (derivatives w.r.t. tau), clamped
    outside [0, 1] (compiled: :func:`sigma_jet_kernel`)."""
    st = np.empty(4)
    sigma_jet_kernel(float(tau), POWERS, st)
    return (float(st[0]), float(st[1]), float(st[2]), float(st[3]))


# the exponents of the profile's powers, passed to the kernels as data: with a constant
# exponent LLVM turns pow(x, 2.0) into x·x, which can differ from the C library's pow (what
# Python's ``x**2`` calls) in the last bit
POWERS = np.array([2.0, 3.0, 4.0])


@kernel
def sigma_jet_kernel(tau: float, pw: np.ndarray, st: np.ndarray) -> None:
    """(σ, σ', σ'', σ''') at ``tau`` into ``st`` (4,), clamped outside [0, 1]; ``pw``:
    :data:`POWERS`. σ by :func:`_sigma`'s Horner form (``1 − _sigma(1 − τ)`` above 1/2) and
    the factored derivatives of the module docstring, each power the C library's ``pow``
    as in :func:`sigma_jets`' scalar form, so the same bits as Python's ``x**n``."""
    if tau <= 0.0:
        st[0] = st[1] = st[2] = st[3] = 0.0
        return
    if tau >= 1.0:
        st[0] = 1.0
        st[1] = st[2] = st[3] = 0.0
        return
    t = tau
    u = t * (1.0 - t)
    w = t - 0.5
    if t <= 0.5:
        st[0] = math.pow(t, pw[2]) * (35.0 + t * (-84.0 + t * (70.0 - 20.0 * t)))
    else:
        r = 1.0 - t
        st[0] = 1.0 - math.pow(r, pw[2]) * (35.0 + r * (-84.0 + r * (70.0 - 20.0 * r)))
    st[1] = 140.0 * math.pow(u, pw[1])
    st[2] = -840.0 * w * math.pow(u, pw[0])
    st[3] = -840.0 * u * (0.25 - 5.0 * w * w)


def sigma_jets(tau: np.ndarray) -> np.ndarray:
    """:func:`sigma_jet` for an array of ``tau``: shape ``tau.shape + (4,)``."""
    t = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    u = t * (1.0 - t)
    w = t - 0.5
    out = np.empty(t.shape + (4,))
    out[..., 0] = np.where(t <= 0.5, _sigma(t), 1.0 - _sigma(1.0 - t))
    out[..., 1] = 140.0 * u**3
    out[..., 2] = -840.0 * w * u**2
    out[..., 3] = -840.0 * u * (0.25 - 5.0 * w * w)
    return out
