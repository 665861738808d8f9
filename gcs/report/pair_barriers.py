"""The true barrier of every pair at every step, summarised as the metrics and the verdict
read it, without keeping the (steps × pairs) array (docs/metrics.md).

A run of N agents over K steps has K·N(N−1)/2 pair barriers: at 1,024 agents and 10 s
(500 steps) 262 million, 2 GB as float64, more with the temporaries of numpy's formula.
The metrics need only their least value and two counts, and the verdict only the steps
where a pair's barrier goes below 0 (its onsets). :func:`pair_barrier_summary` computes
them in one compiled pass over the steps and pairs (O(N²K) time, O(N²) memory: the
previous step's signs), each pair's h from the filters' compiled formula
(:func:`offboard.safety.pair_kernel.pair_h`, summed in the order numpy sums
:func:`swarm_common.barrier.barrier`), the z components divided by κ first
(``controller.dcbf_vertical_scale``). The pairs are
numbered as ``np.triu_indices(N, 1)`` numbers them (i < j, row by row).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offboard.safety.pair_kernel import pair_h
from swarm_common.jit import kernel


@dataclass(frozen=True)
class PairBarrierSummary:
    """What the metrics and the verdict read of the pair barriers of a run."""

    h_min: float  # m², the least over pairs and steps (inf without pairs or steps; NaN if any)
    violation_steps: int  # steps where some pair has h < 0
    violation_pair_steps: int  # (step, pair) samples with h < 0
    onset_steps: np.ndarray  # (E,) int64: the step of each onset of h < 0 ...
    onset_pairs: np.ndarray  # (E,) int64: ... its pair (triu numbering) ...
    onset_values: np.ndarray  # (E,) float64: ... and h there (m²); by step, then pair


@kernel
def _summary_kernel(
    p: np.ndarray, v: np.ndarray, two_tau: float, d2: float, kappa: float,
    onset_k: np.ndarray, onset_m: np.ndarray, onset_h: np.ndarray,
) -> tuple[float, int, int, int]:
    """(h_min, violation steps, violation pair-steps, onsets found) over p, v (K, N, 3);
    the first ``len(onset_k)`` onsets are written to onset_k, onset_m, onset_h (the count
    may exceed it: the caller then calls again with room for all)."""
    k_steps, n = p.shape[0], p.shape[1]
    prev = np.zeros(n * (n - 1) // 2, dtype=np.bool_)
    h_min = np.inf
    steps = 0
    pair_steps = 0
    found = 0
    cap = onset_k.shape[0]
    for k in range(k_steps):
        m = 0
        any_neg = False
        for i in range(n):
            for j in range(i + 1, n):
                d0 = p[k, i, 0] - p[k, j, 0]
                d1 = p[k, i, 1] - p[k, j, 1]
                d2z = p[k, i, 2] - p[k, j, 2]
                w0 = v[k, i, 0] - v[k, j, 0]
                w1 = v[k, i, 1] - v[k, j, 1]
                w2 = v[k, i, 2] - v[k, j, 2]
                if kappa != 1.0:
                    d2z = d2z / kappa
                    w2 = w2 / kappa
                h = pair_h(d0, d1, d2z, w0, w1, w2, two_tau, d2)
                if h < h_min or h != h:  # a NaN (a diverged state) is the least, as in numpy
                    h_min = h if h_min == h_min else h_min
                neg = h < 0.0
                if neg:
                    any_neg = True
                    pair_steps += 1
                    if not prev[m]:
                        if found < cap:
                            onset_k[found] = k
                            onset_m[found] = m
                            onset_h[found] = h
                        found += 1
                prev[m] = neg
                m += 1
        if any_neg:
            steps += 1
    return h_min, steps, pair_steps, found


def pair_barrier_summary(
    p: np.ndarray, v: np.ndarray, tau: float, d_safe: float, vertical_scale: float = 1.0,
) -> PairBarrierSummary:
    """The :class:`PairBarrierSummary` of true positions ``p`` and velocities ``v``
    (K, N, 3; m, m/s), with the barrier's τ (s), D (m) and κ (module docstring)."""
    p = np.ascontiguousarray(p, dtype=np.float64)
    v = np.ascontiguousarray(v, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3 or v.shape != p.shape:
        raise ValueError(f"positions {p.shape} and velocities {v.shape}: expected (K, N, 3)")
    two_tau, d2, kappa = 2.0 * float(tau), float(d_safe) ** 2, float(vertical_scale)
    cap = 1024
    while True:
        ok, om, oh = np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty(cap)
        h_min, steps, pair_steps, found = _summary_kernel(p, v, two_tau, d2, kappa, ok, om, oh)
        if found <= cap:
            return PairBarrierSummary(float(h_min), int(steps), int(pair_steps), ok[:found],
                                      om[:found], oh[:found])
        cap = found
