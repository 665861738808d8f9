"""A follower's bookkeeping of the other agents' estimates, against plain references:
``NeighbourAccel`` (two slots per agent, the older overwritten) against a list of every
accepted estimate, and ``NeighbourPredictor.predict_many`` against ``get`` per agent, over
random streams with late, duplicate, out-of-order, stale and unknown-agent estimates."""

from __future__ import annotations

import math

import numpy as np

from offboard.agent_types import NeighbourEstimate
from offboard.neighbour_accel import NeighbourAccel
from offboard.predictor import NeighbourPredictor

IDS = [3, 5, 8, 13, 21]
A_MAX = 6.0


def _estimate(rng: np.random.Generator, aid: int, t: float) -> NeighbourEstimate:
    return NeighbourEstimate(aid, t, rng.normal(size=3), rng.normal(0.0, 3.0, 3),
                             rng.normal(size=3), rng.normal(size=12), bool(aid == 3),
                             bool(rng.random() < 0.8))


def _reference_accel(history: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """The last two accepted estimates' velocity difference, norm-bounded by A_MAX."""
    if len(history) < 2:
        return np.zeros(3)
    (t0, z0), (t1, z1) = history[-2], history[-1]
    a = (z1 - z0) / (t1 - t0)
    n = math.sqrt(float(a @ a))
    return a * (A_MAX / n) if n > A_MAX else a


def test_neighbour_accel_keeps_the_last_two_newer_estimates() -> None:
    rng = np.random.default_rng(3)
    acc = NeighbourAccel(IDS, A_MAX)
    history: dict[int, list[tuple[float, np.ndarray]]] = {aid: [] for aid in IDS}
    for k in range(600):
        batch = {}
        for aid in [*IDS, 99]:  # 99 is not in the scenario: ignored
            if rng.random() < 0.6:
                # mostly the next period, sometimes a repeat or an older one
                t = 0.02 * (k + int(rng.choice([0, 0, 0, -1, -3])))
                batch[aid] = _estimate(rng, aid, t)
        acc.ingest(batch)
        for aid, e in batch.items():
            h = history.get(aid)
            if h is not None and (not h or e.t > h[-1][0] + 1e-9):
                h.append((e.t, e.z2.copy()))
        idx = rng.permutation(len(IDS))[: int(rng.integers(0, len(IDS) + 1))]
        got = acc.rows(idx)
        want = np.array([_reference_accel(history[IDS[j]]) for j in idx]).reshape(-1, 3)
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12)


def test_predict_many_is_get_of_each_agent() -> None:
    rng = np.random.default_rng(4)
    pred = NeighbourPredictor(0.4, 0.02, (4.0, 3.0), (2.0, 2.5), max_age=0.5, a_max=10.0)
    for k in range(300):
        t = 0.02 * k
        batch = {aid: _estimate(rng, aid, t + 0.02 * float(rng.choice([1, 1, 0, -2, -10])))
                 for aid in IDS if rng.random() < 0.5}
        pred.ingest(batch, comm_ok=bool(rng.random() < 0.9))
        ask = [*IDS, 77]  # 77 never heard: None
        many = pred.predict_many(ask, t)
        for aid, got in zip(ask, many, strict=True):
            want = pred.get(aid, t)
            assert (got is None) == (want is None)
            if got is not None and want is not None:
                for a, b in zip(got, want, strict=True):
                    assert np.array_equal(a, b)
