"""Clocks of the simulator: wall-clock real time and lockstep (docs/conventions.md §Lockstep).

Simulation time is always ``t_k = k / control_hz`` at control step ``k``; what differs is
*when* step k+1 is integrated:

* :class:`RealTimeClock`: when the wall clock reaches ``t0 + (k+1)·dt`` (the loop sleeps
  in ``select`` until then; if it falls behind it catches up without sleeping, and after
  more than ``max_lag`` seconds behind it re-anchors instead of bursting).
* :class:`LockstepClock`: when every active vehicle has answered step k (or the per-step
  wall timeout expired); the server decides, the clock only keeps k and the deadline.

Heartbeats and the other telemetry streams run on the wall clock in both modes
(``wall()`` is ``time.monotonic``).
"""

from __future__ import annotations

import time


class _Clock:
    lockstep = False

    def __init__(self, control_dt: float) -> None:
        self.dt = float(control_dt)
        self.k = 0

    @staticmethod
    def wall() -> float:
        return time.monotonic()

    def t(self, k: int | None = None) -> float:
        """Simulation time of step ``k`` (default: the current step)."""
        return (self.k if k is None else k) * self.dt

    def t_ms(self, k: int | None = None) -> int:
        """``round(t_k · 1000)``: the ``time_boot_ms`` a lockstep answer must echo."""
        return int(round(self.t(k) * 1000.0))

    def t_us(self, k: int | None = None) -> int:
        return int(round(self.t(k) * 1e6))


class RealTimeClock(_Clock):
    """Step k+1 is due at ``t0 + (k+1)·dt`` on the wall clock."""

    def __init__(self, control_dt: float, max_lag: float = 0.25) -> None:
        super().__init__(control_dt)
        self.max_lag = max_lag
        self.t0 = self.wall()
        self.relocks = 0

    def next_deadline(self) -> float:
        return self.t0 + (self.k + 1) * self.dt

    def due(self, now: float | None = None) -> bool:
        now = self.wall() if now is None else now
        return now >= self.next_deadline()

    def advance(self, now: float | None = None) -> None:
        self.k += 1
        now = self.wall() if now is None else now
        if now - self.next_deadline() > self.max_lag:  # far behind: re-anchor, count it
            self.t0 = now - self.k * self.dt
            self.relocks += 1


class LockstepClock(_Clock):
    """Step k+1 is integrated only when the server says so (all answered, or timeout)."""

    lockstep = True

    def __init__(self, control_dt: float, step_timeout: float = 0.5) -> None:
        super().__init__(control_dt)
        self.step_timeout = float(step_timeout)
        self.started = False  # start barrier passed
        self.step_started_wall = self.wall()

    def begin_step(self, now: float | None = None) -> None:
        self.step_started_wall = self.wall() if now is None else now

    def deadline(self) -> float:
        return self.step_started_wall + self.step_timeout

    def advance(self, now: float | None = None) -> None:
        self.k += 1
        self.begin_step(now)
