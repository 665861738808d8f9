"""Other agents' actual accelerations from their broadcast velocities (docs/safety.md §3):
the dcbf filter's estimate of a neighbour's acceleration (``SafetyInput.other_acc``)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from offboard.estimation.peer_table import EstimateBatch, PeerTable
from offboard.records import NeighbourEstimate
from swarm_common.jit import kernel


class NeighbourAccel:
    """Other agents' actual accelerations (m/s²), finite differences of their successive
    broadcast velocities z2 (leaders: their predicted true velocity), norm-bounded by
    ``a_max``; held while no new data arrives (docs/safety.md §3).

    The last two accepted estimates' time and z2 per agent are the acceleration slots of a
    :class:`~offboard.estimation.peer_table.PeerTable` (``table``: a follower shares its
    predictor's,
    which one ingest fills); :meth:`rows` forms the differences for the rows it is asked
    for in one compiled call (:func:`neighbour_accel_rows`)."""

    def __init__(
        self, ids: list[int] | tuple[int, ...], a_max: float, table: PeerTable | None = None
    ) -> None:
        self.ids = list(ids)
        self.a_max = float(a_max)
        self._index_of = {aid: j for j, aid in enumerate(self.ids)}
        self.table = PeerTable(len(self.ids)) if table is None else table

    def ingest(self, neighbours: Mapping[int, NeighbourEstimate]) -> None:
        """Update from the estimates received this step (by agent id; ids outside the
        scenario are ignored; one not newer than the last is ignored)."""
        batch, idx = EstimateBatch.from_estimates(self._index_of, len(self.ids), neighbours)
        self.table.ingest(batch, idx, True)

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """(M,3) estimates for scenario indices ``idx`` (zero where fewer than two)."""
        sel = np.asarray(idx, dtype=np.int64)
        out = np.empty((len(sel), 3))  # a new array from Python: cheaper than a boxed one
        neighbour_accel_rows(sel, self.table.acc_t, self.table.acc_z2, self.a_max, out)
        return out


@kernel
def neighbour_accel_rows(
    idx: np.ndarray, t: np.ndarray, z2: np.ndarray, a_max: float, out: np.ndarray
) -> None:
    """Writes ``out`` (M,3) (the caller's new array: none to box): for each scenario index
    ``idx[r]`` with two accepted estimates,
    ``sat_{a_max}((z2_last − z2_prev) / (t_last − t_prev))`` (m/s²), zero elsewhere
    (:class:`NeighbourAccel`). t (2,N) times (s, NaN for a slot never written) and z2
    (2,N,3) velocities (m/s) in two slots per agent; the later time is the last (an
    estimate is accepted only if newer). sat scales a vector down to norm ``a_max``
    (m/s²) if longer."""
    if out.shape[0] != idx.shape[0] or out.shape[1] != 3:
        raise ValueError("neighbour_accel_rows: out not (M, 3)")
    for r in range(idx.shape[0]):
        j = idx[r]
        if math.isnan(t[0, j]) or math.isnan(t[1, j]):
            out[r, 0], out[r, 1], out[r, 2] = 0.0, 0.0, 0.0
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
