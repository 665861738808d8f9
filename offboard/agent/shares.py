"""Who takes the whole avoidance budget of a pair in the dcbf filter (docs/safety.md A5, §5b).

Entry point: :class:`ShareRule`. A follower takes the whole budget of a pair, instead of
its reciprocal half, when the other agent

* is a leader;
* says in its last estimate that it no longer cooperates;
* is sensed but has never been heard from (a real-time start: its daemon may not be
  flying it yet);
* or alone fell silent: no estimate from it for more than ``silent_after`` (s) while
  others were heard within that time. Its daemon is then stopped, dead or cut off, so its
  vehicle flies an old setpoint or its failsafe, not its half. When everyone is silent at
  once (this agent's own link is out) nobody is singled out: the others still run their
  filters on their onboard sensing.

Silence is judged by the estimates' own stamps, so in-process and lockstep runs judge it
alike. The rcbf filter keeps the paper's shares and does not read this.
"""

from __future__ import annotations

import math

import numpy as np

from offboard.estimation.peer_table import full_share_rows
from offboard.estimation.predictor import NeighbourPredictor

# a neighbour not heard from for longer than this is no longer trusted to do its half of
# an avoidance: s, and at least this many control periods
SILENT_AFTER_S = 0.1
SILENT_AFTER_PERIODS = 3


class ShareRule:
    """The full-share mask of a follower's pairs (module docstring), read from the
    neighbour predictor's table of estimates."""

    def __init__(self, pred: NeighbourPredictor, leader_mask: np.ndarray, dt: float) -> None:
        self.pred = pred
        self.leader_mask = leader_mask
        self.silent_after = max(SILENT_AFTER_S, SILENT_AFTER_PERIODS * dt)  # s
        # (predictor revision, (N,) fixed part of the mask) of :meth:`mask`
        self._cached: tuple[int, np.ndarray] = (-1, leader_mask)

    def silence(self, t: float) -> tuple[float, bool]:
        """(since, others_heard): an agent whose newest estimate is older than ``since``
        (s) is silent at ``t``, and it stands out only when others were heard since then
        (newest ≥ since; one never heard has −inf and a full share already)."""
        since = t - self.silent_after
        return since, self.pred.newest >= since

    def mask(self) -> np.ndarray:
        """(N,) True for a leader, an agent never heard from or one that no longer
        cooperates (the rule's fixed part, kept while the predictor's revision is
        unchanged)."""
        rev, tab = self.pred.revision, self.pred.table
        if self._cached[0] != rev:  # someone first heard from, or a cooperative flag changed
            never = tab.t == -math.inf
            self._cached = (rev, self.leader_mask | never | ~tab.cooperative)
        return self._cached[1]

    def full(self, sel: np.ndarray, t: float) -> np.ndarray:
        """(M,) True where this follower takes the whole budget of the pair with each
        agent of ``sel`` (scenario indices) at ``t``."""
        since, others_heard = self.silence(t)
        out = np.empty(len(sel), dtype=np.bool_)  # new from Python: cheaper than boxed
        full_share_rows(sel, self.mask(), self.pred.table.t, since, others_heard, out)
        return out
