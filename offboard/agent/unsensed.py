"""Neighbours inside sensing range by their predicted position but not sensed now
(dropout, occlusion): the dcbf filter keeps their barrier rows from the prediction
(docs/safety.md §5c)."""

from __future__ import annotations

import math

import numpy as np

from offboard.estimation.peer_table import unsensed_candidates
from offboard.estimation.predictor import CURRENT_AGE_S, NeighbourPredictor
from swarm_common.fastnp import norm

# relative margin on the sensing range of the compiled pre-test of predicted pairs (its sum
# of squares and the exact norm's BLAS dot differ by a few ulps)
RANGE_MARGIN = 1e-6

# the rows of neighbours that are not sensed now but predicted:
# (indices (P,), Δp (P,3) m, Δv (P,3) m/s, margins (P,) m)
PredictedPairs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class UnsensedNeighbours:
    """Agent ``index``'s neighbours to keep from prediction, read from its predictor."""

    def __init__(self, pred: NeighbourPredictor, index: int, n: int, sensing_range_m: float,
                 tau_s: float) -> None:
        self.pred, self.index, self.n = pred, index, n
        self.range, self.tau = float(sensing_range_m), float(tau_s)
        # (predictor revision, sorted scenario indices (int64) of the agents heard from)
        self._heard: tuple[int, np.ndarray] = (-1, np.zeros(0, dtype=np.int64))

    def pairs(self, t: float, sel: np.ndarray, z1: np.ndarray,
              z2: np.ndarray) -> PredictedPairs | None:
        """Agents within sensing range of the own estimate z1 (m) by their predicted
        position at ``t`` but not among the sensed ``sel``: (idx, Δp, Δv, margin), None if
        there is none (z2 the own velocity estimate, m/s). The margin (m) is the
        prediction's error bound on the position plus τ times that on the velocity, so
        the barrier is kept against every position the other can be at."""
        if len(sel) >= self.n - 1:  # every other agent is sensed: none to predict
            return None
        rows: list[tuple[int, np.ndarray, np.ndarray, float]] = []
        tau, rng, pred = self.tau, self.range, self.pred
        # only agents heard from can be predicted (the others' get() is None): O(peers).
        # Current data certainly out of range (a margin over the exact test below) is
        # passed over in the same compiled call; the rest take the exact test
        cand = unsensed_candidates(
            self._heard_indices(), self.index, np.asarray(sel, dtype=np.int64),
            pred.table.t, pred.table.rows, z1, t, CURRENT_AGE_S,
            (rng * (1.0 + RANGE_MARGIN)) ** 2,
        )
        for j in cand.tolist():
            got = pred.get_at(j, t)
            if got is None:
                continue
            dp = z1 - got[0]
            if norm(dp) > rng:
                continue
            b = pred.bound_at(j, t) or 0.0
            rows.append((j, dp, z2 - got[1], b + tau * pred.velocity_bound_at(j, t)))
        if not rows:
            return None
        return (np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                np.array([r[2] for r in rows]), np.array([r[3] for r in rows]))

    def _heard_indices(self) -> np.ndarray:
        """Sorted scenario indices (int64) of the agents heard from."""
        rev = self.pred.revision  # bumped when an agent is first heard from
        if self._heard[0] != rev:
            heard = np.flatnonzero(self.pred.table.t > -math.inf).astype(np.int64)
            self._heard = (rev, heard)
        return self._heard[1]
