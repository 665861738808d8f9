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

    :meth:`ingest` keeps the last two estimates per agent in arrays by scenario index; the
    difference is formed for the rows :meth:`rows` asks for (compiled:
    :func:`neighbour_accel_rows`)."""

    def __init__(self, ids: list[int] | tuple[int, ...], a_max: float) -> None:
        self.ids = list(ids)
        self.a_max = float(a_max)
        self._index_of = {aid: j for j, aid in enumerate(self.ids)}
        n = len(self.ids)
        self._count = [0] * n  # estimates taken per index (0, 1, or 2 meaning "two or more")
        self._t = np.zeros((n, 2))  # [last, previous] times (s)
        self._z2 = np.zeros((n, 2, 3))  # [last, previous] velocities (m/s)

    def ingest(self, neighbours: dict[int, NeighbourEstimate]) -> None:
        """Update from the estimates received this step (by agent id; ids outside the
        scenario are ignored)."""
        count, t_arr, z_arr = self._count, self._t, self._z2
        for aid, e in neighbours.items():
            j = self._index_of.get(aid)
            if j is None:
                continue
            c = count[j]
            if c:
                if not e.t > t_arr[j, 0] + 1e-9:
                    continue
                t_arr[j, 1] = t_arr[j, 0]
                z_arr[j, 1] = z_arr[j, 0]
            t_arr[j, 0] = e.t
            z_arr[j, 0] = e.z2
            count[j] = min(c + 1, 2)

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """(M,3) estimates for scenario indices ``idx`` (zero where fewer than two)."""
        have = np.array([self._count[int(j)] == 2 for j in idx], dtype=np.bool_)
        return neighbour_accel_rows(np.asarray(idx, dtype=np.int64), have, self._t, self._z2,
                                    self.a_max)


@kernel
def neighbour_accel_rows(
    idx: np.ndarray, have: np.ndarray, t: np.ndarray, z2: np.ndarray, a_max: float
) -> np.ndarray:
    """(M,3) ``sat_{a_max}((z2_last − z2_prev) / (t_last − t_prev))`` (m/s²) for the
    scenario indices ``idx`` where ``have``, zero elsewhere (:class:`NeighbourAccel`);
    sat scales a vector down to norm ``a_max`` (m/s²) if longer."""
    out = np.zeros((idx.shape[0], 3))
    for r in range(idx.shape[0]):
        if not have[r]:
            continue
        j = idx[r]
        dt = t[j, 0] - t[j, 1]
        a0 = (z2[j, 0, 0] - z2[j, 1, 0]) / dt
        a1 = (z2[j, 0, 1] - z2[j, 1, 1]) / dt
        a2 = (z2[j, 0, 2] - z2[j, 1, 2]) / dt
        n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        s = a_max / n if n > a_max else 1.0
        out[r, 0], out[r, 1], out[r, 2] = a0 * s, a1 * s, a2 * s
    return out
