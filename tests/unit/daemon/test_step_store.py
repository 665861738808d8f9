"""offboard.daemon.zenoh.step_store.StepStore against a plain dict trimmed by scanning every key
(the
rule it replaces), over random inserts, trims and deletions from outside."""

from __future__ import annotations

import math

import numpy as np
import pytest

from offboard.daemon.zenoh.step_store import StepStore


def _model_keep_within(d: dict[int, int], lo: float, hi: float) -> None:
    for s in [s for s in d if not lo <= s <= hi]:
        del d[s]


@pytest.mark.parametrize("seed", range(20))
def test_trims_equal_a_full_scan(seed: int) -> None:
    rng = np.random.default_rng(seed)
    store: StepStore[int] = StepStore()
    model: dict[int, int] = {}
    ref = 0
    for i in range(600):
        op = rng.integers(6)
        if op <= 2:  # an insert around the reference (late, current, early)
            step = int(ref + rng.integers(-80, 60))
            store[step] = model[step] = i
        elif op == 3:  # the window around the reference moves (sometimes back)
            ref += int(rng.integers(-3, 6))
            lo, hi = ref - 64, ref + 50
            store.keep_within(lo, hi)
            _model_keep_within(model, lo, hi)
        elif op == 4:  # the "older than the newest minus KEEP" trim
            lowest = int(ref + rng.integers(-90, 10))
            store.keep_from(lowest)
            _model_keep_within(model, lowest, math.inf)
        elif model:  # someone deletes a key directly: the bounds stay conservative
            step = int(rng.choice(list(model)))
            del store[step], model[step]
        assert dict(store) == model
        assert all(store.lo <= s <= store.hi for s in store)


def test_bounds_after_trims_near_and_far() -> None:
    store: StepStore[str] = StepStore()
    assert (store.lo, store.hi) == (math.inf, -math.inf)
    store.keep_within(0, 10)  # nothing to do on an empty store
    for s in (5, 1, 9, 3):
        store[s] = str(s)
    assert (store.lo, store.hi) == (1, 9)
    store.keep_within(2, 8)  # one step beyond each bound: popped by number
    assert sorted(store) == [3, 5] and (store.lo, store.hi) == (2, 8)
    store[100] = "100"  # far beyond: the next trim scans, and its bounds are exact
    store.keep_within(3, 40)
    assert sorted(store) == [3, 5] and (store.lo, store.hi) == (3, 5)
    store.keep_from(6)
    assert store == {} and (store.lo, store.hi) == (math.inf, -math.inf)
    store[7] = "7"
    store.clear()
    assert store == {} and (store.lo, store.hi) == (math.inf, -math.inf)
