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

from dataclasses import dataclass

import numpy as np

from swarm_common.fastnp import norm, vec3
from swarm_common.jit import kernel

START_CAPACITY = 512  # samples the window's ring holds before it grows (6 s at 50 Hz: 301)
# the ring's counters (DeadlockDetector._n): first sample, samples, held steps, low steps
N_HEAD, N_COUNT, N_HELD, N_LOW = range(4)
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


@kernel
def window_step(ts: np.ndarray, errs: np.ndarray, held: np.ndarray, pos: np.ndarray,
                has_pos: np.ndarray, n: np.ndarray, t: float, err_m: float, is_held: bool,
                p: np.ndarray, given: bool, window_s: float, err_tol_m: float,
                min_progress: float, held_fraction: float) -> bool:
    """Add the sample (``t`` s, ``err_m`` m, ``is_held``, the position ``p`` (3,) m where
    ``given``) to the ring ``ts``, ``errs``, ``held``, ``pos``, ``has_pos`` (capacity C, at
    least one free slot) whose counters are ``n`` (``N_*``), drop every sample but the
    newest at or before t − ``window_s``, and return whether the window shows a deadlock
    but for the travel test: full, never within ``err_tol_m``, the error fallen by less
    than ``min_progress`` of its value at the window's start, and held on at least
    ``held_fraction`` of its samples (the module docstring). The window's first sample is
    then at ``n[N_HEAD]``."""
    cap = ts.shape[0]
    k = (n[N_HEAD] + n[N_COUNT]) % cap
    ts[k], errs[k], held[k], has_pos[k] = t, err_m, is_held, given
    if given:
        pos[k, 0], pos[k, 1], pos[k, 2] = p[0], p[1], p[2]
    n[N_COUNT] += 1
    n[N_HELD] += is_held
    n[N_LOW] += err_m <= err_tol_m
    while n[N_COUNT] > 1 and ts[(n[N_HEAD] + 1) % cap] <= t - window_s:
        h = n[N_HEAD]
        n[N_HELD] -= held[h]
        n[N_LOW] -= errs[h] <= err_tol_m
        n[N_HEAD] = (h + 1) % cap
        n[N_COUNT] -= 1
    e0 = errs[n[N_HEAD]]
    return bool(
        t - ts[n[N_HEAD]] >= window_s
        and n[N_LOW] == 0
        and e0 - err_m < min_progress * e0
        and n[N_HELD] >= held_fraction * n[N_COUNT]
    )


class DeadlockDetector:
    """Sliding-window deadlock test of the module docstring. The window is a ring of
    samples stepped by the compiled :func:`window_step` (it runs every control step of
    every follower); the travel test, on the few steps that reach it, is made here."""

    def __init__(self, cfg: DeadlockConfig | None = None) -> None:
        self.cfg = cfg or DeadlockConfig()
        self._alloc(START_CAPACITY)
        self.active = False

    def _alloc(self, cap: int) -> None:
        self._t = np.zeros(cap)  # s
        self._err = np.zeros(cap)  # m
        self._held = np.zeros(cap, dtype=np.int64)  # 1: the filter held the agent
        self._pos = np.zeros((cap, 3))  # m, the agent's position
        self._has_pos = np.zeros(cap, dtype=np.bool_)  # a position was given
        self._n = np.zeros(4, dtype=np.int64)  # N_HEAD, N_COUNT, N_HELD, N_LOW

    def _grow(self) -> None:
        """Twice the ring's capacity, its samples unrolled in order from slot 0."""
        head, count = int(self._n[N_HEAD]), int(self._n[N_COUNT])
        cap = len(self._t)
        order = (head + np.arange(count)) % cap
        old = (self._t[order], self._err[order], self._held[order], self._pos[order],
               self._has_pos[order])
        counts = self._n.copy()
        self._alloc(2 * cap)
        self._t[:count], self._err[:count], self._held[:count] = old[0], old[1], old[2]
        self._pos[:count], self._has_pos[:count] = old[3], old[4]
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
        cfg = self.cfg
        n = self._n
        if n[N_COUNT] == len(self._t):
            self._grow()
            n = self._n
        p = _NO_POS if pos is None else vec3(np.asarray(pos, float))
        stuck = window_step(self._t, self._err, self._held, self._pos, self._has_pos, n,
                            float(t), float(err_m), bool(held), p, pos is not None,
                            cfg.window_s, cfg.err_tol_m, cfg.min_progress, cfg.held_fraction)
        if stuck and pos is not None and self._has_pos[n[N_HEAD]]:
            stuck = norm(p - self._pos[n[N_HEAD]]) < cfg.max_travel_m
        self.active = bool(stuck)
        return self.active
