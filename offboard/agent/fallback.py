"""The safe behaviour a follower falls back to when its estimates cannot be trusted
(docs/safety.md, "In-flight alarms and the fallback"): brake, hold, land, on its own
odometry. Entered by :mod:`offboard.agent.guard` when the
:class:`~offboard.safety.monitor.SafetyMonitor` latches FALLBACK."""

from __future__ import annotations

import math

import numpy as np

from offboard.agent.landing import LANDED_SETTLE_S, LANDED_Z, V_D
from offboard.agent.takeoff import TAU_R, ramped_travel

HOLD_S = 3.0  # s, the fallback hovers this long once braked, then lands
BRAKED_MPS = 0.3  # m/s, the fallback's braking phase ends below this speed


class Fallback:
    """The safe behaviour on the agent's own odometry (p, v): brake (u = −k_d v) until
    slower than :data:`BRAKED_MPS`, hold that point (PD, gains ``kp`` 1/s², ``kd`` 1/s) for
    :data:`HOLD_S`, then descend to z = 0 at the landing's speed and idle once down. Every
    command is clipped to the control box [``lo``, ``hi``] (m/s²)."""

    def __init__(self, kp: float, kd: float, lo: np.ndarray, hi: np.ndarray) -> None:
        self.kp, self.kd = kp, kd
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        self.t0: float | None = None  # s, the fallback's start
        self.hold_p: np.ndarray | None = None  # m, the held point once braked
        self.t_hold = math.inf  # s, when the hold began

    @property
    def active(self) -> bool:
        return self.t0 is not None

    def start(self, t: float) -> None:
        """Enter the fallback at ``t`` (s); idempotent."""
        if self.t0 is None:
            self.t0 = t

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(p_ref, v_ref) of the hold and the descent at ``t`` (s), once braked."""
        assert self.hold_p is not None
        dz = max(0.0, float(self.hold_p[2]))
        d, v, _, _ = ramped_travel(t - self.t_hold - HOLD_S, dz, V_D)
        p = self.hold_p.copy()
        p[2] -= d
        return p, np.array([0.0, 0.0, -v])

    def landed(self, t: float, z: float) -> bool:
        """The descent has ended :data:`LANDED_SETTLE_S` ago and the altitude ``z`` (m) is
        below :data:`LANDED_Z`."""
        if self.hold_p is None:
            return False
        t_end = self.t_hold + HOLD_S + max(0.0, float(self.hold_p[2])) / V_D + TAU_R
        return t >= t_end + LANDED_SETTLE_S and z < LANDED_Z

    def command(self, t: float, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        """u (3,) at ``t`` from the odometry ``p`` (m), ``v`` (m/s)."""
        p, v = np.asarray(p, float), np.asarray(v, float)
        if self.hold_p is None:
            if float(np.linalg.norm(v)) >= BRAKED_MPS:
                return np.clip(-self.kd * v, self.lo, self.hi)
            self.hold_p, self.t_hold = p.copy(), t
        if self.landed(t, float(p[2])):
            return np.array([0.0, 0.0, self.lo[2]])
        p_ref, v_ref = self.reference(t)
        return np.clip(self.kp * (p_ref - p) + self.kd * (v_ref - v), self.lo, self.hi)
