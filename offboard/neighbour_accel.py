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

    :meth:`ingest` keeps the last two accepted estimates' time and z2 per agent by
    scenario index, in two slots of arrays (the older slot is overwritten; a slot never
    written has time NaN); :meth:`rows` forms the differences for the rows it is asked
    for in one compiled call (:func:`neighbour_accel_rows`)."""

    def __init__(self, ids: list[int] | tuple[int, ...], a_max: float) -> None:
        self.ids = list(ids)
        self.a_max = float(a_max)
        self._index_of = {aid: j for j, aid in enumerate(self.ids)}
        n = len(self.ids)
        self._t = np.full((2, n), np.nan)  # s, the time of each slot's estimate
        self._z2 = np.zeros((2, n, 3))  # m/s, each slot's velocity
        # per agent, in plain Python (no numpy scalars on the per-estimate path): the slot
        # the next accepted estimate overwrites, and the last accepted time (s)
        self._older = [0] * n
        self._t_last: list[float | None] = [None] * n

    def ingest(self, neighbours: dict[int, NeighbourEstimate]) -> None:
        """Update from the estimates received this step (by agent id; ids outside the
        scenario are ignored; one not newer than the last is ignored)."""
        index_of, t_last, older = self._index_of, self._t_last, self._older
        tt, zz = self._t, self._z2
        for aid, e in neighbours.items():
            j = index_of.get(aid)
            if j is None:
                continue
            last = t_last[j]
            if last is not None and not e.t > last + 1e-9:
                continue
            s = older[j]
            older[j] = 1 - s
            t_last[j] = e.t
            tt[s, j] = e.t
            zz[s, j] = e.z2

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """(M,3) estimates for scenario indices ``idx`` (zero where fewer than two)."""
        return neighbour_accel_rows(
            np.asarray(idx, dtype=np.int64), self._t, self._z2, self.a_max
        )


@kernel
def neighbour_accel_rows(
    idx: np.ndarray, t: np.ndarray, z2: np.ndarray, a_max: float
) -> np.ndarray:
    """(M,3): for each scenario index ``idx[r]`` with two accepted estimates,
    ``sat_{a_max}((z2_last − z2_prev) / (t_last − t_prev))`` (m/s²), zero elsewhere
    (:class:`NeighbourAccel`). t (2,N) times (s, NaN for a slot never written) and z2
    (2,N,3) velocities (m/s) in two slots per agent; the later time is the last (an
    estimate is accepted only if newer). sat scales a vector down to norm ``a_max``
    (m/s²) if longer."""
    out = np.zeros((idx.shape[0], 3))
    for r in range(idx.shape[0]):
        j = idx[r]
        if math.isnan(t[0, j]) or math.isnan(t[1, j]):
            continue
        s = 0 if t[0, j] > t[1, j] else 1
        q = 1 - s
        dt = t[s, j] - t[q, j]
        a0 = (z2[s, j, 0] - z2[q, j, 0]) / dt
        a1 = (z2[s, j, 1] - z2[q, j, 1]) / dt
        a2 = (z2[s, j, 2] - z2[q, j, 2]) / dt
        n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        sc = a_max / n if n > a_max else 1.0
        out[r, 0], out[r, 1], out[r, 2] = a0 * sc, a1 * sc, a2 * sc
    return out
