"""The navigation check of a real-time follower daemon: its DESO position estimate against
its own vehicle's ODOMETRY (docs/faults.md, "A starved daemon").

A follower flies on the DESO's estimate ẑ₁, built from relative sensing and its neighbours'
estimates; its vehicle measures its own position too. When the two disagree by more than
``gate_m`` (m) at ``steps`` consecutive checks (one every ``every`` control steps at most),
the estimate has diverged (a starved daemon whose observer ran away; every neighbour out of
sensing range while it dead-reckons). Flying on it then throws the vehicle away: in starved
test runs, 12 to 88 m up. The check latches; the daemon then brakes and holds on its
odometry and lands (:meth:`offboard.daemon.runner_loss.RunnerLoss.navigation_fault`), and does not
give the vehicle back to the estimate. Healthy flight kept the two within 0.9 m in every
real-time test, under load too (docs/faults.md), so the gate is above that. For ``grace_s``
after the first step and after a gap longer than the follower's coast covers (a stalled
daemon, or a scenario's large initial estimate error) the estimate converges first (the
DESO's slowest pole is about 3.6 1/s: in 2 s an error of 100 m, the largest a scenario may
set, decays below 0.1 m): meanwhile the disagreement may not grow by more than the gate over
the one at the grace's start. Lockstep and in-process runs have no such check: their steps
are never late, and the check must not change their bits. ENU, m.
"""

from __future__ import annotations

import numpy as np

from offboard.agent.follower import MAX_COAST_PERIODS
from offboard.daemon.limits import NAV_GATE_M, NAV_GATE_STEPS

NAV_GRACE_S = 2.0  # s not counted after the first step and after a long gap
# steps between two checks (10 Hz at 50 Hz): converting the ODOMETRY costs about 54 µs,
# and an estimate runs away over seconds (docs/performance.md, twenty-first round)
NAV_CHECK_EVERY = 5


class NavigationCheck:
    """Latching comparison of ẑ₁ with the vehicle's measured position (module docstring)."""

    def __init__(
        self, control_hz: int, gate_m: float = NAV_GATE_M, steps: int = NAV_GATE_STEPS,
        grace_s: float = NAV_GRACE_S, every: int = NAV_CHECK_EVERY,
    ) -> None:
        if not (control_hz > 0 and gate_m > 0.0 and steps >= 1 and grace_s >= 0.0
                and every >= 1):
            raise ValueError(f"control_hz = {control_hz!r}, gate_m = {gate_m!r}, steps = "
                             f"{steps!r}, grace_s = {grace_s!r}, every = {every!r}: need > 0, "
                             "> 0, >= 1, >= 0, >= 1")
        self.gate_m = float(gate_m)
        self.steps = int(steps)
        self.every = int(every)
        self.grace_steps = int(round(grace_s * control_hz))
        self.last_k: int | None = None
        self.grace_until = 0  # steps before this one are in the grace ...
        self.grace_err: float | None = None  # ... which starts at this disagreement (m)
        self.run = 0  # consecutive checks over the gate
        self.worst_m = 0.0  # the largest disagreement seen (m)
        self.failed = False

    def due(self, k: int) -> bool:
        """Whether step ``k`` is checked: not failed, and ``every`` steps or more since the
        last check (the caller converts its ODOMETRY only then)."""
        return not self.failed and (self.last_k is None or k - self.last_k >= self.every)

    def update(self, k: int, estimate: np.ndarray, measured: np.ndarray) -> bool:
        """``estimate`` and ``measured`` (3,) positions for the same instant (m), at control
        step ``k``. True on the step the check fails (once); it stays failed."""
        if self.failed:
            return False
        if self.last_k is None or k - self.last_k > MAX_COAST_PERIODS + 1:
            self.grace_until, self.grace_err = k + self.grace_steps, None
        self.last_k = k
        err = float(np.linalg.norm(np.asarray(estimate, float) - np.asarray(measured, float)))
        if not np.isfinite(err):
            err = np.inf
        if k < self.grace_until:  # converging: it may not grow by more than the gate
            if self.grace_err is None:
                self.grace_err = err
            limit = self.grace_err + self.gate_m
        else:
            self.worst_m = max(self.worst_m, err)
            limit = self.gate_m
        self.run = self.run + 1 if err > limit else 0
        if self.run >= self.steps:
            self.failed = True
            return True
        return False
