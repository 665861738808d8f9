"""Baselines: "improved APF" and no collision avoidance (paper §5.4; Departure 17).

Both use the same nominal formation controller as the CLF–RCBF method
(:func:`offboard.safety.rcbf.clf_rcbf.clf_terms_of_reference`); they differ only in how
they avoid others:

* ``apf``: ``u = clip(u_nom + Σ_j u_rep,j + u_side)`` with the repulsion of
  :func:`apf_term` (distance part + closing-speed part) and the same sideways deadlock
  breaker as the RCBF method (:func:`offboard.safety.rcbf.clf_rcbf.tangential_term`).
* ``none``: ``u = clip(u_nom)``.

:class:`ApfFilter` and :class:`NoFilter` are their safety filters.
"""

from __future__ import annotations

import math

import numpy as np

from offboard.safety.base import SafetyFilter, SafetyInput, SafetyOutput
from swarm_common.enums import Method
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


class NoFilter(SafetyFilter):
    """No collision avoidance: ``u = clip(u_nom)``; h is only reported."""

    method = Method.NONE

    def apply(self, x: SafetyInput) -> SafetyOutput:
        u = none_control(x.clf.u_nom, self.u_lo, self.u_hi)
        h_min = float(self._barrier(x).min()) if len(x.pairs) else math.inf
        return SafetyOutput(u, h_min=h_min)


class ApfFilter(SafetyFilter):
    """Improved APF: ``u = clip(u_nom + Σ u_rep + u_side)`` (§5.4, Departure 17)."""

    method = Method.APF

    def apply(self, x: SafetyInput) -> SafetyOutput:
        ctl = self.ctl
        h = self._barrier(x)
        side = self._sidestep(x, h)
        dp, dv = x.dp, x.dv
        dd = einsum("ij,ij->i", dp, dv) / np.maximum(
            np.sqrt(einsum("ij,ij->i", dp, dp)), 1e-6
        )  # range rate ḋ_ij (negative when closing)
        u = apf_control(
            x.clf.u_nom, dp, dd, side, ctl.apf_gain,
            ctl.apf_velocity_gain, ctl.apf_radius_m, self.u_lo, self.u_hi,
        )
        return SafetyOutput(u, h_min=float(h.min()) if len(h) else math.inf)
