"""Neighbour data ageing in the agent (Departure 16 and communication.max_age_s)."""

from __future__ import annotations

import numpy as np

from offboard.agent_types import NeighbourEstimate
from offboard.predictor import NeighbourPredictor


def _est(t: float) -> NeighbourEstimate:
    xi = np.zeros(12)
    xi[3:6] = [1.0, 0.0, 0.0]  # desired velocity 1 m/s along x
    return NeighbourEstimate(5, t, np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.zeros(3),
                             xi, False)


def test_predicts_through_an_outage_then_drops_stale_data() -> None:
    pred = NeighbourPredictor(2 * np.pi * 0.2, 0.02, (4.0, 4.0), (4.0, 3.0), max_age=1.0)
    pred.ingest({5: _est(0.0)}, comm_ok=True)
    got = pred.get(5, 0.0)
    assert got is not None and np.allclose(got[0], 0.0)
    # 0.5 s later (an outage): predicted forward, on its desired motion (1 m/s along x)
    got = pred.get(5, 0.5)
    assert got is not None
    p, v, _ = got
    assert p[0] > 0.4 and abs(v[0] - 1.0) < 0.05
    # older than max_age: dropped, not extrapolated forever
    assert pred.get(5, 1.2) is None
    # a fresh message brings it back
    pred.ingest({5: _est(1.2)}, comm_ok=True)
    assert pred.get(5, 1.2) is not None
    # during an outage nothing is ingested
    pred.ingest({5: _est(5.0)}, comm_ok=False)
    assert pred.get(5, 5.0) is None
