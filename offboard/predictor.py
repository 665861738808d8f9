"""Neighbour data ageing: the last received estimate per agent, predicted to a requested
time (Departure 16, ``communication.max_age_s``).

The desired state ξ is propagated by the exosystem (:func:`offboard.reference.exo_propagator`);
the agent's offset from it (e1 = z1 − p*, e2 = z2 − v*) by the closed-loop error dynamics
every agent shares, ``ë1 = −k_v ė1 − k_p' e1`` (the nominal controller's for followers, the
leaders' PD for leaders). Both are exact matrix exponentials, cached per step count.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from offboard.agent_types import NeighbourEstimate
from offboard.reference import exo_propagator, xi_p, xi_v

_EXO_CACHE: dict[tuple[float, float, int], np.ndarray] = {}
_ERR_CACHE: dict[tuple[float, float, float, int], np.ndarray] = {}

Prediction = tuple[np.ndarray, np.ndarray, np.ndarray]  # (p, v, ξ) of one agent


class NeighbourPredictor:
    """Last received estimate per agent, predicted to a requested time (Departure 16).

    ``omega`` (rad/s) is the exosystem frequency, ``dt`` (s) the control period;
    ``fol_gains``/``lead_gains`` are (k_p', k_v) of the error dynamics of followers and
    leaders; data older than ``max_age`` (s) is dropped, not predicted.
    """

    def __init__(self, omega: float, dt: float, fol_gains: tuple[float, float],
                 lead_gains: tuple[float, float], max_age: float = math.inf) -> None:
        self.omega = omega
        self.dt = dt
        self.max_age = max_age  # older data is dropped, not predicted (communication.max_age_s)
        self.gains = {False: fol_gains, True: lead_gains}
        self.last: dict[int, NeighbourEstimate] = {}

    def exo(self, n: int) -> np.ndarray:
        """12×12 exosystem propagator over ``n`` control periods (cached)."""
        key = (self.omega, self.dt, n)
        m = _EXO_CACHE.get(key)
        if m is None:
            m = exo_propagator(self.omega, n * self.dt)
            _EXO_CACHE[key] = m
        return m

    def err(self, leader: bool, n: int) -> np.ndarray:
        """2×2 propagator of (e1, e2) over ``n`` control periods (cached)."""
        kp, kv = self.gains[leader]
        key = (kp, kv, self.dt, n)
        m = _ERR_CACHE.get(key)
        if m is None:
            m = expm(np.array([[0.0, 1.0], [-kp, -kv]]) * n * self.dt)
            _ERR_CACHE[key] = m
        return m

    def ingest(self, neighbours: dict[int, NeighbourEstimate], comm_ok: bool) -> None:
        """Keep the newest estimate per agent (an out-of-order older one is ignored)."""
        if not comm_ok:
            return
        last = self.last
        for j, e in neighbours.items():
            old = last.get(j)
            if old is None or e.t >= old.t:
                last[j] = e

    def get(self, agent_id: int, t: float) -> Prediction | None:
        """(p, v, ξ) of ``agent_id`` predicted to ``t``; None if never received or older
        than ``max_age`` (the agent then runs without that neighbour: the conservative
        behaviour for a silent or dead neighbour; onboard sensing still feeds the RCBF)."""
        e = self.last.get(agent_id)
        if e is None or t - e.t > self.max_age + 1e-9:
            return None
        n = int(round((t - e.t) / self.dt))
        if n <= 0:
            return e.z1, e.z2, e.xi
        xi = self.exo(n) @ e.xi
        m = self.err(e.is_leader, n)
        e1 = e.z1 - xi_p(e.xi)
        e2 = e.z2 - xi_v(e.xi)
        p = xi_p(xi) + m[0, 0] * e1 + m[0, 1] * e2
        v = xi_v(xi) + m[1, 0] * e1 + m[1, 1] * e2
        return p, v, xi
