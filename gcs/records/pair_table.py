"""The pairs a record's ``/pairs`` message holds at each step (docs/records.md).

Up to :data:`~gcs.records.topics.PAIRS_ALL_MAX` pairs (a swarm of up to 64 agents) it
holds every pair i < j, the same pairs at every step, in ``numpy.triu_indices`` order.
Past that, every pair at every step would make a record grow with the square of the swarm
(0.5 s of a 2,048-agent grid wrote 809 MB), so each step holds the
:data:`~gcs.records.topics.PAIRS_PER_AGENT` × N pairs that are closest at that step: the
fewest metres first, a tie going to the pair first in ``triu_indices`` order, listed in
that order. ``min_distance_m`` and ``min_h_m2`` stay the least over every pair.

The closest pairs are found exactly, without the distances of every pair: each agent's
nearest neighbours (a k-d tree) give at least P distinct pairs, so the P-th least of
their distances bounds the P-th least over every pair; every pair within that bound is
measured with the record's own arithmetic (``‖p_i − p_j‖`` as ``numpy.linalg.norm``) and
the P least are kept. A step with a non-finite position measures every pair instead (NaN
last). The same positions give the same pairs, so a record and its run folder export the
same ``pairs.csv``.

Entry points: :func:`pair_table`, :func:`closest_pairs`
(:func:`~gcs.records.topics.recorded_pair_count` counts them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from gcs.records.topics import recorded_pair_count
from gcs.report.pair_barriers import pair_barrier_summary
from gcs.report.verdict import pair_barrier
from swarm_common.barrier import barrier

_BOUND_SLACK = 1e-9  # relative widening of the k-d tree's radius (its own arithmetic)


@dataclass(frozen=True)
class PairTable:
    """The recorded pairs of K steps: column indices ``i`` < ``j`` (K, P) int64, their
    distance (m) and true barrier h (m², docs/safety.md) at each step (K, P), and the
    least h over every pair at each step, ``min_h_m2`` (K,; NaN where a pair's is)."""

    i: np.ndarray
    j: np.ndarray
    distance_m: np.ndarray
    h_m2: np.ndarray
    min_h_m2: np.ndarray


def row_norm(x: np.ndarray) -> np.ndarray:
    """‖x‖ over the last axis (numpy.linalg.norm; NaN rows quietly NaN)."""
    with np.errstate(invalid="ignore"):
        return np.asarray(np.linalg.norm(x, axis=-1))


def _triu_key(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    return i.astype(np.int64) * n + j


def _least(i: np.ndarray, j: np.ndarray, dist: np.ndarray, n: int,
           count: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` pairs of least ``dist`` among (``i``, ``j``), ties by triu order,
    listed in triu order."""
    key = _triu_key(i, j, n)
    order = np.lexsort((key, dist))[:count]  # by distance (NaN last), then triu order
    keep = np.sort(key[order])
    return keep // n, keep % n


def closest_pairs(p: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` closest pairs i < j of the positions ``p`` (N,3) (module docstring),
    as column indices in triu order."""
    n = len(p)
    if not np.isfinite(p).all():
        i, j = np.triu_indices(n, k=1)
        return _least(i, j, row_norm(p[i] - p[j]), n, count)
    tree = cKDTree(p)
    # each agent's k nearest, itself among them or not (coincident agents): at least
    # k − 1 = 2⌈count/N⌉ others each, so at least count distinct pairs
    k = min(n, 2 * -(-count // n) + 1)
    _, nbr = tree.query(p, k=k)
    a = np.repeat(np.arange(n), k)
    b = nbr.reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = np.unique(_triu_key(lo, hi, n)[lo != hi])
    ci, cj = key // n, key % n
    bound = float(np.sort(row_norm(p[ci] - p[cj]))[count - 1])
    near = tree.query_pairs(bound * (1.0 + _BOUND_SLACK) + _BOUND_SLACK,
                            output_type="ndarray")
    ni, nj = np.minimum(near[:, 0], near[:, 1]), np.maximum(near[:, 0], near[:, 1])
    return _least(ni, nj, row_norm(p[ni] - p[nj]), n, count)


def pair_table(p: np.ndarray, v: np.ndarray, tau: float, d_safe: float,
               vertical_scale: float = 1.0) -> PairTable:
    """The recorded pairs of the positions ``p`` and velocities ``v`` (K, N, 3) (m, m/s),
    their barrier with ``tau`` (s), ``d_safe`` (m) and the vertical scale κ."""
    k, n = p.shape[:2]
    count = recorded_pair_count(n)
    if count == n * (n - 1) // 2:  # every pair, as numpy's arrays over all steps
        i, j = np.triu_indices(n, k=1)
        h = pair_barrier(p, v, tau, d_safe, vertical_scale)
        with np.errstate(invalid="ignore"):
            hmin = np.min(h, axis=1) if h.shape[1] else np.full(k, np.nan)
        return PairTable(np.broadcast_to(i, (k, count)), np.broadcast_to(j, (k, count)),
                         row_norm(p[:, i] - p[:, j]), h, hmin)
    ii, jj = np.zeros((k, count), np.int64), np.zeros((k, count), np.int64)
    dist, h, hmin = np.zeros((k, count)), np.zeros((k, count)), np.zeros(k)
    for s in range(k):
        a, b = closest_pairs(p[s], count)
        ii[s], jj[s] = a, b
        dp = p[s, a] - p[s, b]
        dist[s] = row_norm(dp)
        h[s] = barrier(dp, v[s, a] - v[s, b], tau, d_safe, vertical_scale)
        hmin[s] = pair_barrier_summary(p[s:s + 1], v[s:s + 1], tau, d_safe,
                                       vertical_scale).h_min
    return PairTable(ii, jj, dist, h, hmin)
