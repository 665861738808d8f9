"""The neighbour data path as arrays: received estimates by scenario index.

A follower reads its neighbours' estimates three ways: the predictor (the last accepted
estimate per agent, predicted to t_k; :mod:`offboard.estimation.predictor`), the acceleration
estimate (its last two velocities; :mod:`offboard.estimation.neighbour_accel`) and the observers
(ẑ_j1, ẑ_j2 and ξ̂_j gathered by index inside
:func:`offboard.estimation.deso_kernel.deso_step_kernel`
and :func:`offboard.estimation.reference.observer_step`). All three read one :class:`PeerTable`,
which :meth:`PeerTable.ingest` updates from a step's :class:`EstimateBatch` in one
compiled call (:func:`ingest_kernel`), with no Python per neighbour.

The in-process runner hands every agent the same batch (all agents' estimates of the step
before, float32-rounded as on the wire) and each follower takes its own peers' rows; a
daemon writes its received payloads into a batch of their own
(:func:`offboard.daemon.wire_convert.estimates_from_wire`; records given by agent id go through
:meth:`EstimateBatch.from_estimates`). Row layout (:data:`ROW`): z1 (m), z2 (m/s), z3
(m/s²), ξ (12: p*, v*, a*, j*).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from offboard.records import NeighbourEstimate
from swarm_common.jit import CallSite, kernel

ROW = 21  # floats per estimate row: z1, z2, z3, ξ
XI_COL = 9  # the row's first column of ξ
Z1, Z2, Z3, XI = slice(0, 3), slice(3, 6), slice(6, 9), slice(XI_COL, XI_COL + 12)
# s: an acceleration estimate takes an estimate only this much newer than its last one
ACC_NEWER_S = 1e-9


@dataclass
class EstimateBatch:
    """One step's estimates by scenario index: stamp ``t`` (s; NaN where there is none),
    ``rows`` (N, ROW) [z1, z2, z3, ξ], ``leader`` and ``cooperative`` flags (N,)."""

    t: np.ndarray
    rows: np.ndarray
    leader: np.ndarray
    cooperative: np.ndarray

    @classmethod
    def empty(cls, n: int) -> EstimateBatch:
        return cls(np.full(n, np.nan), np.zeros((n, ROW)), np.zeros(n, dtype=np.bool_),
                   np.ones(n, dtype=np.bool_))

    @classmethod
    def from_estimates(
        cls, index_of: Mapping[int, int], n: int, ests: Mapping[int, NeighbourEstimate]
    ) -> tuple[EstimateBatch, np.ndarray]:
        """The batch of ``ests`` (by agent id; ids outside ``index_of`` are left out) and
        the scenario indices it holds, in the order given."""
        b = cls.empty(n)
        idx: list[int] = []
        for aid, e in ests.items():
            j = index_of.get(aid)
            if j is None:
                continue
            idx.append(j)
            b.t[j] = e.t
            r = b.rows[j]
            r[Z1], r[Z2], r[Z3], r[XI] = e.z1, e.z2, e.z3, e.xi
            b.leader[j], b.cooperative[j] = e.is_leader, e.cooperative
        return b, np.array(idx, dtype=np.int64)


class PeerTable:
    """What one agent has received, by scenario index of the ``n`` agents.

    * the last accepted estimate per agent (the predictor's): ``t`` (s, −inf never heard),
      ``rows``, ``leader``, ``cooperative``; an estimate is accepted when at least as new
      as the last one, and only while the link is up;
    * the last two accepted velocities per agent (the acceleration estimate's): ``acc_t``
      (2, n) (s, NaN for a slot never written), ``acc_z2`` (2, n, 3) (m/s), ``acc_older``
      the slot the next one overwrites; accepted when more than ACC_NEWER_S newer than the
      last, link up or not (docs/safety.md §3).
    """

    def __init__(self, n: int) -> None:
        self.t = np.full(n, -np.inf)
        self.rows = np.zeros((n, ROW))
        self.leader = np.zeros(n, dtype=np.bool_)
        self.cooperative = np.ones(n, dtype=np.bool_)
        self.version = np.zeros(n, dtype=np.int64)  # rows accepted per agent
        self.acc_t = np.full((2, n), np.nan)
        self.acc_z2 = np.zeros((2, n, 3))
        self.acc_older = np.zeros(n, dtype=np.int64)
        self.newest = -math.inf  # s, the newest stamp accepted from anyone
        # bumped when an agent is first heard from or its cooperative flag changes
        self.revision = 0
        self._ingest = CallSite(ingest_kernel)  # every EstimateBatch has the same types

    def ingest(self, batch: EstimateBatch, idx: np.ndarray, link_up: bool) -> None:
        """Take the estimates of ``batch`` at scenario indices ``idx`` (NaN stamps skipped)."""
        changed, newest = self._ingest.call(
            idx, batch.t, batch.rows, batch.leader, batch.cooperative, link_up, self.t,
            self.rows, self.leader, self.cooperative, self.version, self.acc_t, self.acc_z2,
            self.acc_older,
        )
        if changed:
            self.revision += 1
        if newest > self.newest:
            self.newest = newest


@kernel
def ingest_kernel(
    idx: np.ndarray, bt: np.ndarray, brows: np.ndarray, blead: np.ndarray,
    bcoop: np.ndarray, link_up: bool, t: np.ndarray, rows: np.ndarray, lead: np.ndarray,
    coop: np.ndarray, version: np.ndarray, acc_t: np.ndarray, acc_z2: np.ndarray,
    acc_older: np.ndarray,
) -> tuple[bool, float]:
    """:meth:`PeerTable.ingest` (arrays as there; idx (m,) int64): for each ``j = idx[r]``
    with a stamp, the predictor's row is replaced when ``link_up`` and the stamp is not
    older than the last (its ``version`` counted; first heard, or a changed cooperative
    flag, is reported), and the acceleration slots take its z2 when it is more than
    ACC_NEWER_S newer than their last. Returns (changed, newest accepted stamp (s, −inf
    if none)): scalars, no array to box. ValueError, with nothing written, for an index
    outside the batch or the table."""
    n = min(bt.shape[0], brows.shape[0], t.shape[0], rows.shape[0], acc_t.shape[1])
    for r in range(idx.shape[0]):
        if not 0 <= idx[r] < n:
            raise ValueError("ingest_kernel: an index outside the batch or the table")
    changed, newest = False, -math.inf
    for r in range(idx.shape[0]):
        j = idx[r]
        s = bt[j]
        if math.isnan(s):
            continue
        if link_up and s >= t[j]:
            if t[j] == -math.inf or coop[j] != bcoop[j]:
                changed = True
            t[j] = s
            for c in range(ROW):
                rows[j, c] = brows[j, c]
            lead[j] = blead[j]
            coop[j] = bcoop[j]
            version[j] += 1
            if s > newest:
                newest = s
        older = acc_older[j]
        last = acc_t[1 - older, j]
        if math.isnan(last) or s > last + ACC_NEWER_S:
            acc_t[older, j] = s
            for c in range(3):
                acc_z2[older, j, c] = brows[j, 3 + c]
            acc_older[j] = 1 - older
    return changed, newest


def rows_of(
    n: int, z1: Mapping[int, np.ndarray] | None = None, z2: Mapping[int, np.ndarray] | None = None,
    xi: Mapping[int, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(rows (n, ROW), have (n,) bool) of vectors given by scenario index: the input of
    :meth:`offboard.estimation.deso.DESO.update` and
    :meth:`offboard.estimation.reference.DesiredStateObserver.update` from per-agent z1 (m), z2
    (m/s)
    and ξ; ``have[j]`` where any of them is given for j."""
    rows = np.zeros((n, ROW))
    have = np.zeros(n, dtype=np.bool_)
    for cols, vecs in ((Z1, z1), (Z2, z2), (XI, xi)):
        for j, x in (vecs or {}).items():
            rows[j, cols] = x
            have[j] = True
    return rows, have


@kernel
def reach_bound(v_bar: float, tau_s: float, d: float, a_b: float, lag: float) -> float:
    """:func:`swarm_common.scenario.transient_check.pair_reach` (m) for a pair closing at
    ``v_bar`` (m/s), the same formula compiled for :func:`unsensed_candidates`' pre-test
    (which keeps a margin on it; the exact test stays with the Python one)."""
    tv = tau_s * v_bar
    r_h = tv + math.sqrt(tv * tv + d * d)
    if a_b <= 0.0:
        return math.inf
    return max(r_h, d + v_bar * lag + v_bar * v_bar / (2.0 * a_b))


@kernel
def unsensed_candidates(
    heard: np.ndarray, own: int, sensed: np.ndarray, t_tab: np.ndarray, rows: np.ndarray,
    z1: np.ndarray, z2: np.ndarray, t: float, age_max: float, r2: float, reach: np.ndarray,
    rng: float, dv_step: float, margin: float,
) -> np.ndarray:
    """The agents of ``heard`` (scenario indices, int64, in that order) that may need rows
    but are not sensed: not ``own``, not in ``sensed`` (int64), and not certainly passed
    over. Only current rows (stamp at most ``age_max`` s before ``t``) are passed over:

    * with ``reach`` empty, those whose z1 is farther than √r2 (m) from ``z1``;
    * with ``reach`` = (τ_s, d, a_b, lag) of the load check's (b), those certainly
      beyond both the sensing range ``rng`` (m) and the reach
      (:func:`reach_bound`) at their closing speed ‖z2 − z2_j‖ + ``dv_step`` (m/s):
      their distance, shrunk by the relative ``margin``, beyond ``rng`` and beyond the
      reach at that speed grown by ``margin``, grown by ``margin`` again.

    The norms are sums of squares in order, a cheap pre-test: callers keep a margin on r2
    and test the rest exactly (offboard.agent.unsensed)."""
    n = t_tab.shape[0]
    if rows.shape[0] < n:
        raise ValueError("unsensed_candidates: the rows are fewer than the stamps")
    for r in range(sensed.shape[0]):
        if not 0 <= sensed[r] < n:
            raise ValueError("unsensed_candidates: an index outside the table")
    # searched, not marked in an (N,) mask: the cost follows the pairs. Sorted by insertion
    # (they come sorted: one pass), not np.sort, whose quicksort allocates a stack per call
    skip = sensed.copy()
    n_skip = skip.shape[0]
    for a in range(1, n_skip):
        x = skip[a]
        b = a - 1
        while b >= 0 and skip[b] > x:
            skip[b + 1] = skip[b]
            b -= 1
        skip[b + 1] = x
    with_reach = reach.shape[0] == 4
    out = np.empty(heard.shape[0], dtype=np.int64)
    m = 0
    for r in range(heard.shape[0]):
        j = heard[r]
        if not 0 <= j < n:
            raise ValueError("unsensed_candidates: an index outside the table")
        if j == own:
            continue
        at = np.searchsorted(skip, j)
        if at < n_skip and skip[at] == j:
            continue
        if t - t_tab[j] <= age_max:
            d0 = z1[0] - rows[j, 0]
            d1 = z1[1] - rows[j, 1]
            d2 = z1[2] - rows[j, 2]
            ss = d0 * d0 + d1 * d1 + d2 * d2
            if ss > r2:
                continue
            if with_reach:
                dist = math.sqrt(ss) * (1.0 - margin)
                if dist > rng:
                    w0 = z2[0] - rows[j, 3]
                    w1 = z2[1] - rows[j, 4]
                    w2 = z2[2] - rows[j, 5]
                    v = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2) * (1.0 + margin) + dv_step
                    far = reach_bound(v, reach[0], reach[1], reach[2], reach[3])
                    if dist > far * (1.0 + margin):
                        continue
        out[m] = j
        m += 1
    return out[:m]


@kernel
def full_share_rows(
    sel: np.ndarray, full: np.ndarray, t_tab: np.ndarray, since: float, others_heard: bool,
    out: np.ndarray,
) -> None:
    """Writes ``out`` (M,) bool (the caller's new array: none to box) for the pairs ``sel``
    (M,) (scenario indices, int64): ``full[j]`` (N,)
    bool, or, when ``others_heard``, the agent's last stamp ``t_tab[j]`` (s, −inf never
    heard) is before ``since`` (s). The dcbf filter's full-share mask
    (:meth:`offboard.agent.shares.ShareRule.full`) in one call."""
    if out.shape[0] != sel.shape[0]:
        raise ValueError("full_share_rows: out not of the pairs' length")
    for r in range(sel.shape[0]):
        j = sel[r]
        if not (0 <= j < full.shape[0] and j < t_tab.shape[0]):
            raise ValueError("full_share_rows: an index outside the table")
        out[r] = full[j] or (others_heard and t_tab[j] < since)
