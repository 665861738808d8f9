"""The pairs a record's /pairs holds (gcs.records.pair_table): every pair up to 64 agents,
as numpy's arrays over all steps; past that the 4 N closest at each step, found with a
k-d tree and checked here against the distances of every pair."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.records import topics as tp
from gcs.records.pair_table import closest_pairs, pair_table
from gcs.report.verdict import pair_barrier


def _brute(p: np.ndarray, count: int) -> np.ndarray:
    """Triu keys i N + j of the ``count`` closest pairs over every pair (ties: triu order)."""
    n = len(p)
    i, j = np.triu_indices(n, 1)
    d = np.linalg.norm(p[i] - p[j], axis=-1)
    key = i * n + j
    return np.sort(key[np.lexsort((key, d))[:count]])


def test_recorded_pair_count() -> None:
    assert [tp.recorded_pair_count(n) for n in (0, 1, 2, 8, 64)] == [0, 0, 1, 28, 2016]
    assert tp.recorded_pair_count(65) == 4 * 65 < 65 * 64 // 2
    assert tp.recorded_pair_count(2048) == 8192


@pytest.mark.parametrize("seed", range(8))
def test_the_closest_pairs_are_those_of_every_pair(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for trial in range(6):
        n = int(rng.integers(65, 260))
        p = rng.normal(0.0, 10.0, (n, 3))
        if trial % 2 == 0:  # a dense cluster: many of the closest pairs share agents
            p[: n // 3] = rng.normal(0.0, 0.2, (n // 3, 3))
        if trial % 3 == 0:  # coincident agents
            p[5] = p[6] = p[7]
        if trial == 5:  # a lattice: many equal distances, ties by triu order
            p = np.round(p / 4.0) * 4.0
        count = tp.recorded_pair_count(n)
        a, b = closest_pairs(p, count)
        assert len(a) == count and np.all(a < b)
        assert np.array_equal(a * n + b, _brute(p, count)), (seed, trial)


def test_a_non_finite_position_ranks_its_pairs_last() -> None:
    rng = np.random.default_rng(3)
    p = rng.normal(0.0, 5.0, (80, 3))
    p[10] = np.nan
    a, b = closest_pairs(p, 320)
    assert not np.any((a == 10) | (b == 10))
    assert np.array_equal(a * 80 + b, _brute(np.where(np.isnan(p), 1e9, p), 320))


def test_up_to_64_agents_every_pair_as_before() -> None:
    rng = np.random.default_rng(4)
    p, v = rng.normal(0, 3, (7, 64, 3)), rng.normal(0, 1, (7, 64, 3))
    tab = pair_table(p, v, 0.8, 0.6, 2.0)
    i, j = np.triu_indices(64, 1)
    h = pair_barrier(p, v, 0.8, 0.6, 2.0)
    assert np.array_equal(tab.i[3], i) and np.array_equal(tab.j[6], j)
    assert np.array_equal(tab.h_m2, h) and np.array_equal(tab.min_h_m2, h.min(axis=1))
    assert np.array_equal(tab.distance_m, np.linalg.norm(p[:, i] - p[:, j], axis=-1))


def test_past_64_agents_the_closest_pairs_and_the_least_barrier_of_all() -> None:
    rng = np.random.default_rng(5)
    k, n = 4, 90
    p, v = rng.normal(0, 6, (k, n, 3)), rng.normal(0, 2, (k, n, 3))
    tab = pair_table(p, v, 0.8, 0.6)
    assert tab.i.shape == (k, 4 * n)
    every = pair_barrier(p, v, 0.8, 0.6)
    for s in range(k):
        assert np.array_equal(tab.i[s] * n + tab.j[s], _brute(p[s], 4 * n))
        dp = p[s, tab.i[s]] - p[s, tab.j[s]]
        dv = v[s, tab.i[s]] - v[s, tab.j[s]]
        h = np.einsum("ij,ij->i", dp, dp) + 1.6 * np.einsum("ij,ij->i", dv, dp) - 0.36
        np.testing.assert_allclose(tab.h_m2[s], h, rtol=0, atol=1e-9)
        # the least barrier is over every pair, not only the recorded ones
        assert tab.min_h_m2[s] == pytest.approx(every[s].min(), abs=1e-9)
