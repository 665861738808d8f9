"""In-flight safety alarms of a follower (docs/safety.md, "In-flight alarms and the
fallback"; the fallback itself: :mod:`offboard.agent.fallback`). Pure maths: no I/O; the
daemon logs the onsets.

:class:`SafetyMonitor` reads, once per control step, what the follower already has at t_k
and returns its :class:`~swarm_common.enums.AgentAlarm` bits:

* ``RESIDUAL``: the observer's position estimate ẑ_i1 disagrees with what its sensing
  implies. For every neighbour j with a fresh relative measurement r_ij ≈ p_j − p_i and a
  usable estimate ẑ_j1 predicted to t_k, ẑ_j1 − r_ij is where j's estimate and the sensor
  put agent i; the residual takes ‖ẑ_i1 − (ẑ_j1 − r_ij)‖ (m) over those j. It
  equals e_i − e_j plus the sensing error (e the estimate errors), so it needs no ground
  truth. A neighbour j that is *not* sensed (not even held through a dropout) although
  the estimates put it at ‖ẑ_j1 − ẑ_i1‖ < R (the sensing range, m) is just as
  inconsistent: its true distance is ≥ R, so ‖e_i − e_j‖ ≥ R − ‖ẑ_j1 − ẑ_i1‖, the lower
  bound it contributes (0 when the estimates put it out of range). The residual is the
  largest over both kinds of j: it flags i's own estimate running away, and also a
  neighbour's that i reads (its own estimate is then driven by it). The median was tried
  and detects 1.6 s later on cube8 with 0.5 m/s range-rate noise: neighbours that drift
  together agree with each other. The estimated speed ‖ẑ_i2‖ above :data:`V_IMPOSSIBLE_MPS`
  counts as over the bound as well (it also covers an agent that senses nobody). Over the bound
  (:func:`monitor_config`) for ``persist`` consecutive steps raises the bit; it is
  cleared after as many steps under it.
* ``NEAR_ENTRY``: an agent sensed at t_k but not at t_{k−1} whose barrier
  h = ‖Δp‖² + 2τ ΔvᵀΔp − D² (from the sensed Δp = p_i − p_j, Δv) is already < 0 at
  first sight: it was heard too late to brake. Raised on that step.
* ``FALLBACK``: ``RESIDUAL`` held for ``fallback_after`` consecutive steps latches the
  fallback (:class:`offboard.agent.fallback.Fallback`); the bit stays set from then on (no
  recovery in flight).

All vectors ENU, z up (m, m/s, m/s²).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from offboard.safety.monitor_kernel import CTR_FALLBACK, monitor_step
from swarm_common.barrier import barrier
from swarm_common.enums import NO_ALARM, AgentAlarm
from swarm_common.fastnp import vec3
from swarm_common.jit import CallSite
from swarm_common.scenario.model import Scenario

RESIDUAL_FLOOR_M = 1.0  # m, the bound's floor: transients of the estimates (docs/safety.md)
CHI2_3_999 = 16.266  # the 0.999 quantile of χ² with 3 degrees of freedom
SENSE_SIGMAS = 4.0  # standard deviations of the relative-position noise in the bound
V_IMPOSSIBLE_MPS = 30.0  # m/s, an estimated speed no vehicle of this class flies
PERSIST_S = 0.2  # s over (under) the bound that raises (clears) RESIDUAL
FALLBACK_AFTER_S = 0.5  # s of RESIDUAL held that latches the fallback
PAIR_ROOM = 16  # pairs the monitor's lists hold at first, grown on demand


@dataclass(frozen=True)
class MonitorConfig:
    """The monitor's bounds: ``bound_m`` (m) on the residual, ``v_max_mps`` on the
    estimated speed, the persistence ``persist`` and ``fallback_after`` (control steps),
    the barrier's τ (s) and D (m)."""

    bound_m: float
    v_max_mps: float
    persist: int
    fallback_after: int
    tau_s: float
    d_safe_m: float
    range_m: float  # m, the sensing range R
    vertical_scale: float = 1.0  # κ of the barrier (docs/safety.md §4c; 1: the sphere)


def residual_bound(init_pos_error_m: float, distance_noise_m: float,
                   bearing_noise_rad: float, range_m: float) -> float:
    """The residual's bound (m): :data:`RESIDUAL_FLOOR_M`, plus the 0.999 quantile of
    ‖e_i − e_j‖ for two independent initial estimate errors of ``init_pos_error_m`` (m,
    std per axis): √(2 χ²₃) σ₀, plus :data:`SENSE_SIGMAS` standard deviations of a relative
    position measured at ``range_m`` (m): σ_d + R σ_β."""
    start = math.sqrt(2.0 * CHI2_3_999) * init_pos_error_m
    sense = SENSE_SIGMAS * (distance_noise_m + range_m * bearing_noise_rad)
    return RESIDUAL_FLOOR_M + start + sense


def monitor_config(sc: Scenario) -> MonitorConfig:
    """The monitor of scenario ``sc`` (cube8: bound 2.77 m, 10 and 25 steps at 50 Hz)."""
    s = sc.sensing
    bound = residual_bound(sc.observer.init_pos_error_m, s.distance_noise_m,
                           s.bearing_noise_rad, sc.formation.sensing_range_m)
    dt = sc.control_dt
    return MonitorConfig(bound, V_IMPOSSIBLE_MPS, max(1, round(PERSIST_S / dt)),
                         max(1, round(FALLBACK_AFTER_S / dt)), sc.controller.tau_safe_s,
                         sc.controller.d_safe_m, sc.formation.sensing_range_m,
                         sc.controller.dcbf_vertical_scale)


class SafetyMonitor:
    """One follower's alarms (module docstring); ``n`` agents in the scenario."""

    def __init__(self, cfg: MonitorConfig, n: int) -> None:
        self.cfg = cfg
        self.residual = math.nan  # m, the last step's residual (NaN: no usable neighbour)
        # consecutive steps over the bound, under it while raised, RESIDUAL raised, steps
        # it has been held, the fallback latched (monitor_kernel.CTR_*)
        self._ctr = np.zeros(5, dtype=np.int64)
        self.fallback = False  # latched
        # the pairs the filter used at the last step: marked by scenario index (n,) and
        # listed (monitor_kernel.monitor_terms); the list's and the new pairs' rooms grow
        # with the pairs, not with n
        self._mark = np.zeros(n, dtype=np.int8)
        self._prev = np.zeros(PAIR_ROOM, dtype=np.int64)
        self._n_prev = 0
        self._new = np.zeros(PAIR_ROOM, dtype=np.int64)  # sensed now but not before
        self._n_new = 0
        self._first = True
        self._step = CallSite(monitor_step)  # its arguments' types are fixed

    def step(self, z1: np.ndarray, z2: np.ndarray, est_p: np.ndarray, have: np.ndarray,
             peers: np.ndarray, rel_p: np.ndarray, fresh: np.ndarray, sel: np.ndarray,
             pair_p: np.ndarray, pair_v: np.ndarray) -> AgentAlarm:
        """The bits of one step. ``z1``, ``z2`` (3,): this agent's estimates at t_k;
        ``est_p`` (N, ≥ 3): the others' position estimates predicted to t_k (the first
        three columns), ``have`` (N,) where they are, of which the rows of ``peers``
        (scenario indices, int64) are read; ``rel_p`` (N,3) with ``fresh``
        (N,) bool: this step's relative positions p_j − p_i; ``sel`` (indices) with
        ``pair_p``, ``pair_v`` (N,3): the pairs the filter uses this step (held through a
        dropout) and their p_j − p_i, v_j − v_i."""
        cfg = self.cfg
        z1 = vec3(z1)
        if len(sel) > len(self._prev):  # more pairs than ever: room for them, the list kept
            room = max(len(sel), 2 * len(self._prev))
            self._prev = np.concatenate([self._prev, np.zeros(room - len(self._prev),
                                                              dtype=np.int64)])
            self._new = np.zeros(room, dtype=np.int64)
        self.residual, self._n_new, raised = self._step.call(
            z1, z2, est_p, have, peers, rel_p, fresh, sel, self._mark, self._prev,
            self._n_prev, self._new, cfg.range_m, self._ctr, cfg.bound_m, cfg.v_max_mps,
            cfg.persist, cfg.fallback_after)
        self._n_prev = len(sel)
        any_new = self._n_new > 0
        if self._ctr[CTR_FALLBACK]:
            self.fallback = True
        bits = AgentAlarm.RESIDUAL if raised else NO_ALARM
        if any_new and self._near_entry(pair_p, pair_v):
            bits |= AgentAlarm.NEAR_ENTRY
        self._first = False
        if self.fallback:
            bits |= AgentAlarm.FALLBACK
        return bits

    def _near_entry(self, pair_p: np.ndarray, pair_v: np.ndarray) -> bool:
        """Any pair first sensed this step already inside its barrier (h < 0). Not on the
        first step: the start positions were checked at load."""
        if self._first:
            return False
        new = self._new[:self._n_new]
        h = barrier(pair_p[new], pair_v[new], self.cfg.tau_s, self.cfg.d_safe_m,
                    self.cfg.vertical_scale)
        return bool(np.any(h < 0.0))


def alarm_onsets(prev: int, now: int) -> AgentAlarm:
    """The bits set in ``now`` but not in ``prev`` (what a log names once per onset)."""
    return AgentAlarm(int(now) & ~int(prev) & int(~AgentAlarm(0)))


ALARM_TEXT = {
    AgentAlarm.RESIDUAL: "estimate residual over its bound (the observer may be diverging)",
    AgentAlarm.NEAR_ENTRY: "a neighbour first heard inside its barrier (heard too late to brake)",
    AgentAlarm.FALLBACK: "formation control left for the fallback: hold on odometry, then land",
    AgentAlarm.DEADLOCK: "formation error stalled while the filter holds it (liveness)",
    AgentAlarm.FENCE_MISMATCH: "the vehicle's fence is not the filter's (a fence it cannot take)",
}
