"""The verdict's fence follows what each vehicle stores (gcs.report.world_metrics): a
ground station's upload, reported by the simulator's truth, is scored from its time on for
that vehicle alone, as the filter's prism of it; a stored fence that is not one convex
inclusion polygon is not scored."""

from __future__ import annotations

import numpy as np

from gcs.report.world_metrics import world_metric_values, world_truth
from swarm_common.world.config import parse_world

WORLD = parse_world({"geofence": {"min_m": [-2.0, -2.0, 0.0], "max_m": [9.0, 8.0, 9.5],
                                  "margin_m": 0.5}}, 0.5)
SQUARE = (0.0, 0.0, 8.0, 0.0, 8.0, 7.0, 0.0, 7.0)  # inside the box, x up to 8 m
T = np.arange(0.0, 2.0, 0.02)


def _hover(x: float) -> tuple[np.ndarray, np.ndarray]:
    """Two vehicles at rest for 2 s at (x, 3, 4) and (4, 3, 4)."""
    p = np.zeros((len(T), 2, 3))
    p[:, 0] = [x, 3.0, 4.0]
    p[:, 1] = [4.0, 3.0, 4.0]
    return p, np.zeros_like(p)


def test_an_uploaded_fence_is_scored_from_its_time_for_its_vehicle_only() -> None:
    p, v = _hover(8.5)  # 0.5 m inside the box's x = 9 face, 0.5 m outside the square's
    before = world_truth(WORLD, p, v, 1.0)
    assert before.margin is not None and np.allclose(before.margin[:, 0], 0.5)
    after = world_truth(WORLD, p, v, 1.0, T, ((1.0, 0, SQUARE),), 0.5)
    assert after.margin is not None and after.h_fence is not None
    k = int(np.searchsorted(T, 1.0 - 1e-9))
    assert np.allclose(after.margin[:k, 0], 0.5) and np.allclose(after.margin[k:, 0], -0.5)
    assert np.array_equal(after.margin[:, 1], before.margin[:, 1])  # the other keeps the box
    assert np.all(after.h_fence[k:, 0] < 0.0) and np.all(after.h_fence[:k, 0] >= 0.0)
    assert world_metric_values(after)["fence_min_margin_m"] == -0.5
    # a larger upload takes back a breach of the scenario's box
    p2, v2 = _hover(9.2)
    big = (-3.0, -3.0, 12.0, -3.0, 12.0, 10.0, -3.0, 10.0)
    both = world_truth(WORLD, p2, v2, 1.0, T, ((0.0, 0, big),), 0.5)
    assert both.margin is not None and np.allclose(both.margin[:, 0], 2.8)


def test_a_fence_that_is_not_one_polygon_is_not_scored() -> None:
    p, v = _hover(9.5)  # outside the box
    got = world_truth(WORLD, p, v, 1.0, T, ((0.5, 0, ()),), 0.5)
    assert got.margin is not None and got.h_fence is not None
    k = int(np.searchsorted(T, 0.5 - 1e-9))
    assert np.all(got.margin[:k, 0] < 0.0) and np.all(np.isnan(got.margin[k:, 0]))
    assert world_metric_values(got)["fence_min_margin_m"] == -0.5  # before the change
    # without a scenario fence: only the uploaded one, with the pair barrier's D as margin
    bare = parse_world({}, 0.5)
    up = world_truth(bare, p, v, 1.0, T, ((0.0, 1, SQUARE),), 0.5)
    assert up.margin is not None and np.all(np.isnan(up.margin[:, 0]))
    assert np.allclose(up.margin[:, 1], 3.0)  # (4, 3) in the square: 3 m from y = 0 and x = 0
    assert world_metric_values(up)["fence_min_margin_m"] == 3.0
