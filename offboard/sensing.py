"""Synthetic onboard relative sensing (paper §3 inputs; Departure 6).

For agent i and every other agent j within ``formation.sensing_range_m`` the sensor gives
the bearing ``g_ij``, the bearing rate ``ġ_ij = P_ij (v_j − v_i)/d_ij``, the distance
``d_ij`` and the range rate ``ḋ_ij = g_ijᵀ (v_j − v_i)``, each with seeded Gaussian noise
(``[sensing]``), and independent per-pair dropouts. From them the relative position and
velocity follow: ``p_j − p_i = g_ij d_ij`` and ``v_j − v_i = ġ_ij d_ij + g_ij ḋ_ij``.

Reproducibility: the generator is ``np.random.default_rng([seed, agent_id, 0x5E])`` and
every call draws the same count of numbers (N×8 normals and N uniforms) whatever is in
range, so runs with the same seed are identical.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm_common.fastnp import einsum
from swarm_common.scenario import SensingConfig


@dataclass
class Measurements:
    """Relative measurements of one agent to all N agents (rows for itself are invalid)."""

    valid: np.ndarray  # (N,) bool: in range, not dropped, not self
    g: np.ndarray  # (N,3) bearings g_ij
    g_dot: np.ndarray  # (N,3) bearing rates
    d: np.ndarray  # (N,) distances
    d_dot: np.ndarray  # (N,) range rates

    def rel_pos(self) -> np.ndarray:
        """(N,3) measured p_j − p_i = g_ij d_ij."""
        return self.g * self.d[:, None]

    def rel_vel(self) -> np.ndarray:
        """(N,3) measured v_j − v_i = ġ_ij d_ij + g_ij ḋ_ij."""
        return self.g_dot * self.d[:, None] + self.g * self.d_dot[:, None]


class Sensor:
    """Bearing / bearing-rate / range / range-rate sensor of agent ``index``."""

    def __init__(
        self,
        index: int,
        agent_id: int,
        n: int,
        sensing: SensingConfig,
        sensing_range_m: float,
        seed: int,
    ) -> None:
        self.index = index
        self.n = n
        self.range = float(sensing_range_m)
        self.sig = np.array(
            [  # noise standard deviations (rad, rad/s, m, m/s)
                sensing.bearing_noise_rad,
                sensing.bearing_rate_noise_radps,
                sensing.distance_noise_m,
                sensing.range_rate_noise_mps,
            ],
            dtype=float,
        )
        self._sig = tuple(float(x) for x in self.sig)  # plain floats: no numpy scalars
        self.dropout = float(sensing.dropout_prob)
        self.rng = np.random.default_rng([int(seed), int(agent_id), 0x5E])

    def measure(self, p: np.ndarray, v: np.ndarray) -> Measurements:
        """Measurements from ground-truth (N,3) ENU positions and velocities."""
        i = self.index
        rel = p - p[i]
        relv = v - v[i]
        d = np.sqrt(einsum("ij,ij->i", rel, rel))
        d[i] = 1.0
        g = rel / d[:, None]
        g[i, 0] = 1.0  # placeholder row for itself (marked invalid)
        gd = einsum("ij,ij->i", g, relv)
        g_dot = (relv - g * gd[:, None]) / d[:, None]
        noise = self.rng.standard_normal((self.n, 8))
        drop = self.rng.random(self.n)
        sb, sr, sd, sdd = self._sig
        # bearing noise: isotropic perturbation, renormalised (its along-g part is 2nd order)
        gm = g + noise[:, 0:3] * sb
        gm /= np.sqrt(einsum("ij,ij->i", gm, gm))[:, None]
        gdm = g_dot + noise[:, 3:6] * sr
        dm = d + noise[:, 6] * sd
        ddm = gd + noise[:, 7] * sdd
        valid = (d <= self.range) & (drop >= self.dropout)
        valid[i] = False
        return Measurements(valid=valid, g=gm, g_dot=gdm, d=dm, d_dot=ddm)


class DropoutHold:
    """Keeps a dropped pair in the safety constraints for ``hold_s`` seconds.

    A pair dropped this step but sensed within ``hold_s`` is extrapolated with its last
    measured relative velocity (dropouts must not switch a barrier off). ``enabled`` is
    False when the scenario has no dropouts (then nothing is tracked).
    """

    def __init__(self, n: int, index: int, hold_s: float, enabled: bool) -> None:
        self.index = index
        self.hold_s = hold_s
        self.enabled = enabled
        self._last_seen = np.full(n, -np.inf)
        self._last_rp = np.zeros((n, 3))
        self._last_rv = np.zeros((n, 3))

    def pairs(
        self, t: float, valid: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sel, rp, rv): indices of the pairs to constrain at ``t`` (s) and the (N,3)
        relative positions p_j − p_i (m) / velocities (m/s) to use for them."""
        held = None
        if self.enabled:
            self._last_seen[valid] = t
            self._last_rp[valid] = rel_p[valid]
            self._last_rv[valid] = rel_v[valid]
            held = ~valid & (t - self._last_seen <= self.hold_s)
            held[self.index] = False
        if held is None or not held.any():
            return np.nonzero(valid)[0], rel_p, rel_v
        age = (t - self._last_seen[held])[:, None]
        rp_s, rv_s = rel_p.copy(), rel_v.copy()
        rp_s[held] = self._last_rp[held] + age * self._last_rv[held]
        rv_s[held] = self._last_rv[held]
        return np.nonzero(valid | held)[0], rp_s, rv_s
