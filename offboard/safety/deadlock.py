"""Deadlock detection: the formation error stops falling while the filter holds the agent
(docs/safety.md, "Dense formations: liveness"). Pure, no I/O.

One :class:`DeadlockDetector` per follower, fed once per control step with the mission
time, the agent's formation error ‖p̂ − p*‖ and the filter's correction ‖u − u_nom‖. It
reports a deadlock when, over the last ``window_s`` seconds, all three hold:

* the error is above ``err_tol_m`` throughout (the agent is not in formation);
* it fell by less than ``min_progress`` of its value at the window's start (stalled);
* the filter corrected the nominal command by more than ``corr_tol_mps2`` on at least
  ``held_fraction`` of the steps (it is the filter, not the nominal law, that holds it);
* where the caller gives the agent's position, it moved less than ``max_travel_m`` from
  where it was at the window's start (it is stuck, not going around something: a
  follower that winds between obstacles keeps a large error for a while, yet moves).

The flag clears as soon as one of them fails. Wiring (not done here): a follower keeps a
detector, feeds it after its QP, and sets an ``AgentAlarm`` bit while :attr:`active`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarm_common.fastnp import vec3
from swarm_common.jit import CallSite, kernel

START_CAPACITY = 512  # samples the window's ring holds before it grows (6 s at 50 Hz: 301)
# the ring's counters (DeadlockDetector._n): first sample, samples, held steps, low steps
N_HEAD, N_COUNT, N_HELD, N_LOW = range(4)
# the ring's columns: time (s), error (m), held (1/0), position (m), position given (1/0)
R_T, R_ERR, R_HELD, R_P, R_HAS = 0, 1, 2, 3, 6
R_WIDTH = 7
# the configuration as the kernels read it (DeadlockConfig's fields, units there)
C_WINDOW, C_ERR_TOL, C_PROGRESS, C_HELD_FRACTION, C_TRAVEL = range(5)
_NO_POS = np.zeros(3)  # window_step's position argument when none is given (not stored)


@dataclass(frozen=True)
class DeadlockConfig:
    """Thresholds of :class:`DeadlockDetector` (units in the names)."""

    window_s: float = 3.0
    err_tol_m: float = 0.1  # formation_time_s's tolerance (gcs.report.metrics.TRACK_TOL_M)
    min_progress: float = 0.1  # fraction of the error the window must remove
    corr_tol_mps2: float = 0.05
    held_fraction: float = 0.5
    max_travel_m: float = 0.5  # m, net displacement over the window of a stuck agent

    def __post_init__(self) -> None:
        if not self.window_s > 0.0:
            raise ValueError("window_s must be > 0")
        if not 0.0 <= self.min_progress < 1.0:
            raise ValueError("min_progress must be in [0, 1)")
        if not 0.0 < self.held_fraction <= 1.0:
            raise ValueError("held_fraction must be in (0, 1]")

    def array(self) -> np.ndarray:
        """The thresholds as the kernels read them (``C_*``)."""
        out = np.empty(5)
        out[C_WINDOW], out[C_ERR_TOL], out[C_PROGRESS] = (
            self.window_s, self.err_tol_m, self.min_progress)
        out[C_HELD_FRACTION], out[C_TRAVEL] = self.held_fraction, self.max_travel_m
        return out


@kernel
def window_step(ring: np.ndarray, n: np.ndarray, cfg: np.ndarray, t: float, err_m: float,
                is_held: bool, p: np.ndarray, given: bool) -> bool:
    """Add the sample (``t`` s, ``err_m`` m, ``is_held``, the position ``p`` (3,) m where
    ``given``) to the ring ``ring`` (C, R_WIDTH; at least one free slot) whose counters
    are ``n`` (``N_*``), drop every sample but the newest at or before t − window, and
    return whether the window shows a deadlock (thresholds ``cfg``, ``C_*``): full, never
    within the error tolerance, the error fallen by less than the progress fraction of its
    value at the window's start, held on at least the held fraction of its samples, and,
    where both this sample and the window's first have a position, moved less than the
    travel bound (the module docstring). The window's first sample is then at
    ``n[N_HEAD]``."""
    cap = ring.shape[0]
    err_tol = cfg[C_ERR_TOL]
    k = (n[N_HEAD] + n[N_COUNT]) % cap
    ring[k, R_T], ring[k, R_ERR] = t, err_m
    ring[k, R_HELD] = 1.0 if is_held else 0.0
    ring[k, R_HAS] = 1.0 if given else 0.0
    if given:
        ring[k, R_P], ring[k, R_P + 1], ring[k, R_P + 2] = p[0], p[1], p[2]
    n[N_COUNT] += 1
    n[N_HELD] += is_held
    n[N_LOW] += err_m <= err_tol
    while n[N_COUNT] > 1 and ring[(n[N_HEAD] + 1) % cap, R_T] <= t - cfg[C_WINDOW]:
        h = n[N_HEAD]
        n[N_HELD] -= ring[h, R_HELD] != 0.0
        n[N_LOW] -= ring[h, R_ERR] <= err_tol
        n[N_HEAD] = (h + 1) % cap
        n[N_COUNT] -= 1
    h = n[N_HEAD]
    e0 = ring[h, R_ERR]
    stuck = (t - ring[h, R_T] >= cfg[C_WINDOW] and n[N_LOW] == 0
             and e0 - err_m < cfg[C_PROGRESS] * e0
             and n[N_HELD] >= cfg[C_HELD_FRACTION] * n[N_COUNT])
    if stuck and given and ring[h, R_HAS] != 0.0:
        dx, dy, dz = p[0] - ring[h, R_P], p[1] - ring[h, R_P + 1], p[2] - ring[h, R_P + 2]
        stuck = math.sqrt(dx * dx + dy * dy + dz * dz) < cfg[C_TRAVEL]
    return bool(stuck)


@kernel
def tracking_step(ring: np.ndarray, n: np.ndarray, cfg: np.ndarray, t: float,
                  p: np.ndarray, target: np.ndarray, is_held: bool) -> bool:
    """:func:`window_step` of the error ‖p − target[0:3]‖ (m) at the position ``p`` (3,)."""
    dx, dy, dz = p[0] - target[0], p[1] - target[1], p[2] - target[2]
    return window_step(ring, n, cfg, t, math.sqrt(dx * dx + dy * dy + dz * dz), is_held,
                       p, True)


class DeadlockDetector:
    """Sliding-window deadlock test of the module docstring. The window is a ring of
    samples stepped by one compiled call (:func:`window_step`; it runs every control step
    of every follower)."""

    def __init__(self, cfg: DeadlockConfig | None = None) -> None:
        self.cfg = cfg or DeadlockConfig()
        self._cfg = self.cfg.array()
        self._tracking = CallSite(tracking_step)  # its arguments' types are fixed
        self._alloc(START_CAPACITY)
        self.active = False

    def _alloc(self, cap: int) -> None:
        self._ring = np.zeros((cap, R_WIDTH))  # columns R_*
        self._n = np.zeros(4, dtype=np.int64)  # N_HEAD, N_COUNT, N_HELD, N_LOW

    def _grow(self) -> None:
        """Twice the ring's capacity, its samples unrolled in order from slot 0."""
        head, count = int(self._n[N_HEAD]), int(self._n[N_COUNT])
        cap = len(self._ring)
        old = self._ring[(head + np.arange(count)) % cap]
        counts = self._n.copy()
        self._alloc(2 * cap)
        self._ring[:count] = old
        self._n[:] = counts
        self._n[N_HEAD] = 0

    def reset(self) -> None:
        """Forget the history (a new mission phase, e.g. the land-all)."""
        self._n[:] = 0
        self.active = False

    def update(self, t: float, err_m: float, corr_mps2: float) -> bool:
        """One step at mission time ``t`` (s, increasing) with formation error ``err_m`` (m)
        and filter correction ``corr_mps2`` = ‖u − u_nom‖ (m/s²); returns :attr:`active`."""
        return self.update_held(t, err_m, corr_mps2 > self.cfg.corr_tol_mps2)

    def update_held(self, t: float, err_m: float, held: bool,
                    pos: np.ndarray | None = None) -> bool:
        """:meth:`update` where the caller knows whether the filter held the agent this step
        (e.g. its QP had an active row) rather than the size of its correction; ``pos``
        (3,) the agent's position (m), for the travel test (none without it)."""
        if self._n[N_COUNT] == len(self._ring):
            self._grow()
        p = _NO_POS if pos is None else vec3(np.asarray(pos, float))
        self.active = window_step(self._ring, self._n, self._cfg, float(t), float(err_m),
                                  bool(held), p, pos is not None)
        return self.active

    def update_tracking(self, t: float, p: np.ndarray, target: np.ndarray,
                        held: bool) -> bool:
        """:meth:`update_held` with the error ‖p − target[0:3]‖ (m) of the position ``p``
        (3,) float64 to the tracked ``target`` (≥ 3,) float64, both C-contiguous (the
        follower's ẑ1 and ξ̂), at position ``p``."""
        if self._n[N_COUNT] == len(self._ring):
            self._grow()
        self.active = self._tracking.call(self._ring, self._n, self._cfg, float(t), p, target,
                                    held)
        return self.active
