"""Rows of heard neighbours that are not sensed (offboard.agent.unsensed, docs/safety.md §5c
and §5j): a heard pair beyond the sensing range gets rows from its prediction where the
load check's reach at its closing speed says it must, and not where its prediction's error
reaches into the range; stale data is predicted at constant velocity with the bounds of a
follower's largest acceleration."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from offboard.agent.unsensed import HEARD_AFTER_S, UnsensedNeighbours
from offboard.estimation.predictor import NeighbourPredictor
from swarm_common.scenario.transient_check import pair_reach, speed_for_range

TAU_S, D, A_B, LAG, RANGE = 0.8, 0.5, 5.0, 0.17, 3.0
A_MAX = 16.0  # m/s², the stand-in predictor's bound on a follower's acceleration
T_NOW = 10.0  # s, when the rows are asked for


class _Pred:
    """A predictor stand-in: agents with positions ``p`` and velocities ``v`` received at
    ``T_NOW − age`` (followers); ``get_at`` gives current data as received."""

    def __init__(self, p: np.ndarray, v: np.ndarray, age: np.ndarray) -> None:
        n = len(p)
        rows = np.zeros((n, 21))
        rows[:, 0:3], rows[:, 3:6] = p, v
        self.table = SimpleNamespace(t=T_NOW - age, rows=rows, leader=np.zeros(n, bool))
        self.revision, self.a_max, self.max_age, self.drop_bound = 1, A_MAX, 1.0, 1.0

    def get_at(self, j: int, t: float):
        assert t - self.table.t[j] <= 1e-9, "only current data is read through get_at"
        return self.table.rows[j, 0:3], self.table.rows[j, 3:6], np.zeros(12)

    # the predictor's own constant-velocity prediction, over this stand-in's table
    constant_velocity_at = NeighbourPredictor.constant_velocity_at
    _stale = NeighbourPredictor._stale


def _reach(v: float) -> float:
    return pair_reach(v, TAU_S, D, A_B, LAG)


TERMS = (TAU_S, D, A_B, LAG)  # the reach's terms, as UnsensedNeighbours takes them


def _rows(p, v, age=None, reach=TERMS):
    """The rows agent 0 keeps at T_NOW, sensing nobody: {index: (Δp, Δv, margin)}."""
    n = len(p)
    pred = _Pred(np.asarray(p, float), np.asarray(v, float),
                 np.zeros(n) if age is None else np.asarray(age, float))
    un = UnsensedNeighbours(pred, 0, n, RANGE, TAU_S, reach, 0.0)  # type: ignore[arg-type]
    none = np.zeros(0, dtype=np.int64)
    z1, z2 = pred.table.rows[0, 0:3].copy(), pred.table.rows[0, 3:6].copy()
    first = un.pairs(T_NOW - HEARD_AFTER_S, none, z1, z2)  # the start transient: in range only
    got = un.pairs(T_NOW, none, z1, z2)
    out = {} if got is None else {int(j): (a, b, c) for j, a, b, c in zip(*got, strict=True)}
    if first is not None:
        assert all(np.linalg.norm(d) <= RANGE for d in first[1])
    return out


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
    assert list(_rows(p, v)) == [1]
    # without a reach (rcbf, or the rows kept to the range) neither
    assert _rows(p, v, reach=None) == {}


def test_stale_data_is_predicted_at_constant_velocity_with_the_acceleration_bound():
    p = [[0, 0, 0], [6.5, 0, 0]]
    v = [[0, 0, 0], [-4.0, 0, 0]]
    age = 0.1
    rows = _rows(p, v, age=[0.0, age])
    dp, dv, margin = rows[1]
    np.testing.assert_allclose(dp, [-(6.5 - 4.0 * age), 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(dv, [4.0, 0.0, 0.0], atol=1e-12)
    assert margin == pytest.approx(0.5 * A_MAX * age**2 + TAU_S * A_MAX * age)


def test_a_prediction_whose_error_reaches_into_the_range_is_not_a_row():
    p = [[0, 0, 0], [6.5, 0, 0]]
    v = [[0, 0, 0], [-4.0, 0, 0]]
    # age 0.3 s: predicted at 5.3 m with a margin of 0.72 + 0.8·4.8 = 4.56 m, reaching to
    # 0.74 m, inside the 3 m range that the sensor sees empty
    assert _rows(p, v, age=[0.0, 0.3]) == {}
    # age 0.4 s: the position bound 1.28 m is past the drop bound, even in range
    assert _rows([[0, 0, 0], [2.0, 0, 0]], [[0, 0, 0], [0, 0, 0]], age=[0.0, 0.4]) == {}


def test_inside_the_range_every_unsensed_prediction_is_a_row():
    p = [[0, 0, 0], [2.5, 0, 0]]
    v = [[0, 0, 0], [0, 0, 0]]
    assert list(_rows(p, v, age=[0.0, 0.3])) == [1]
    assert list(_rows(p, v, age=[0.0, 0.3], reach=None)) == [1]
