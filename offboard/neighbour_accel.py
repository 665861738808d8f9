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

    :meth:`ingest` keeps the last two estimates per agent by scenario index (the records
    themselves: received estimates are never modified); the differences are formed for
    the rows :meth:`rows` asks for (compiled: :func:`neighbour_accel_rows`)."""

    def __init__(self, ids: list[int] | tuple[int, ...], a_max: float) -> None:
        self.ids = list(ids)
        self.a_max = float(a_max)
        self._index_of = {aid: j for j, aid in enumerate(self.ids)}
        n = len(self.ids)
        self._last: list[NeighbourEstimate | None] = [None] * n
        self._prev: list[NeighbourEstimate | None] = [None] * n

    def ingest(self, neighbours: dict[int, NeighbourEstimate]) -> None:
        """Update from the estimates received this step (by agent id; ids outside the
        scenario are ignored; one not newer than the last is ignored)."""
        index_of, last, prev = self._index_of, self._last, self._prev
        for aid, e in neighbours.items():
            j = index_of.get(aid)
            if j is None:
                continue
            old = last[j]
            if old is not None:
                if not e.t > old.t + 1e-9:
                    continue
                prev[j] = old
            last[j] = e

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """(M,3) estimates for scenario indices ``idx`` (zero where fewer than two)."""
        last, prev = self._last, self._prev
        rows: list[int] = []
        t: list[float] = []
        t_prev: list[float] = []
        z2: list[np.ndarray] = []
        z2_prev: list[np.ndarray] = []
        for r, j in enumerate(idx.tolist()):
            p, e = prev[j], last[j]
            if p is not None and e is not None:
                rows.append(r)
                t.append(e.t)
                t_prev.append(p.t)
                z2.append(e.z2)
                z2_prev.append(p.z2)
        if not rows:
            return np.zeros((len(idx), 3))
        k = len(rows)
        return neighbour_accel_rows(
            len(idx), np.array(rows, dtype=np.int64),
            np.array(t + t_prev, dtype=float).reshape(2, k),
            np.concatenate(z2 + z2_prev).reshape(2, k, 3), self.a_max,
        )


@kernel
def neighbour_accel_rows(
    m: int, rows: np.ndarray, t: np.ndarray, z2: np.ndarray, a_max: float
) -> np.ndarray:
    """(m,3): at each of the K ``rows`` ``sat_{a_max}((z2_last − z2_prev) /
    (t_last − t_prev))`` (m/s²) from t (2,K) [last; previous] times (s) and z2 (2,K,3)
    velocities (m/s), zero elsewhere (:class:`NeighbourAccel`); sat scales a vector down to
    norm ``a_max`` (m/s²) if longer."""
    out = np.zeros((m, 3))
    for i in range(rows.shape[0]):
        r = rows[i]
        dt = t[0, i] - t[1, i]
        a0 = (z2[0, i, 0] - z2[1, i, 0]) / dt
        a1 = (z2[0, i, 1] - z2[1, i, 1]) / dt
        a2 = (z2[0, i, 2] - z2[1, i, 2]) / dt
        n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        s = a_max / n if n > a_max else 1.0
        out[r, 0], out[r, 1], out[r, 2] = a0 * s, a1 * s, a2 * s
    return out
