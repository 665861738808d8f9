"""Payloads kept by control step, trimmed without a scan per payload.

A daemon keeps what its Zenoh subscribers deliver by step (the truth of step k, its peers'
estimates of step k, ...) and forgets steps that fall out of a window: older than
``KEEP_STEPS`` behind the newest payload, or outside its Zenoh guard's window around its
own step (:meth:`offboard.daemon.link_guard.PayloadGuard.window`). Asking ``min(store)`` for
every payload cost a scan of up to 64 keys per payload, about 14 payloads per agent and
step in a packed grid64 process (docs/performance.md, "Issue 11, thirteenth round").

:class:`StepStore` is a dict (step → value) that also holds a lower and an upper bound
of its keys: no key lies outside them. Every insertion widens them; a trim narrows them to
the window it keeps (or, after a scan, to the keys left); a key deleted from outside only
leaves them wider than needed. So "is anything out of the window?" is two comparisons.
When something does leave, about once per step, it is usually a step or two just beyond
a bound: those are popped by number (steps are integers), without a scan of the keys.
"""

from __future__ import annotations

import math
from typing import TypeVar

V = TypeVar("V")
FEW = 8  # steps beyond a bound popped one by one; a wider gap is found by a scan


class StepStore(dict[int, V]):
    """A dict of values by step (int) whose trims are O(1) when nothing leaves.

    Insert with ``store[step] = value`` (``dict.setdefault`` and ``dict.update`` bypass
    the bounds and must not be used)."""

    def __init__(self) -> None:
        super().__init__()
        self.lo: float = math.inf  # no key is below it
        self.hi: float = -math.inf  # no key is above it

    def __setitem__(self, step: int, value: V) -> None:
        super().__setitem__(step, value)
        if step < self.lo:
            self.lo = step
        if step > self.hi:
            self.hi = step

    def keep_within(self, lowest: float, highest: float) -> None:
        """Forget every step outside [lowest, highest]."""
        if self.lo >= lowest and self.hi <= highest:
            return
        if lowest - self.lo <= FEW and self.hi - highest <= FEW:
            # the usual case: a step or two leave at one end; pop them by number
            if self.lo < lowest:
                for step in range(int(self.lo), math.ceil(lowest)):
                    self.pop(step, None)
                self.lo = lowest  # no key below it now (not necessarily one at it)
            if self.hi > highest:
                for step in range(int(self.hi), math.floor(highest), -1):
                    self.pop(step, None)
                self.hi = highest
            if not self:
                self.lo, self.hi = math.inf, -math.inf
            return
        for step in [s for s in self if not lowest <= s <= highest]:
            del self[step]
        self.lo = min(self, default=math.inf)
        self.hi = max(self, default=-math.inf)

    def keep_from(self, lowest: float) -> None:
        """Forget every step below ``lowest``."""
        self.keep_within(lowest, math.inf)

    def clear(self) -> None:
        super().clear()
        self.lo, self.hi = math.inf, -math.inf
