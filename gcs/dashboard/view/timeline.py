"""The event log's timeline: one clock on screen, and a repeated event shown once.

* :class:`SimClock` - the simulation's time (s) at a wall-clock instant. Every event the
  dashboard receives is stamped on arrival with the wall clock; the feeds say what the sim
  time was when a message left (truth ``t``, a vehicle's ``time_boot_ms``). The clock keeps
  the latest such pair and reads ``sim + (wall - wall_ref)``, the extrapolation bounded by
  :data:`MAX_EXTRAPOLATION_S` (a lockstep run may run slower or faster than the wall, and
  one that stopped must not look as if its time goes on). Before any pair it reads NaN:
  the screen shows ``-`` rather than a time on another clock.
* :class:`EventMerger` - the same event again (same agent, kind and text up to its
  numbers) within :data:`REPEAT_WINDOW_S` of its first showing is counted, not shown; once
  the window ends a single line says how often it came again, with the worst severity
  among the repeats (syslog's "last message repeated N times"). A steady flood is one line
  per window; an event that stopped repeating closes its window quietly.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Generic, Protocol, TypeVar

MAX_EXTRAPOLATION_S = 1.0  # s the sim clock is carried past its last reference
RESTART_S = 5.0  # s: a stamp this much older than the reference means a new run
REPEAT_WINDOW_S = 10.0  # s (wall) over which repeats of one event are counted
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


class Event(Protocol):
    """What the merger reads of an event (:class:`gcs.dashboard.view.state.DashEvent`)."""

    @property
    def agent(self) -> int: ...
    @property
    def kind(self) -> str: ...
    @property
    def text(self) -> str: ...
    @property
    def severity(self) -> int: ...


E = TypeVar("E", bound=Event)


class SimClock:
    """Sim time (s) at a wall-clock instant, from the latest (sim, wall) reference."""

    def __init__(self) -> None:
        self._ref: tuple[float, float] | None = None  # (sim s, wall s)

    @property
    def known(self) -> bool:
        return self._ref is not None

    def observe(self, sim_s: float, wall_s: float) -> None:
        """A message stamped ``sim_s`` (sim) arrived at ``wall_s`` (wall). A stamp older
        than the reference is a late packet and ignored, unless it is older by more than
        :data:`RESTART_S` (the simulator started again)."""
        if not (math.isfinite(sim_s) and math.isfinite(wall_s)):
            return
        ref = self._ref
        if ref is None or sim_s >= ref[0] or sim_s < ref[0] - RESTART_S:
            self._ref = (sim_s, wall_s)

    def at(self, wall_s: float) -> float:
        """Sim time at ``wall_s`` (NaN before any reference)."""
        if self._ref is None:
            return math.nan
        sim, wall = self._ref
        return sim + min(max(wall_s - wall, -MAX_EXTRAPOLATION_S), MAX_EXTRAPOLATION_S)


def event_key(e: Event) -> tuple[int, str, str]:
    """What makes two events "the same": agent, kind, and the text with numbers blanked."""
    return e.agent, e.kind, _NUMBER.sub("#", e.text)


@dataclass
class _Run(Generic[E]):
    opened: float  # wall s when the event was last shown
    repeats: int = 0
    last: E | None = None
    worst: int = 7  # lowest (worst) MAV_SEVERITY among the repeats


class EventMerger(Generic[E]):
    """Shows an event once, then one line per :data:`REPEAT_WINDOW_S` with its count."""

    def __init__(self, window_s: float = REPEAT_WINDOW_S) -> None:
        self.window_s = window_s
        self._runs: dict[tuple[int, str, str], _Run[E]] = {}
        self.merged = 0  # events counted into a repeat line instead of shown

    def push(self, events: Iterable[E], wall_s: float) -> list[E]:
        """The lines to show for ``events`` received by ``wall_s`` (and the repeat lines of
        windows that ended)."""
        out: list[E] = []
        for e in events:
            key = event_key(e)
            run = self._runs.get(key)
            if run is None:
                self._runs[key] = _Run[E](opened=wall_s)
                out.append(e)
                continue
            run.repeats += 1
            run.last = e
            run.worst = min(run.worst, e.severity)
            self.merged += 1
        out.extend(self.flush(wall_s))
        return out

    def flush(self, wall_s: float, force: bool = False) -> list[E]:
        """Repeat lines of the windows that ended by ``wall_s`` (every open one: ``force``)."""
        out: list[E] = []
        for key, run in list(self._runs.items()):
            if not force and wall_s - run.opened < self.window_s:
                continue
            if run.repeats and run.last is not None:
                span = max(wall_s - run.opened, 0.0)
                text = f"{run.last.text} (again {run.repeats}x in {span:.0f} s)"
                out.append(replace(run.last, text=text, severity=run.worst))  # type: ignore[type-var]
                self._runs[key] = _Run[E](opened=wall_s)
            else:
                del self._runs[key]
        return out
