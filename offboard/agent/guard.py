"""A follower's in-flight guard: its :class:`~offboard.safety.monitor.SafetyMonitor` and,
once that latches, the :class:`~offboard.agent.fallback.Fallback` that replaces formation
control (docs/safety.md, "In-flight alarms and the fallback").

The guard only reads the follower's state: while no fallback is latched the follower's
commands and estimates are exactly those without it. In the fallback the command comes
from the agent's own odometry (its own row of the positions and velocities it is stepped
with: the daemon's own ODOMETRY, the in-process runner's truth), and the estimate it
publishes is that odometry, marked non-cooperative so that the others take the whole
avoidance budget against it (docs/safety.md A5). The fallback is never left in flight.
"""

from __future__ import annotations

import numpy as np

from offboard.agent.fallback import Fallback
from offboard.records import NeighbourEstimate
from offboard.safety.deadlock import DeadlockConfig, DeadlockDetector
from offboard.safety.monitor import SafetyMonitor, monitor_config
from swarm_common.enums import NO_ALARM, AgentAlarm
from swarm_common.fastnp import f64, vec3
from swarm_common.scenario.model import Scenario

# s: the window over which a stalled formation error with the filter active is a deadlock.
# Shorter windows flagged the crossings of cube8 and swap_centre, where followers first move
# apart under the filter before they close on their vertices (docs/safety.md 5f).
DEADLOCK_WINDOW_S = 6.0
# the fallback's horizontal clearance to a sensed agent below it, in D_safe: two landed
# agents then stand at least 2 D apart
FALLBACK_CLEAR_D = 2.0

class InFlightGuard:
    """The guard of follower ``index`` of ``sc``; ``peers`` the scenario indices whose
    estimates it predicts to t_k (graph neighbours and the leaders among its peers);
    ``lo``, ``hi`` (3,) the control box (m/s²)."""

    def __init__(self, sc: Scenario, index: int, peers: np.ndarray, lo: np.ndarray,
                 hi: np.ndarray) -> None:
        self.monitor = SafetyMonitor(monitor_config(sc), sc.n)
        self.fallback = Fallback(sc.controller.leader_kp, sc.controller.leader_kd, lo, hi,
                                 FALLBACK_CLEAR_D * sc.controller.d_safe_m)
        self.index = index
        self.dt = sc.control_dt
        self._peers = np.unique(np.asarray(peers, dtype=np.int64))  # rows the monitor reads
        self.bits = NO_ALARM
        self.deadlock = DeadlockDetector(DeadlockConfig(window_s=DEADLOCK_WINDOW_S))

    def liveness(self, t: float, z1: np.ndarray, xi: np.ndarray, held: bool,
                 flying: bool) -> AgentAlarm:
        """DEADLOCK while the formation error ‖ẑ1 − ξ̂_p‖ (m; ``z1`` (3,) the position
        estimate at ``t`` (s), ``xi`` (12,) the tracked desired state) stalls with the
        filter holding the agent (``held``: a barrier row was active) over the detector's
        window (:class:`~offboard.safety.deadlock.DeadlockDetector`, its travel test on
        ``z1``). Only while ``flying`` formation (not on the pad, landing or in the
        fallback): otherwise the window starts again."""
        if not flying or self.fallback.active:
            self.deadlock.reset()
            return NO_ALARM
        if self.deadlock.update_tracking(t, vec3(z1), f64(xi), held):
            return AgentAlarm.DEADLOCK
        return NO_ALARM

    def check(
        self, t: float, z1: np.ndarray, z2: np.ndarray, rows: np.ndarray, have: np.ndarray,
        rel_p: np.ndarray, fresh: np.ndarray, sel: np.ndarray, rp: np.ndarray,
        rv: np.ndarray,
    ) -> AgentAlarm:
        """The step's alarm bits at ``t`` (s), from the estimates ``z1``, ``z2`` (3,) at t_k,
        the neighbours' predicted ``rows`` (N, ROW) with ``have`` (N,), this step's sensed
        ``rel_p`` (N,3) where ``fresh`` (N,), and the filter's pairs ``sel`` (indices) with
        their p_j − p_i, v_j − v_i ``rp``, ``rv`` (N,3). Latches the fallback at ``t``."""
        bits = self.monitor.step(z1, z2, rows, have, self._peers, rel_p, fresh, sel, rp, rv)
        if self.monitor.fallback:
            self.fallback.start(t)
            bits |= AgentAlarm.FALLBACK
        self.bits = bits
        return bits

    def command(self, t: float, p: np.ndarray, v: np.ndarray, u: np.ndarray,
                rel_p: np.ndarray | None = None, sel: np.ndarray | None = None) -> np.ndarray:
        """``u``, or in the fallback its command from the odometry ``p`` (m), ``v`` (m/s)
        and the relative positions p_j − p_i ``rel_p`` (N, 3, m) of the sensed ``sel``."""
        if not self.fallback.active:
            return u
        below = None if rel_p is None or sel is None else rel_p[sel]
        return self.fallback.command(t, p, v, below)

    def estimate(self, est: NeighbourEstimate, p: np.ndarray, v: np.ndarray) -> NeighbourEstimate:
        """``est``, or in the fallback the odometry ``p``, ``v`` predicted to ``est.t``
        (one control period ahead), non-cooperative, with the fallback's reference."""
        fb = self.fallback
        if not fb.active:
            return est
        p, v = np.asarray(p, float), np.asarray(v, float)
        xi = np.zeros(12)
        if fb.hold_p is not None:
            xi[0:3], xi[3:6] = fb.reference(est.t)
        else:
            xi[0:3] = p
        return NeighbourEstimate(est.id, est.t, p + v * self.dt, v.copy(), np.zeros(3), xi,
                                 False, cooperative=False)
