"""The pairs a follower's filter reads when it is stepped part by part (rcbf, apf, none;
dcbf without its compiled front, :mod:`offboard.safety.dcbf.front`): the sensed pairs, then
the neighbours predicted but not sensed (:mod:`offboard.agent.unsensed`) with their margins
and flags; and the leaders' accelerations that the rcbf filter reads."""

from __future__ import annotations

import numpy as np

from offboard.agent.unsensed import PredictedPairs
from offboard.estimation.peer_table import XI
from offboard.estimation.reference import xi_a
from swarm_common.enums import Method

# (scenario indices (M,), Δp = p_i − p_j (M,3) m, Δv (M,3) m/s, margins (M,) m, predicted (M,))
Pairs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class PairInputs:
    """One follower's part-by-part pair input; ``lead_peers`` the leaders' scenario
    indices."""

    def __init__(self, lead_peers: list[int]) -> None:
        self.lead_peers = list(lead_peers)
        self._zero_rows: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def pairs(self, sel: np.ndarray, dp: np.ndarray, dv: np.ndarray,
              extra: PredictedPairs | None) -> Pairs:
        """The sensed ``sel`` with their Δp, Δv (no margin, not predicted), followed by
        ``extra``'s predicted ones."""
        margin, predicted = self._no_margin(len(sel))
        if extra is None:
            return sel, dp, dv, margin, predicted
        idx, pp, pv, pm = extra
        return (np.concatenate([sel, idx]), np.concatenate([dp, pp]), np.concatenate([dv, pv]),
                np.concatenate([margin, pm]),
                np.concatenate([predicted, np.ones(len(idx), dtype=bool)]))

    def leader_accels(self, method: Method, rows: np.ndarray,
                      have: np.ndarray) -> dict[int, np.ndarray]:
        """The leaders' a* (m/s²) predicted to t_k, by scenario index: the rcbf filter's
        known acceleration of a leader (Departure 13; the other filters do not read it)."""
        if method != Method.RCBF:
            return {}
        return {j: xi_a(rows[j, XI]) for j in self.lead_peers if have[j]}

    def _no_margin(self, m: int) -> tuple[np.ndarray, np.ndarray]:
        """(M,) zero margins and (M,) False predicted flags: the sensed pairs' part, made
        once per M (the filters only read them)."""
        got = self._zero_rows.get(m)
        if got is None:
            got = (np.zeros(m), np.zeros(m, dtype=bool))
            self._zero_rows[m] = got
        return got
