"""Other agents' actual accelerations from their broadcast velocities (docs/safety.md §3):
the dcbf filter's estimate of a neighbour's acceleration (``SafetyInput.other_acc``)."""

from __future__ import annotations

import math

import numpy as np

from offboard.agent_types import NeighbourEstimate
from swarm_common.jit import kernel


class NeighbourAccel:
    """Other agents' actual accelerations (m/s²), finite differences of their successive
    broadcast velocities z2 (leaders: their predicted true velocity), norm-bounded by
    ``a_max``; held while no new data arrives (docs/safety.md §3).

    :meth:`ingest` keeps the last two estimates per agent in arrays by scenario index (two
    slots each, the older overwritten); the difference is formed for the rows :meth:`rows`
    asks for (compiled: :func:`neighbour_accel_rows`)."""

    def __init__(self, ids: list[int] | tuple[int, ...], a_max: float) -> None:
        self.ids = list(ids)
        self.a_max = float(a_max)
        self._index_of = {aid: j for j, aid in enumerate(self.ids)}
        n = len(self.ids)
        # estimates taken per index (0, 1, or 2 meaning "two or more")
        self._count = np.zeros(n, dtype=np.int64)
        # two slots per index; _last[j] is the slot of the last estimate, the other slot
        # holds the previous one (a new estimate overwrites the previous: no shifting)
        self._last = np.zeros(n, dtype=np.int64)
        self._t_last = [0.0] * n  # the last estimate's time (s), for the ordering test
        self._t = np.zeros((n, 2))  # times (s) per slot
        self._z2 = np.zeros((n, 2, 3))  # velocities (m/s) per slot

    def ingest(self, neighbours: dict[int, NeighbourEstimate]) -> None:
        """Update from the estimates received this step (by agent id; ids outside the
        scenario are ignored; one not newer than the last is ignored)."""
        index_of, count, last, t_last = self._index_of, self._count, self._last, self._t_last
        for aid, e in neighbours.items():
            j = index_of.get(aid)
            if j is None:
                continue
            c = count[j]
            slot = 0
            if c:
                if not e.t > t_last[j] + 1e-9:
                    continue
                slot = 1 - last[j]
                count[j] = 2
            else:
                count[j] = 1
            t_last[j] = e.t
            self._t[j, slot] = e.t
            self._z2[j, slot] = e.z2
            last[j] = slot

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """(M,3) estimates for scenario indices ``idx`` (zero where fewer than two)."""
        idx = np.asarray(idx, dtype=np.int64)
        return neighbour_accel_rows(idx, self._count[idx] == 2, self._last, self._t,
                                    self._z2, self.a_max)


@kernel
def neighbour_accel_rows(
    idx: np.ndarray, have: np.ndarray, last: np.ndarray, t: np.ndarray, z2: np.ndarray,
    a_max: float,
) -> np.ndarray:
    """(M,3) ``sat_{a_max}((z2_last − z2_prev) / (t_last − t_prev))`` (m/s²) for the
    scenario indices ``idx`` where ``have``, zero elsewhere (:class:`NeighbourAccel`):
    slot ``last[j]`` of ``t`` (N,2) and ``z2`` (N,2,3) holds the last estimate, the other
    slot the previous one; sat scales a vector down to norm ``a_max`` (m/s²) if longer."""
    out = np.zeros((idx.shape[0], 3))
    for r in range(idx.shape[0]):
        if not have[r]:
            continue
        j = idx[r]
        a = last[j]
        b = 1 - a
        dt = t[j, a] - t[j, b]
        a0 = (z2[j, a, 0] - z2[j, b, 0]) / dt
        a1 = (z2[j, a, 1] - z2[j, b, 1]) / dt
        a2 = (z2[j, a, 2] - z2[j, b, 2]) / dt
        n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        s = a_max / n if n > a_max else 1.0
        out[r, 0], out[r, 1], out[r, 2] = a0 * s, a1 * s, a2 * s
    return out
