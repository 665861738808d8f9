"""The safe behaviour a follower falls back to when its estimates cannot be trusted
(docs/safety.md, "In-flight alarms and the fallback"): brake, hold, land, on its own
odometry. Entered by :mod:`offboard.agent.guard` when the
:class:`~offboard.safety.monitor.SafetyMonitor` latches FALLBACK.

Two rules keep the landing itself safe (issue 40: a dense cube's fallback agents landed on
one another, and dropped from the height where ground effect held them):

* **Not onto another agent.** Its sensing (relative positions, no estimate) still works:
  while a sensed agent is below it within the horizontal clearance ``clear_m``, the descent
  stops and the held point moves sideways away from it at :data:`SIDESTEP_MPS`.
* **Down to the ground.** Once the descent's reference has ended, the vertical command
  tracks a sink rate of :data:`TOUCH_MPS` (PI: gains ``kd``, ``kp``) instead of the pad's
  altitude, so ground effect cannot hold the vehicle a few cm up until the idle cut drops
  it."""

from __future__ import annotations

import math

import numpy as np

from offboard.agent.landing import LANDED_SETTLE_S, LANDED_Z, V_D
from offboard.agent.takeoff import TAU_R, ramped_travel

HOLD_S = 3.0  # s, the fallback hovers this long once braked, then lands
BRAKED_MPS = 0.3  # m/s, the fallback's braking phase ends below this speed
SIDESTEP_MPS = 0.5  # m/s, the held point's sideways speed away from an agent below
TOUCH_MPS = 0.3  # m/s, the sink rate tracked after the descent's reference ends


class Fallback:
    """The safe behaviour on the agent's own odometry (p, v): brake (u = −k_d v) until
    slower than :data:`BRAKED_MPS`, hold that point (PD, gains ``kp`` 1/s², ``kd`` 1/s) for
    :data:`HOLD_S`, then descend to z = 0 at the landing's speed and idle once down. Every
    command is clipped to the control box [``lo``, ``hi``] (m/s²)."""

    def __init__(self, kp: float, kd: float, lo: np.ndarray, hi: np.ndarray,
                 clear_m: float = 0.0) -> None:
        self.kp, self.kd = kp, kd
        self.clear_m = float(clear_m)  # m, horizontal clearance to an agent below
        self._t_last: float | None = None  # s, the previous command's time
        self._sink_i = 0.0  # m/s·s, the touchdown's integral of its sink-rate error
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        self.t0: float | None = None  # s, the fallback's start
        self.active = False  # latched by start(): read by the guard every step
        self.hold_p: np.ndarray | None = None  # m, the held point once braked
        self.t_hold = math.inf  # s, when the hold began

    def start(self, t: float) -> None:
        """Enter the fallback at ``t`` (s); idempotent."""
        if self.t0 is None:
            self.t0 = t
            self.active = True

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
        return t >= self._descent_end() + LANDED_SETTLE_S and z < LANDED_Z

    def command(self, t: float, p: np.ndarray, v: np.ndarray,
                below: np.ndarray | None = None) -> np.ndarray:
        """u (3,) at ``t`` from the odometry ``p`` (m), ``v`` (m/s) and the sensed agents'
        relative positions ``below`` (M, 3), p_j − p_i (m; module docstring)."""
        p, v = np.asarray(p, float), np.asarray(v, float)
        dt = 0.0 if self._t_last is None else max(0.0, t - self._t_last)
        self._t_last = t
        if self.hold_p is None:
            if float(np.linalg.norm(v)) >= BRAKED_MPS:
                return np.clip(-self.kd * v, self.lo, self.hi)
            self.hold_p, self.t_hold = p.copy(), t
        if self.landed(t, float(p[2])):
            return np.array([0.0, 0.0, self.lo[2]])
        away = self._away(below)
        if away is not None:  # an agent below: no descent, the held point moves off
            self.t_hold += dt
            self.hold_p[:2] += SIDESTEP_MPS * dt * away
        p_ref, v_ref = self.reference(t)
        if away is not None:
            v_ref[2] = 0.0
        u = self.kp * (p_ref - p) + self.kd * (v_ref - v)
        if t >= self._descent_end():  # down to the ground at the touchdown sink rate
            err = -TOUCH_MPS - float(v[2])
            self._sink_i = min(0.0, self._sink_i + err * dt)  # only ever pushes down
            u[2] = self.kd * err + self.kp * self._sink_i
        return np.clip(u, self.lo, self.hi)

    def _descent_end(self) -> float:
        """When the descent's reference comes to rest on the ground (s)."""
        assert self.hold_p is not None
        return self.t_hold + HOLD_S + max(0.0, float(self.hold_p[2])) / V_D + TAU_R

    def _away(self, below: np.ndarray | None) -> np.ndarray | None:
        """The horizontal unit direction away from the nearest sensed agent below within
        the clearance, None when there is none."""
        if below is None or len(below) == 0 or self.clear_m <= 0.0:
            return None
        r = np.asarray(below, float)
        horiz = np.hypot(r[:, 0], r[:, 1])
        near = (r[:, 2] < 0.0) & (horiz < self.clear_m)
        if not near.any():
            return None
        k = int(np.flatnonzero(near)[np.argmin(horiz[near])])
        if horiz[k] < 1e-9:  # straight below: any direction will do; a fixed one
            return np.array([1.0, 0.0])
        return -r[k, :2] / horiz[k]
