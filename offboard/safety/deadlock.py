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

from collections import deque
from dataclasses import dataclass

import numpy as np

from swarm_common.fastnp import norm


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


class DeadlockDetector:
    """Sliding-window deadlock test of the module docstring."""

    def __init__(self, cfg: DeadlockConfig | None = None) -> None:
        self.cfg = cfg or DeadlockConfig()
        self._hist: deque[tuple[float, float, bool, np.ndarray | None]] = deque()
        self._held = 0  # steps in the window with the filter correcting
        self._low = 0  # steps in the window with the error at or below err_tol_m
        self.active = False

    def reset(self) -> None:
        """Forget the history (a new mission phase, e.g. the land-all)."""
        self._hist.clear()
        self._held = 0
        self._low = 0
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
        self._hist.append((t, err_m, held, None if pos is None else np.array(pos, float)))
        self._held += held
        self._low += err_m <= cfg.err_tol_m
        # keep the newest sample at or before t − window as the window's start (running
        # counts instead of a scan of the window: this runs every control step)
        while len(self._hist) > 1 and self._hist[1][0] <= t - cfg.window_s:
            _, e_old, held_old, _ = self._hist.popleft()
            self._held -= held_old
            self._low -= e_old <= cfg.err_tol_m
        t0, e0, _, p0 = self._hist[0]
        full = t - t0 >= cfg.window_s
        n = len(self._hist)
        self.active = bool(
            full
            and self._low == 0
            and e0 - err_m < cfg.min_progress * e0
            and self._held >= cfg.held_fraction * n
            and (p0 is None or pos is None
                 or norm(np.asarray(pos, float) - p0) < cfg.max_travel_m)
        )
        return self.active
