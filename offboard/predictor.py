"""Neighbour data ageing: the last received estimate per agent, predicted to a requested
time (Departure 16, ``communication.max_age_s``; docs/estimation.md §4).

The desired state ξ is propagated by the exosystem (:func:`offboard.reference.exo_propagator`);
the agent's offset from it (e1 = z1 − p*, e2 = z2 − v*) by the closed-loop error dynamics
``ë1 = −k_v ė1 − k_p' e1`` (the nominal controller's for followers, the leaders' PD for
leaders). Both are exact matrix exponentials, cached per step count.

* **Leaders** fly the exosystem's trajectory with their own PD and never yield, so their
  data is predicted through any outage and never dropped for its age (bound 0).
* **Followers** may be held by their safety filter or saturated, so the assumed closed
  loop can be wrong. Their prediction error is bounded by ``½ a_dev age²`` (m), with
  ``a_dev = a_max + ā* + c_r ‖(e1, e2)‖`` (m/s²): ``a_max`` bounds the follower's actual
  acceleration, ``ā*`` the exosystem's desired acceleration over the gap and
  ``c_r ‖(e1, e2)‖`` the assumed loop's own error acceleration. Their data is dropped
  once that bound exceeds ``drop_bound`` (m), or after ``max_age`` (s).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from offboard.agent_types import NeighbourEstimate
from offboard.reference import exo_propagator, xi_a, xi_j, xi_p, xi_v

A_MAX_DEFAULT = 16.0  # m/s², follower acceleration bound: √3·u_max (8 m/s²) + 2 m/s² disturbance
DROP_BOUND_M = 1.0  # m, a follower's prediction is dropped once its error bound exceeds this
# s, data at most this much older than the requested time is current (age 0): a stamp
# t_k + dt computed by the sender and the receiver's (k + 1)·dt differ by rounding only
CURRENT_AGE_S = 1e-9

_EXO_CACHE: dict[tuple[float, float, int], np.ndarray] = {}
_ERR_CACHE: dict[tuple[float, float, float, int], np.ndarray] = {}
_CR_CACHE: dict[tuple[float, float], float] = {}

Prediction = tuple[np.ndarray, np.ndarray, np.ndarray]  # (p, v, ξ) of one agent


def error_accel_gain(kp: float, kv: float) -> float:
    """c_r = sup_{s ≥ 0} ‖[−k_p, −k_v] e^{A s}‖₂ (1/s²) for A = [[0, 1], [−k_p, −k_v]]:
    the largest acceleration of the assumed error loop per unit ‖(e1, e2)‖ at the start.
    Per axis ``|ë(s)| ≤ c_r |(e1, e2)|``, hence ``‖ë(s)‖ ≤ c_r √(‖e1‖² + ‖e2‖²)``."""
    key = (kp, kv)
    c = _CR_CACHE.get(key)
    if c is None:
        a = np.array([[0.0, 1.0], [-kp, -kv]])
        row = np.array([-kp, -kv])
        decay = max(1e-3, -float(np.max(np.linalg.eigvals(a).real)))
        ss = np.linspace(0.0, 12.0 / decay, 2001)
        step = expm(a * (ss[1] - ss[0]))
        m, c = np.eye(2), 0.0
        for _ in ss:
            c = max(c, float(np.linalg.norm(row @ m)))
            m = step @ m
        c *= 1.0 + 1e-3  # margin for the sampling of s
        _CR_CACHE[key] = c
    return c


class NeighbourPredictor:
    """Last received estimate per agent, predicted to a requested time (Departure 16).

    ``omega`` (rad/s) is the exosystem frequency, ``dt`` (s) the control period;
    ``fol_gains``/``lead_gains`` are (k_p', k_v) of the error dynamics of followers and
    leaders; ``max_age`` (s) caps the age of followers' data, ``a_max`` (m/s²) bounds a
    follower's actual acceleration and ``drop_bound`` (m) is the error bound beyond which
    a follower's prediction is useless (see :meth:`bound`).
    """

    def __init__(self, omega: float, dt: float, fol_gains: tuple[float, float],
                 lead_gains: tuple[float, float], max_age: float = math.inf,
                 a_max: float = A_MAX_DEFAULT, drop_bound: float = DROP_BOUND_M) -> None:
        self.omega = omega
        self.dt = dt
        self.max_age = max_age  # followers' older data is dropped (communication.max_age_s)
        self.a_max = a_max
        self.drop_bound = drop_bound
        self.gains = {False: fol_gains, True: lead_gains}
        self.last: dict[int, NeighbourEstimate] = {}
        self._a_dev: dict[int, float] = {}  # per agent: a_dev of its last estimate (m/s²)
        # bumped when an agent is first heard from or its ``cooperative`` flag changes:
        # what a reader derives from who is heard and who cooperates is current while
        # this is unchanged
        self.revision = 0
        self.newest = -math.inf  # s, the newest stamp received from anyone

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
                if old is None or old.cooperative != e.cooperative:
                    self.revision += 1
                last[j] = e
                self._a_dev.pop(j, None)
                if e.t > self.newest:
                    self.newest = e.t

    def a_dev(self, e: NeighbourEstimate) -> float:
        """Bound (m/s²) on the gap between a follower's actual acceleration and the one its
        prediction from ``e`` assumes: a_max + ā* + c_r ‖(e1, e2)‖ (module docstring).
        The exosystem's acceleration is a sinusoid per axis, so
        ‖a*(s)‖ ≤ ā* = √(‖a*₀‖² + ‖j*₀‖²/ω²) for all s."""
        a0, j0 = xi_a(e.xi), xi_j(e.xi)
        w2 = self.omega**2 if self.omega > 0.0 else 1.0
        a_star = math.sqrt(float(a0 @ a0) + float(j0 @ j0) / w2)
        e1 = e.z1 - xi_p(e.xi)
        e2 = e.z2 - xi_v(e.xi)
        kp, kv = self.gains[False]
        c_r = error_accel_gain(kp, kv)
        return self.a_max + a_star + c_r * math.sqrt(float(e1 @ e1) + float(e2 @ e2))

    def bound(self, agent_id: int, t: float) -> float | None:
        """Bound (m) on the error of ``agent_id``'s predicted position at ``t``, None if
        nothing was received. Leaders: 0 (exosystem and their own PD; docs/estimation.md).
        Followers: ½ a_dev age² (0 while the data is current, age ≤ CURRENT_AGE_S); its
        velocity error is at most a_dev·age."""
        e = self.last.get(agent_id)
        if e is None:
            return None
        age = max(0.0, t - e.t)
        if e.is_leader or age <= CURRENT_AGE_S:
            return 0.0
        a = self._a_dev.get(agent_id)
        if a is None:
            a = self.a_dev(e)
            self._a_dev[agent_id] = a
        return 0.5 * a * age * age

    def velocity_bound(self, agent_id: int, t: float) -> float:
        """Bound (m/s) on the error of ``agent_id``'s predicted velocity at ``t``: a_dev·age
        for a follower (the derivative of :meth:`bound`), 0 for a leader or current data."""
        b = self.bound(agent_id, t)
        e = self.last.get(agent_id)
        if b is None or e is None or b <= 0.0:
            return 0.0
        return 2.0 * b / max(t - e.t, 1e-9)

    def predict_many(self, agent_ids: list[int], t: float) -> list[Prediction | None]:
        """:meth:`get` of each of ``agent_ids`` at ``t``, with get's first answer inline:
        data current at ``t`` (age ≤ CURRENT_AGE_S, the common case in lockstep) as
        received, without a method call per agent."""
        last = self.last
        out: list[Prediction | None] = []
        for aid in agent_ids:
            e = last.get(aid)
            if e is None:
                out.append(None)
            elif t - e.t <= CURRENT_AGE_S:
                out.append((e.z1, e.z2, e.xi))
            else:
                out.append(self.get(aid, t))
        return out

    def get(self, agent_id: int, t: float) -> Prediction | None:
        """(p, v, ξ) of ``agent_id`` predicted to ``t``; None if never received or, for a
        follower, if older than ``max_age`` or its :meth:`bound` exceeds ``drop_bound``
        (the agent then runs without that neighbour: the conservative behaviour for a
        silent or unpredictable neighbour; onboard sensing still feeds the safety filter).
        A leader's data is never dropped."""
        e = self.last.get(agent_id)
        if e is None:
            return None
        age = t - e.t
        if age <= CURRENT_AGE_S:  # current data (bound 0): as received
            return e.z1, e.z2, e.xi
        if not e.is_leader:
            if age > self.max_age + 1e-9:
                return None
            b = self.bound(agent_id, t)
            if b is not None and b > self.drop_bound:
                return None
        n = int(round(age / self.dt))
        if n <= 0:
            return e.z1, e.z2, e.xi
        xi = self.exo(n) @ e.xi
        m = self.err(e.is_leader, n)
        e1 = e.z1 - xi_p(e.xi)
        e2 = e.z2 - xi_v(e.xi)
        p = xi_p(xi) + m[0, 0] * e1 + m[0, 1] * e2
        v = xi_v(xi) + m[1, 0] * e1 + m[1, 1] * e2
        return p, v, xi
