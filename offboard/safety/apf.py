"""Baselines: "improved APF" and no collision avoidance (paper §5.4; Departure 17).

Both use the same nominal formation controller as the CLF–RCBF method
(:func:`offboard.safety.rcbf.clf_rcbf.clf_terms`); they differ only in how they avoid others:

* ``apf``: ``u = clip(u_nom + Σ_j u_rep,j + u_side)`` with the repulsion of
  :func:`apf_term` (distance part + closing-speed part) and the same sideways deadlock
  breaker as the RCBF method (:func:`offboard.safety.rcbf.clf_rcbf.tangential_term`).
* ``none``: ``u = clip(u_nom)``.
"""

from __future__ import annotations

import numpy as np

from swarm_common.fastnp import einsum


def apf_term(
    dp: np.ndarray, d_dot: np.ndarray, gain: float, vgain: float, radius: float
) -> np.ndarray:
    """Improved APF repulsion (Departure 17) summed over sensed agents.

    For d < R: ``[k (1/d − 1/R)/d² + k_v max(0, −ḋ)(1/d − 1/R)] n̂``, n̂ = (p_i − p_j)/d,
    ḋ the range rate (negative when closing): a distance part plus a part proportional to
    the closing speed.
    """
    if len(dp) == 0:
        return np.zeros(3)
    d = np.sqrt(einsum("ij,ij->i", dp, dp))
    d = np.maximum(d, 1e-3)
    act = d < radius
    if not np.any(act):
        return np.zeros(3)
    d, dpa, dd = d[act], dp[act], d_dot[act]
    x = 1.0 / d - 1.0 / radius
    mag = gain * x / d**2 + vgain * np.maximum(0.0, -dd) * x
    return ((mag / d)[:, None] * dpa).sum(axis=0)


def apf_control(
    u_nom: np.ndarray,
    dp: np.ndarray,
    d_dot: np.ndarray,
    side: np.ndarray,
    gain: float,
    vgain: float,
    radius: float,
    u_lo: np.ndarray,
    u_hi: np.ndarray,
) -> np.ndarray:
    """APF control: nominal + repulsion + sideways term, clipped to the box."""
    return np.clip(u_nom + apf_term(dp, d_dot, gain, vgain, radius) + side, u_lo, u_hi)


def none_control(u_nom: np.ndarray, u_lo: np.ndarray, u_hi: np.ndarray) -> np.ndarray:
    """No collision avoidance: the nominal formation controller, clipped to the box."""
    return np.clip(u_nom, u_lo, u_hi)
