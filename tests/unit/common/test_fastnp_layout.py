"""``swarm_common.fastnp.vec3`` / ``rows3`` / ``bools``: the array itself when it already has
the one layout a compiled kernel is compiled for (native float64 or bool, C order), a
converted copy with the same values otherwise."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from swarm_common.fastnp import bools, rows3, vec3
from vehicle_sim.physics.contacts_kernel import pair_distances_kernel


def _kernel_output() -> np.ndarray:
    """A (3,) row of an array a compiled kernel returned: its dtype is an equal object
    of numba's, not numpy's float64 singleton."""
    return pair_distances_kernel(np.zeros((3, 3)))[0]


@pytest.mark.parametrize("x", [
    np.arange(3.0),
    _kernel_output(),
    np.empty(3, dtype=pickle.loads(pickle.dumps(np.dtype(np.float64)))),
])
def test_vec3_returns_a_ready_vector_itself(x: np.ndarray) -> None:
    assert vec3(x) is x


@pytest.mark.parametrize("x", [
    np.arange(6.0)[::2],  # strided
    np.arange(3, dtype=np.float32),
    np.arange(3, dtype=">f8"),  # byte-swapped
    np.arange(3),  # integers
    np.arange(3.0).reshape(1, 3),
])
def test_vec3_converts_anything_else(x: np.ndarray) -> None:
    v = vec3(x)
    assert v is not x
    assert v.dtype == np.float64 and v.dtype.isnative and v.flags.c_contiguous
    assert v.shape == (3,) and np.array_equal(v, np.ravel(x).astype(np.float64))


def test_rows3_returns_ready_rows_itself_and_converts_the_rest() -> None:
    ready = np.arange(12.0).reshape(4, 3)
    assert rows3(ready) is ready
    for x in (np.arange(16.0).reshape(4, 4)[:, :3], np.asfortranarray(ready),
              ready.astype(np.float32), ready.astype(">f8"), np.arange(12.0)):
        r = rows3(x)
        assert r is not x
        assert r.dtype == np.float64 and r.dtype.isnative and r.flags.c_contiguous
        assert np.array_equal(r, np.reshape(np.asarray(x, dtype=np.float64), (-1, 3)))


def test_bools_returns_a_bool_array_itself_and_converts_anything_else() -> None:
    x = np.array([True, False, True])
    assert bools(x) is x
    for other in (x.tolist(), x.astype(np.uint8), np.array([1, 0, 0, 1, 1, 0], bool)[::2]):
        got = bools(other)
        assert got is not other and got.dtype == np.bool_ and got.flags.c_contiguous
        assert got.tolist() == [True, False, True]
