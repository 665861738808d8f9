"""Rows of heard neighbours beyond the sensing range (offboard.agent.unsensed, docs/safety.md
§5j): a heard pair gets rows from its prediction where the load check's reach at its
closing speed says it must, and not where its prediction's error reaches into the range."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from offboard.agent.unsensed import HEARD_AFTER_S, UnsensedNeighbours
from swarm_common.scenario.transient_check import pair_reach, speed_for_range

TAU_S, D, A_B, LAG, RANGE = 0.8, 0.5, 5.0, 0.17, 3.0


class _Pred:
    """A predictor stand-in: agents 1..n−1 at positions ``p`` with velocities ``v`` and
    error bounds ``b`` (position, m) and ``bv`` (velocity, m/s), current at t = 1."""

    def __init__(self, p: np.ndarray, v: np.ndarray, b: np.ndarray, bv: np.ndarray) -> None:
        n = len(p)
        rows = np.zeros((n, 12))
        rows[:, 0:3] = p
        self.table = SimpleNamespace(t=np.ones(n), rows=rows)
        self.revision = 1
        self.p, self.v, self.b, self.bv = p, v, b, bv

    def get_at(self, j: int, t: float):
        return self.p[j], self.v[j], np.zeros(12)

    def bound_at(self, j: int, t: float) -> float:
        return float(self.b[j])

    def velocity_bound_at(self, j: int, t: float) -> float:
        return float(self.bv[j])


def _reach(v: float) -> float:
    return pair_reach(v, TAU_S, D, A_B, LAG)


def _rows(p, v, b=None, bv=None, reach=_reach):
    n = len(p)
    pred = _Pred(np.asarray(p, float), np.asarray(v, float),
                 np.zeros(n) if b is None else np.asarray(b, float),
                 np.zeros(n) if bv is None else np.asarray(bv, float))
    un = UnsensedNeighbours(pred, 0, n, RANGE, TAU_S, reach, 0.0)  # type: ignore[arg-type]
    none = np.zeros(0, dtype=np.int64)
    first = un.pairs(0.0, none, pred.p[0], pred.v[0])  # the start transient: in range only
    got = un.pairs(HEARD_AFTER_S, none, pred.p[0], pred.v[0])
    in_range = [] if first is None else first[0].tolist()
    assert set(in_range) <= set([] if got is None else got[0].tolist())
    assert all(np.linalg.norm(pred.p[j] - pred.p[0]) <= RANGE for j in in_range)
    return [] if got is None else got[0].tolist()


def test_reach_is_the_inverse_of_the_range_speed():
    for r in (1.0, 3.0, 6.93, 20.0):
        v = speed_for_range(r, TAU_S, D, A_B, LAG)
        assert _reach(v) == pytest.approx(r, rel=1e-9)
    assert math.isinf(pair_reach(1.0, TAU_S, D, 0.0, LAG))


def test_a_fast_closing_heard_pair_beyond_range_gets_rows():
    # agent 1 at 6 m closing at 4 m/s: the reach at 4 m/s is ≥ 6 m, so it is a row;
    # agent 2 at 6 m at rest relative to agent 0 is not (reach at 0 m/s is D)
    v_fast = 4.0
    assert _reach(v_fast) > 6.0 > _reach(0.0)
    p = [[0, 0, 0], [6, 0, 0], [0, 6, 0]]
    v = [[0, 0, 0], [-v_fast, 0, 0], [0, 0, 0]]
    assert _rows(p, v) == [1]
    # without a reach (rcbf, or the rows kept to the range) neither
    assert _rows(p, v, reach=None) == []


def test_a_prediction_whose_error_reaches_into_the_range_is_not_a_row():
    p = [[0, 0, 0], [6, 0, 0]]
    v = [[0, 0, 0], [-4.0, 0, 0]]
    # margin b + τ b_v = 0.2 + 0.8·3 = 2.6 m: 6 − 2.6 = 3.4 m stays beyond the 3 m range
    assert _rows(p, v, b=[0, 0.2], bv=[0, 3.0]) == [1]
    # 0.2 + 0.8·4 = 3.4 m: the ball reaches 2.6 m, inside the range the sensor sees empty
    assert _rows(p, v, b=[0, 0.2], bv=[0, 4.0]) == []


def test_inside_the_range_every_unsensed_prediction_is_a_row():
    p = [[0, 0, 0], [2.5, 0, 0]]
    v = [[0, 0, 0], [0, 0, 0]]
    assert _rows(p, v, b=[0, 1.0], bv=[0, 5.0]) == [1]
    assert _rows(p, v, b=[0, 1.0], bv=[0, 5.0], reach=None) == [1]
