"""Neighbours that are heard but not sensed now: the dcbf filter keeps their barrier rows
from the prediction (docs/safety.md §5c and §5j).

* Inside sensing range by their predicted position (dropout, occlusion): always.
* Beyond it (issue 40, "every heard neighbour is a constraint"): while the row's margin
  (the prediction's position error bound plus τ times its velocity's) keeps it beyond the
  sensing range (the sensor sees nobody inside the range, so a wider ball says less than
  the sensor does: stale data of a fast-changing neighbour), and the pair is within the
  distance from which it must have rows, max(R_h, R_b) of the load check (b) at the
  closing speed it can reach within a period
  (:func:`swarm_common.scenario.transient_check.pair_reach`). So a pair of agents that
  hear each other brakes before it comes into range, whatever its speed.
* Not in the follower's first :data:`HEARD_AFTER_S` (the observers' start transient)."""

from __future__ import annotations

import math

import numpy as np

from offboard.estimation.peer_table import unsensed_candidates
from offboard.estimation.predictor import CURRENT_AGE_S, NeighbourPredictor
from swarm_common.fastnp import norm
from swarm_common.jit import CallSite
from swarm_common.scenario.transient_check import pair_reach

# relative margin on the sensing range and the reach of the compiled pre-test of predicted
# pairs (its sums of squares and the exact norm's BLAS dot differ by a few ulps)
RANGE_MARGIN = 1e-6
_NO_REACH = np.zeros(0)  # the pre-test without the reach (rows within the range only)

# s after the follower's first step before a neighbour beyond the sensing range gets rows:
# the observers' start transient (cube8, 100 seeds: the DESO's velocity estimate is off by up
# to 3 m/s on the first steps and within 0.1 m/s by 0.3 s; docs/safety.md §5j)
HEARD_AFTER_S = 0.5

# the rows of neighbours that are not sensed now but predicted:
# (indices (P,), Δp (P,3) m, Δv (P,3) m/s, margins (P,) m)
PredictedPairs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class UnsensedNeighbours:
    """Agent ``index``'s neighbours to keep from prediction, read from its predictor."""

    def __init__(self, pred: NeighbourPredictor, index: int, n: int, sensing_range_m: float,
                 tau_s: float, reach: tuple[float, float, float, float] | None = None,
                 dv_step: float = 0.0) -> None:
        """``reach``: the terms (τ_s, d, a_b, lag) of the load check's (b)
        (:func:`swarm_common.scenario.safety_check.pair_terms`), whose
        :func:`~swarm_common.scenario.transient_check.pair_reach` at v is the distance (m)
        from which a pair closing at v (m/s) must have rows (None: no row beyond the
        sensing range); ``dv_step``: the most a pair's relative speed can grow by within
        a period (m/s)."""
        self.pred, self.index, self.n = pred, index, n
        self.range, self.tau = float(sensing_range_m), float(tau_s)
        self.reach = None if reach is None else tuple(float(x) for x in reach)
        self._reach_arr = _NO_REACH if reach is None else np.array(self.reach, dtype=float)
        self._candidates = CallSite(unsensed_candidates)  # its arguments' types are fixed
        self.dv_step = float(dv_step)
        self._t_first: float | None = None  # the first step's time (HEARD_AFTER_S)
        # (predictor revision, sorted scenario indices (int64) of the agents heard from)
        self._heard: tuple[int, np.ndarray] = (-1, np.zeros(0, dtype=np.int64))

    def pairs(self, t: float, sel: np.ndarray, z1: np.ndarray,
              z2: np.ndarray) -> PredictedPairs | None:
        """Agents heard but not among the sensed ``sel`` that get rows at ``t`` (module
        docstring; from HEARD_AFTER_S after the first call, those beyond the sensing range
        of the own estimate z1 (m) too): (idx, Δp, Δv, margin), None if there is none (z2
        the own velocity estimate, m/s). The margin (m) is the prediction's error bound on
        the position plus τ times that on the velocity, so the barrier is kept against
        every position the other can be at."""
        if self._t_first is None:
            self._t_first = t
        if len(sel) >= self.n - 1:  # every other agent is sensed: none to predict
            return None
        rows: list[tuple[int, np.ndarray, np.ndarray, float]] = []
        tau, rng, pred = self.tau, self.range, self.pred
        # only agents heard from can be predicted (the others' get() is None): O(peers).
        # Current data certainly out of range, or with the reach certainly beyond range
        # and reach (a margin over the exact test below), is passed over in the same
        # compiled call; the rest take the exact test
        reach = self.reach if t - self._t_first >= HEARD_AFTER_S else None
        cand = self._candidates.call(
            self._heard_indices(), self.index, np.asarray(sel, dtype=np.int64),
            pred.table.t, pred.table.rows, z1, z2, t, CURRENT_AGE_S,
            (rng * (1.0 + RANGE_MARGIN)) ** 2 if reach is None else math.inf,
            _NO_REACH if reach is None else self._reach_arr, rng, self.dv_step, RANGE_MARGIN,
        )
        for j in cand.tolist():
            got = pred.constant_velocity_at(j, t)
            if got is None:
                continue
            p_j, v_j, b, b_v = got
            dp = z1 - p_j
            dist = norm(dp)
            dv = z2 - v_j
            margin = b + tau * b_v
            if dist > rng and (reach is None or dist - margin < rng
                               or dist - b > pair_reach(norm(dv) + b_v + self.dv_step, *reach)):
                continue
            rows.append((j, dp, dv, margin))
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
