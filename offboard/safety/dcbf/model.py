"""Sampled-data CBF over the realisable input set (``Method.DCBF``; derivation: docs/safety.md).

Three departures from the paper's RCBF (:mod:`offboard.safety.rcbf.clf_rcbf`), each against a
measured
failure of it:

1. **Input set.** u is constrained to the set the vehicle can fly (tilt cone and thrust
   limit), as linear rows of the QP: ``u_z ∈ [u_z_min, (F_max/m)cos θ − g]`` and the cone
   ``‖u_h‖ ≤ (u_z + g) tan θ`` as K inscribed half-planes
   ``n_kᵀu_h − tanθ cos(π/K) u_z ≤ g tanθ cos(π/K)`` (n_k = (cos 2πk/K, sin 2πk/K)).
   ``‖u + g e_z‖ ≤ (u_z+g)/cos θ ≤ F_max/m``, so the thrust limit holds too, and the
   setpoint conversion (:func:`swarm_common.frames.accel_to_attitude`) never clips u.
2. **Lag and sampling.** The command u_k acts through the first-order inner loop
   ``ȧ = (u − a)/τ`` (τ per axis: τ_rp horizontally, τ_F vertically). The barrier
   condition is enforced on the relative state predicted ``T = τ_rp + dt`` ahead
   (:func:`offboard.safety.dcbf.kernel.dcbf_rows_kernel`), with a linear + cubic class-K
   function and a margin for the
   acceleration error bound ``ē``: ``f(u) = ḣ(x̂_T) − ‖∂ḣ_T/∂a‖ē + α(ĥ_T − ‖∂ĥ_T/∂a‖ē) ≥ 0``
   with ``α(h) = γ1 h + γ3 h³``.
3. **Neighbour motion.** The other agent's acceleration is its estimated actual one
   (finite difference of its broadcast velocity, bounded), never a reference.

A second condition per pair keeps h itself from dipping over the horizon:
``ĥ_T ≥ h0 − min(T α(h0), h0/2)`` (tightened by ē too). Both are convex quadratics in u
(small coefficients); each step they are linearised at the previous command ``u_ref``
(a lower bound, so conservative) and every pair gives two rows
``gᵀ(u − u_ref) ≥ −share·c(u_ref)`` (share ½ follower–follower, 1 against a leader).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from offboard.safety.dcbf.kernel import project_into
from swarm_common.fastnp import vec3
from swarm_common.scenario.input_set import InputSet


@dataclass(frozen=True)
class ProjectedInputSet(InputSet):
    """The dcbf filter's input set (:class:`swarm_common.scenario.input_set.InputSet`) with
    its compiled projection."""

    @cached_property
    def projection(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The arguments of :func:`offboard.safety.dcbf.kernel.project_into` after ``out`` (computed
        once per set): the scalars (uz_lo, uz_hi, uh_lo, uh_hi, cone_c, g, shrink) as one
        array, then the cosines and sines of the K cone-side angles 2πk/K."""
        s, k = self.shrink, self.sides
        ang = 2.0 * math.pi * np.arange(k) / k
        scalars = np.array([
            self.uz_min + s, self.uz_max - s, -self.uh_max + s, self.uh_max - s,
            self.tan_tilt * math.cos(math.pi / k), self.g, s,
        ])
        return scalars, np.cos(ang), np.sin(ang)

    def project(self, u: np.ndarray) -> np.ndarray:
        """A point of the (shrunk) set near ``u``: u_z clipped, then u_h scaled inward
        (compiled: :func:`offboard.safety.dcbf.kernel.project_into`, on a new array)."""
        p, cos_a, sin_a = self.projection
        out = vec3(u).copy()  # a new array from Python: cheaper than one boxed by the kernel
        project_into(out, p, cos_a, sin_a)
        return out


@dataclass(frozen=True)
class LagCoefficients:
    """How the command u enters the state T ahead under ``ȧ = (u − a)/τ`` (per axis).

    With E = e^{−T/τ}: ``a(T) = E a0 + ca u``, ``∫a = ia a0 + cv u``,
    ``∬a = iia a0 + cp u`` (a0 the realised acceleration now).
    """

    T: float
    ca: np.ndarray
    cv: np.ndarray
    cp: np.ndarray
    ea: np.ndarray  # E
    ia: np.ndarray
    iia: np.ndarray

    @classmethod
    def of(cls, tau: np.ndarray, horizon: float) -> LagCoefficients:
        """Coefficients for per-axis lags ``tau`` (s) over ``horizon`` T (s)."""
        t = float(horizon)
        tau = np.asarray(tau, dtype=float)
        e = np.exp(-t / tau)
        ia = tau * (1.0 - e)
        iia = tau * t - tau * ia
        return cls(t, 1.0 - e, t - ia, 0.5 * t * t - iia, e, ia, iia)

    @cached_property
    def sens(self) -> np.ndarray:
        """(3, 2, 1, 3): the (Δp̂, Δv̂, Δâ) sensitivities [p|v|a][error|command][·][axis]
        for :func:`~offboard.safety.dcbf.kernel.dcbf_rows_kernel`: a constant acceleration
        error (T²/2, T, 1 per axis) and the command (cp, cv, ca); computed once per
        horizon."""
        one = np.ones(3)
        err = (0.5 * self.T**2 * one, self.T * one, one)
        cmd = (self.cp, self.cv, self.ca)
        return np.array([[[e], [c]] for e, c in zip(err, cmd, strict=True)])

    @cached_property
    def sens3(self) -> np.ndarray:
        """:attr:`sens` as a (3, 2, 3) contiguous array, for the compiled rows."""
        return np.ascontiguousarray(self.sens.reshape(3, 2, 3))

    @cached_property
    def table(self) -> np.ndarray:
        """(6, 3) rows ca, cv, cp, ea, ia, iia, for the compiled rows."""
        return np.ascontiguousarray(
            np.stack([self.ca, self.cv, self.cp, self.ea, self.ia, self.iia]), dtype=float
        )
