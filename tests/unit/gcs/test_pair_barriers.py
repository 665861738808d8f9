"""The compiled summary of the pair barriers (gcs.report.pair_barriers) against numpy's
whole (steps × pairs) array (gcs.report.verdict.pair_barrier): the same least value (two
implementations: within 1e-12 m² relative; the formula is evaluated in numpy's order),
the same counts and the same onsets below 0, on random swarms that cross, with and without
the vertical scale; and the NaN of a diverged state propagates as numpy's min does."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.report.pair_barriers import pair_barrier_summary
from gcs.report.verdict import onsets, pair_barrier


def _swarm(rng: np.random.Generator, k: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(K, N, 3) positions and velocities of agents drifting through each other."""
    p0 = rng.uniform(-3.0, 3.0, (n, 3))
    vel = rng.normal(0.0, 1.0, (n, 3))
    t = np.arange(k)[:, None, None] * 0.05
    jitter = rng.normal(0.0, 0.05, (k, n, 3))
    return p0[None] + vel[None] * t + jitter, vel[None] + jitter


@pytest.mark.parametrize("kappa", [1.0, 1.7])
def test_summary_equals_the_whole_array(kappa: float) -> None:
    rng = np.random.default_rng(4)
    checked_onsets = 0
    for _ in range(40):
        k, n = int(rng.integers(1, 60)), int(rng.integers(2, 12))
        p, v = _swarm(rng, k, n)
        tau, d = float(rng.uniform(0.1, 1.0)), float(rng.uniform(0.3, 1.5))
        h = pair_barrier(p, v, tau, d, kappa)
        s = pair_barrier_summary(p, v, tau, d, kappa)
        assert s.h_min == pytest.approx(float(h.min()), rel=1e-12, abs=1e-12)
        neg = h < 0.0
        assert s.violation_steps == int(np.any(neg, axis=1).sum())
        assert s.violation_pair_steps == int(neg.sum())
        ks, ms = onsets(neg)
        assert s.onset_steps.tolist() == ks.tolist()
        assert s.onset_pairs.tolist() == ms.tolist()
        np.testing.assert_allclose(s.onset_values, h[ks, ms], rtol=1e-12, atol=1e-12)
        checked_onsets += len(ks)
    assert checked_onsets > 50  # the swarms did cross


def test_more_onsets_than_the_first_buffer() -> None:
    """Pairs that enter and leave h < 0 every other step: thousands of onsets, all kept."""
    k, n = 400, 8
    p = np.zeros((k, n, 3))
    p[:, :, 0] = np.arange(n) * 0.4  # all within D = 1 of a neighbour ...
    p[1::2, :, 0] *= 10.0  # ... on even steps only
    v = np.zeros_like(p)
    s = pair_barrier_summary(p, v, 0.5, 1.0)
    h = pair_barrier(p, v, 0.5, 1.0)
    ks, ms = onsets(h < 0.0)
    assert len(ks) > 1024 and s.onset_steps.tolist() == ks.tolist()
    assert s.onset_pairs.tolist() == ms.tolist()


def test_a_nan_state_gives_a_nan_least_value() -> None:
    rng = np.random.default_rng(2)
    p, v = _swarm(rng, 10, 4)
    p[5, 2, 1] = np.nan
    assert np.isnan(pair_barrier(p, v, 0.5, 1.0).min())
    assert np.isnan(pair_barrier_summary(p, v, 0.5, 1.0).h_min)


def test_bad_shapes_are_refused() -> None:
    with pytest.raises(ValueError, match="expected"):
        pair_barrier_summary(np.zeros((3, 4, 2)), np.zeros((3, 4, 2)), 0.5, 1.0)
