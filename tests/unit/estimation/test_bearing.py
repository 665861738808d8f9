"""Bearing geometry, Laplacian properties and rigidity (paper §2.1; Departure 3)."""

import copy
import dataclasses

import numpy as np
import pytest
from conftest import CUBE8  # noqa: E402

from offboard.estimation.bearing import (
    RigidityError,
    build_formation,
    formation_from_scenario,
)
from offboard.estimation.sensing import Sensor
from swarm_common.scenario.graphs import projector
from swarm_common.scenario.model import load_scenario


@pytest.fixture(scope="module")
def sc():
    return load_scenario(CUBE8)


def test_projector_properties():
    g = np.array([1.0, 2.0, -0.5])
    g /= np.linalg.norm(g)
    p = projector(g)
    assert np.allclose(p, p.T)
    assert np.allclose(p @ p, p)
    assert np.allclose(p @ g, 0.0)
    assert np.isclose(np.trace(p), 2.0)


def test_laplacian_properties(sc):
    f = formation_from_scenario(sc)
    lap = f.laplacian.toarray()
    n = sc.n
    assert len(f.edges) == 24  # 12 edges + 12 face diagonals
    assert np.allclose(lap, lap.T)
    ev = np.linalg.eigvalsh(lap)
    assert ev.min() > -1e-9  # positive semidefinite
    assert f.rank == 3 * n - 4
    # null space: translations and scaling of the desired configuration
    ones = np.kron(np.ones((n, 1)), np.eye(3))
    assert np.allclose(lap @ ones, 0.0)
    assert np.allclose(lap @ f.vertices.reshape(-1), 0.0)
    assert f.lambda_min == pytest.approx(0.19, abs=0.01)
    assert f.lambda_max == pytest.approx(6.65, abs=0.05)


def test_desired_positions_cube(sc):
    f = formation_from_scenario(sc)
    pd = f.desired_positions(sc.initial_positions()[f.leader_idx])
    # edge = leader separation = 4 m (Departure 1); vertex assignment of the scenario
    expect = np.array([4, 0, 2]) + 4.0 * (f.vertices - np.array([1, 0, 0]))
    assert np.allclose(pd, expect)


def test_desired_positions_of_a_series_are_the_per_row_map(sc):
    """desired_positions_series over K rows of leader positions equals desired_positions
    row by row (to the rounding of the summation order), and takes K = 0 (a recording
    with no truth yet)."""
    f = formation_from_scenario(sc)
    rng = np.random.default_rng(4)
    lead = rng.normal(0.0, 5.0, (30, len(f.leader_idx), 3))
    got = f.desired_positions_series(lead)
    assert got.shape == (30, f.n, 3)
    for k in range(30):
        assert np.allclose(got[k], f.desired_positions(lead[k]), rtol=1e-13, atol=1e-12)
    assert f.desired_positions_series(lead[:0]).shape == (0, f.n, 3)


def test_cube_edges_only_is_refused(sc):
    # the 12 cube edges let the cube stretch along an axis: the leaders fix no follower
    with pytest.raises(RigidityError, match='^formation.graph = "cube_edges": .*follower block '
                       'is singular: the leaders do not fix followers 3, 4, 5, 6, 7, 8$'):
        build_formation(sc.ids, sc.leader_ids, sc.vertices(), "cube_edges")


def test_complete_graph_rigid(sc):
    f = build_formation(sc.ids, sc.leader_ids, sc.vertices(), "complete")
    assert f.rank == 3 * sc.n - 4 and f.lambda_min > 0.19


def test_sensing_reproducible_and_exact_without_noise(sc):
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 5, (sc.n, 3))
    v = rng.normal(0, 1, (sc.n, 3))
    quiet = dataclasses.replace(
        sc.sensing, **{f.name: 0.0 for f in dataclasses.fields(sc.sensing)}
    )
    s = Sensor(2, 3, sc.n, quiet, 10.0, seed=1)
    m = s.measure(p, v)
    assert not m.valid[2] and m.valid.sum() == sc.n - 1
    ok = m.valid
    assert np.allclose(m.rel_pos()[ok], (p - p[2])[ok])
    assert np.allclose(m.rel_vel()[ok], (v - v[2])[ok])
    # copied: the sensors of a thread share their outputs (offboard.estimation.sensing)
    a = copy.deepcopy(Sensor(2, 3, sc.n, sc.sensing, 10.0, seed=7).measure(p, v))
    b = Sensor(2, 3, sc.n, sc.sensing, 10.0, seed=7).measure(p, v)
    assert np.array_equal(a.g, b.g) and np.array_equal(a.d, b.d)
    far = Sensor(2, 3, sc.n, sc.sensing, 0.1, seed=7).measure(p, v)
    assert not far.valid.any()
