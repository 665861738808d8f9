"""The realisable virtual controls of a scenario's vehicle: every input set in one place.

* :class:`InputSet` - the polytope inner approximation of what the vehicle can realise
  (a K-sided tilt cone, bounds on u_z and on each horizontal axis): the dcbf filter's
  input set (:class:`offboard.safety.dcbf.model.ProjectedInputSet` adds its projection)
  and the load-time feasibility check's (:mod:`swarm_common.scenario.feasibility`).
* :func:`control_box` - the paper's box ‖u‖∞ ≤ u_max, tightened to what the tilt and
  thrust limits realise, which the other methods (rcbf, apf, none) clip to.

All in m/s², ENU. Pure: numbers in, numbers out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Self

import numpy as np

from swarm_common.scenario.schema import ControllerConfig, VehicleConfig


@dataclass(frozen=True)
class InputSet:
    """Polytope inner approximation of the realisable virtual controls (m/s², ENU)."""

    uz_min: float  # lowest u_z (m/s²)
    uz_max: float  # (F_max/m) cos θ − g (m/s²)
    tan_tilt: float
    sides: int  # K half-planes of the tilt cone
    uh_max: float  # per-axis horizontal bound (m/s², the ‖u‖∞ bound of §4.4)
    g: float  # gravity (m/s²)
    shrink: float = 0.02  # m/s², rows tightened so solver tolerance stays inside

    @classmethod
    def from_vehicle(
        cls, mass: float, g: float, f_max: float, tilt_deg: float, u_max: float, sides: int,
    ) -> Self:
        """The set of a vehicle: mass (kg), gravity (m/s²), F_max (N), tilt limit (deg)."""
        th = math.radians(tilt_deg)
        uz_max = min(u_max, f_max / mass * math.cos(th) - g)
        return cls(-min(u_max, 0.9 * g), uz_max, math.tan(th), int(sides), u_max, g)

    def rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A, lo, hi) with ``lo ≤ A u ≤ hi``: K cone rows, then u_z, u_x, u_y bounds."""
        k, s = self.sides, self.shrink
        c = self.tan_tilt * math.cos(math.pi / k)
        ang = 2.0 * math.pi * np.arange(k) / k
        a = np.zeros((k + 3, 3))
        a[:k, 0], a[:k, 1], a[:k, 2] = np.cos(ang), np.sin(ang), -c
        lo = np.full(k + 3, -np.inf)
        hi = np.empty(k + 3)
        hi[:k] = self.g * c - s
        a[k, 2] = 1.0
        lo[k], hi[k] = self.uz_min + s, self.uz_max - s
        a[k + 1, 0] = a[k + 2, 1] = 1.0
        lo[k + 1 :] = -self.uh_max + s
        hi[k + 1 :] = self.uh_max - s
        return a, lo, hi

    def contains(self, u: np.ndarray, tol: float = 0.0) -> bool:
        """True if ``u`` satisfies every row, the shrink margin not counted, up to ``tol``."""
        a, lo, hi = self.rows()
        y = a @ u
        s = self.shrink + tol
        return bool((y <= hi + s).all() and (y >= lo - s).all())

    @classmethod
    def of(cls, veh: VehicleConfig, ctl: ControllerConfig) -> Self:
        """The set of a scenario's ``[vehicle]`` with ``ctl.dcbf_cone_sides`` sides and
        ``ctl.u_max_mps2``."""
        return cls.from_vehicle(
            veh.mass_kg, veh.gravity_mps2, veh.thrust_max_n, veh.tilt_max_deg, ctl.u_max_mps2,
            ctl.dcbf_cone_sides,
        )

    @property
    def cone_slope(self) -> float:
        """tan θ cos(π/K): ‖u_h‖ ≤ (g + u_z) · slope on the cone's inscribed circle."""
        return self.tan_tilt * math.cos(math.pi / self.sides)

    def horizontal(self, uz: np.ndarray, reserve: float = 0.0) -> np.ndarray:
        """Largest ‖u_h‖ (m/s²) at vertical command ``uz`` in the set scaled by 1 − reserve
        about hover (u = 0), the shrink margin not counted."""
        k = 1.0 - reserve
        return np.minimum(k * self.uh_max, (k * self.g + np.asarray(uz)) * self.cone_slope)


def control_box(veh: VehicleConfig, ctl: ControllerConfig) -> tuple[np.ndarray, np.ndarray]:
    """Box on u that the tilt/thrust limits can realise (paper §4.4 ‖u‖∞ ≤ u_max, tightened).

    z in [−u_max, u_max]; horizontal per axis ``(g − 2) tan(tilt)/√2`` (tilt cone at
    u_z ≥ −2 m/s²), at most u_max (all m/s²).
    """
    umax = ctl.u_max_mps2
    g = veh.gravity_mps2
    uz_lo = min(umax, 0.9 * g)
    uz_hi = min(umax, veh.thrust_max_n / veh.mass_kg - g)
    uh = min(umax, (g - 2.0) * math.tan(math.radians(veh.tilt_max_deg)) / math.sqrt(2.0))
    return np.array([-uh, -uh, -uz_lo]), np.array([uh, uh, uz_hi])
