"""The world in a formation view's cells (gcs.dashboard.view.world_cells), checked by sampling:
dense points of each solid obstacle and of the fence's edges, projected on the plane, must
fall in the returned cells; every returned cell must have a sample close by; and cells far
from every sample must not be returned."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from gcs.dashboard.view.world_cells import (
    AXES,
    Fit,
    footprint,
    footprint_cells,
    world_cells,
    world_extent,
)
from swarm_common.world.config import Geofence, Obstacle, ObstacleKind, World, make_world

RNG = np.random.default_rng(7)
N = 60_000  # samples inside each solid, and as many on its surface
# a view with an odd offset: no cell boundary falls on a round number
FIT = Fit(m_per_col=0.137, centre_a=0.31, centre_b=-0.22, width=61, height=23)
PLANES = ("xy", "xz", "yz")

OBSTACLES = {
    "sphere": Obstacle(ObstacleKind.SPHERE, (0.5, -0.3, 1.1), 0.5, radius_m=0.9),
    "small sphere": Obstacle(ObstacleKind.SPHERE, (-2.0, 0.9, -0.4), 0.5, radius_m=0.05),
    "cylinder": Obstacle(ObstacleKind.CYLINDER, (1.9, 1.0, 0.4), 0.5, radius_m=0.6,
                         z_range_m=(-0.5, 1.3)),
    "box 30°": Obstacle(ObstacleKind.BOX, (-1.2, 0.4, 0.7), 0.5, size_m=(2.0, 0.8, 1.2),
                        yaw_deg=30.0),
    "box -135°": Obstacle(ObstacleKind.BOX, (2.6, -0.9, -0.6), 0.5, size_m=(1.5, 0.3, 0.5),
                          yaw_deg=-135.0),
    "box 0°": Obstacle(ObstacleKind.BOX, (-2.9, -0.8, 0.2), 0.5, size_m=(0.7, 0.5, 0.9)),
    "box 90°": Obstacle(ObstacleKind.BOX, (0.0, 1.5, -0.2), 0.5, size_m=(1.1, 0.2, 0.3),
                        yaw_deg=90.0),
}


def solid_samples(ob: Obstacle) -> np.ndarray:
    """(2N, 3) m: points uniformly inside the solid and points on its surface."""
    c = np.asarray(ob.centre_m)
    if ob.kind is ObstacleKind.SPHERE:
        d = RNG.normal(size=(2 * N, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        radius = np.concatenate([RNG.uniform(size=N) ** (1 / 3), np.ones(N)])
        return c + ob.radius_m * radius[:, None] * d
    if ob.kind is ObstacleKind.CYLINDER:
        th = RNG.uniform(0, 2 * np.pi, 2 * N)
        rad = ob.radius_m * np.concatenate([np.sqrt(RNG.uniform(size=N)), np.ones(N)])
        z0, z1 = ob.z_range_m
        z = RNG.uniform(z0, z1, 2 * N)
        z[N::2] = np.where(RNG.uniform(size=z[N::2].size) < 0.5, z0, z1)  # rims
        return np.column_stack([c[0] + rad * np.cos(th), c[1] + rad * np.sin(th), z])
    h = 0.5 * np.asarray(ob.size_m)
    local = RNG.uniform(-1, 1, (2 * N, 3)) * h
    face = RNG.integers(0, 3, N)
    local[N + np.arange(N), face] = np.where(RNG.uniform(size=N) < 0.5, -1, 1) * h[face]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    local[:8] = corners * h
    yaw = np.deg2rad(ob.yaw_deg)
    x = np.cos(yaw) * local[:, 0] - np.sin(yaw) * local[:, 1]
    y = np.sin(yaw) * local[:, 0] + np.cos(yaw) * local[:, 1]
    return c + np.column_stack([x, y, local[:, 2]])


def cells_of(fit: Fit, pts: np.ndarray, plane: str) -> set[tuple[int, int]]:
    ia, ib, _, _ = AXES[plane]
    col, row = fit.cells(pts[:, ia], pts[:, ib])
    keep = (col >= 0) & (col < fit.width) & (row >= 0) & (row < fit.height)
    return set(zip(col[keep].tolist(), row[keep].tolist(), strict=True))


def near_cells(fit: Fit, pts: np.ndarray, plane: str, grow: float) -> set[tuple[int, int]]:
    """The cells whose rectangle grown by ``grow`` cells each side holds a sample."""
    ia, ib, _, _ = AXES[plane]
    a0, b0 = fit.centres(np.array([0]), np.array([0]))  # cell (0, 0)'s middle
    u = (pts[:, ia] - a0[0]) / fit.m_per_col  # fractional column
    v = (b0[0] - pts[:, ib]) / fit.m_per_row  # fractional row
    out: set[tuple[int, int]] = set()
    for dc in (-1, 0, 1):
        for dr in (-1, 0, 1):
            c, r = np.rint(u).astype(int) + dc, np.rint(v).astype(int) + dr
            ok = (np.abs(u - c) <= 0.5 + grow) & (np.abs(v - r) <= 0.5 + grow)
            out |= set(zip(c[ok].tolist(), r[ok].tolist(), strict=True))
    return out


def test_fit_maps_a_column_per_m_per_col_and_a_row_per_two():
    col0, row0 = FIT.cell(FIT.centre_a, FIT.centre_b)
    assert (col0, row0) == (30, 11)  # the middle of 61 x 23
    for k in range(-25, 26):
        assert FIT.cell(FIT.centre_a + k * FIT.m_per_col, FIT.centre_b) == (30 + k, 11)
    for k in range(-9, 10):  # up is towards row 0; a row is 2 columns tall
        assert FIT.cell(FIT.centre_a, FIT.centre_b + 2 * k * FIT.m_per_col) == (30, 11 - k)


def test_fit_cells_round_trip_and_match_the_scalar_mapping():
    col, row = np.meshgrid(np.arange(-3, 64), np.arange(-3, 26))
    a, b = FIT.centres(col.ravel(), row.ravel())
    c2, r2 = FIT.cells(a, b)
    assert np.array_equal(c2, col.ravel()) and np.array_equal(r2, row.ravel())
    # a point anywhere within 0.49 cell of a middle stays in that cell
    ja = RNG.uniform(-0.49, 0.49, a.size) * FIT.m_per_col
    jb = RNG.uniform(-0.49, 0.49, b.size) * FIT.m_per_row
    c3, r3 = FIT.cells(a + ja, b + jb)
    assert np.array_equal(c3, col.ravel()) and np.array_equal(r3, row.ravel())
    pts = RNG.uniform(-5, 5, (500, 2))
    cv, rv = FIT.cells(pts[:, 0], pts[:, 1])
    assert [FIT.cell(p, q) for p, q in pts] == list(zip(cv.tolist(), rv.tolist(), strict=True))


@pytest.mark.parametrize("plane", PLANES)
@pytest.mark.parametrize("name", list(OBSTACLES))
def test_every_sample_falls_in_a_returned_cell_and_no_cell_is_far(name, plane):
    ob = OBSTACLES[name]
    pts = solid_samples(ob)
    got = world_cells(make_world((ob,), None), plane, FIT).obstacles[0]
    hit = cells_of(FIT, pts, plane)
    assert hit, "the sample lies in the view"
    assert hit <= got, f"cells of samples missing: {sorted(hit - got)[:5]}"
    # every returned cell has a sample within a quarter cell of its edge
    near = near_cells(FIT, pts, plane, 0.25)
    assert got <= near, f"cells with no sample near: {sorted(got - near)[:5]}"
    # a cell whose middle is farther than 1.5 cell diagonals from every sample is not returned
    ia, ib, _, _ = AXES[plane]
    tree = cKDTree(pts[:, [ia, ib]])
    col, row = np.meshgrid(np.arange(FIT.width), np.arange(FIT.height))
    a, b = FIT.centres(col.ravel(), row.ravel())
    dist, _ = tree.query(np.column_stack([a, b]))
    far = dist > 1.5 * np.hypot(FIT.m_per_col, FIT.m_per_row)
    far_cells = set(zip(col.ravel()[far].tolist(), row.ravel()[far].tolist(), strict=True))
    assert len(far_cells) > FIT.width * FIT.height // 2
    assert not got & far_cells


def test_cells_outside_the_view_are_dropped_and_the_rest_kept():
    """A view 10 cells larger each side, same scale and centre: the same cells, shifted."""
    big = Fit(FIT.m_per_col, FIT.centre_a, FIT.centre_b, FIT.width + 20, FIT.height + 20)
    ob = Obstacle(ObstacleKind.BOX, (4.0, 0.0, 2.6), 0.5, size_m=(2.0, 3.0, 1.0), yaw_deg=20.0)
    for plane in PLANES:
        small_cells = world_cells(make_world((ob,), None), plane, FIT).obstacles[0]
        big_cells = world_cells(make_world((ob,), None), plane, big).obstacles[0]
        shifted = {(c - 10, r - 10) for c, r in big_cells}
        inside = {(c, r) for c, r in shifted if 0 <= c < FIT.width and 0 <= r < FIT.height}
        assert small_cells == inside
        assert len(inside) < len(shifted)  # it does cross the view's edge


def test_an_obstacle_out_of_view_has_no_cells():
    ob = Obstacle(ObstacleKind.SPHERE, (40.0, 40.0, 40.0), 0.5, radius_m=1.0)
    for plane in PLANES:
        assert footprint_cells(footprint(ob, plane), FIT) == frozenset()


def fence_edges(lo: tuple[float, float, float], hi: tuple[float, float, float]):
    """(M, 3) points along the box's 12 edges and, per point, the axis the edge runs along."""
    t = np.linspace(0.0, 1.0, 4001)
    pts, along = [], []
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        for s0 in (lo, hi):
            for s1 in (lo, hi):
                p = np.empty((t.size, 3))
                p[:, axis] = lo[axis] + t * (hi[axis] - lo[axis])
                p[:, others[0]] = s0[others[0]]
                p[:, others[1]] = s1[others[1]]
                pts.append(p)
                along.append(np.full(t.size, axis))
    return np.vstack(pts), np.concatenate(along)


@pytest.mark.parametrize("plane", PLANES)
def test_fence_outline_is_the_cells_of_its_edges(plane):
    lo, hi = (-3.1, -1.4, -1.3), (2.9, 1.05, 0.95)
    world = World(geofence=Geofence(lo, hi, 0.5))
    wc = world_cells(world, plane, FIT)
    ia, ib, _, _ = AXES[plane]
    pts, along = fence_edges(lo, hi)
    assert wc.fence_h == cells_of(FIT, pts[along == ia], plane)
    assert wc.fence_v == cells_of(FIT, pts[along == ib], plane)
    assert len(wc.fence_h & wc.fence_v) == 4  # the corners
    inner = RNG.uniform(0.0, 1.0, (20_000, 3)) * (np.array(hi) - lo) + lo
    gap_a = np.minimum(inner[:, ia] - lo[ia], hi[ia] - inner[:, ia]) > 1.5 * FIT.m_per_col
    gap_b = np.minimum(inner[:, ib] - lo[ib], hi[ib] - inner[:, ib]) > 1.5 * FIT.m_per_row
    assert not cells_of(FIT, inner[gap_a & gap_b], plane) & (wc.fence_h | wc.fence_v)


def test_fence_larger_than_the_view_keeps_the_edges_in_view():
    world = World(geofence=Geofence((-100.0, -1.0, -100.0), (100.0, 1.0, 100.0), 0.5))
    wc = world_cells(world, "xy", FIT)
    assert wc.fence_v == frozenset()  # both x edges are out of view
    rows = {r for _, r in wc.fence_h}
    assert {c for c, _ in wc.fence_h} == set(range(FIT.width)) and len(rows) == 2
    assert world_cells(world, "xz", FIT) == world_cells(World(), "xz", FIT)


def test_world_extent_bounds_every_obstacle_and_the_fence_tightly():
    obs = tuple(OBSTACLES.values())
    fence = Geofence((-5.0, -4.0, -3.0), (6.0, 5.0, 4.0), 0.5)
    for ob in obs:
        ext = world_extent(make_world((ob,), None))
        pts = solid_samples(ob)
        assert (pts >= ext.min(axis=0) - 1e-9).all() and (pts <= ext.max(axis=0) + 1e-9).all()
        # tight: the samples reach within 2 % of the size (the sphere's surface is random)
        size = ext.max(axis=0) - ext.min(axis=0)
        np.testing.assert_allclose(pts.min(axis=0), ext.min(axis=0), atol=0.02 * size.max())
        np.testing.assert_allclose(pts.max(axis=0), ext.max(axis=0), atol=0.02 * size.max())
    ext = world_extent(make_world(obs, fence))
    assert ext.shape == (2 * len(obs) + 2, 3)
    assert np.allclose(ext.min(axis=0), fence.min_m) and np.allclose(ext.max(axis=0), fence.max_m)
    assert world_extent(World()).shape == (0, 3)
