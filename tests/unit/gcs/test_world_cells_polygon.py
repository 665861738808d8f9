"""A polygon geofence in the dashboard's views (gcs.dashboard.view.world_cells): its outline from
above, and from the side the rectangle of its extent by its z range."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.dashboard.view.world_cells import Fit, world_cells
from swarm_common.world.config import Geofence, World, polygon_fence

# a view with an odd offset: no cell boundary falls on a round number
FIT = Fit(m_per_col=0.137, centre_a=0.31, centre_b=-0.22, width=61, height=23)
HEXAGON = ((-3.4, -1.5), (-1.5, -2.1), (3.0, -1.9), (3.4, 1.0), (2.0, 1.6), (-3.2, 1.2))
FENCE = polygon_fence(HEXAGON, (-1.0, 0.9), 0.3)


def _dense(a: np.ndarray, b: np.ndarray, n: int = 20_000) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)[:, None]
    return a + s * (b - a)


EDGES = [(np.array(a), np.array(b)) for a, b in zip(HEXAGON, HEXAGON[1:] + HEXAGON[:1],
                                                     strict=True)]


def _touching(cells: frozenset[tuple[int, int]], pts: np.ndarray) -> set[tuple[int, int]]:
    """The ``cells`` whose closed rectangle holds one of ``pts`` (dense: 1e-3 cell slack)."""
    drawn = sorted(cells)
    qa, qb = FIT.centres(*np.array(drawn).T)
    da = np.abs(pts[:, 0][None] - qa[:, None]) / FIT.m_per_col
    db = np.abs(pts[:, 1][None] - qb[:, None]) / FIT.m_per_row
    hit = np.any((da <= 0.5 + 1e-3) & (db <= 0.5 + 1e-3), axis=1)
    return {c for c, h in zip(drawn, hit, strict=True) if h}


@pytest.mark.full
def test_polygon_outline_from_above_follows_its_edges() -> None:
    wc = world_cells(World(geofence=FENCE), "xy", FIT)
    outline = wc.fence_h | wc.fence_v
    pts = np.vstack([_dense(a, b) for a, b in EDGES])
    # every drawn cell's closed rectangle touches an edge
    assert _touching(outline, pts) == set(outline)
    # every cell an edge passes through is drawn or next to a drawn one (a clipped corner)
    col, row = FIT.cells(pts[:, 0], pts[:, 1])
    drawn = np.array(sorted(outline))
    cheb = np.max(np.abs(np.stack([col, row], 1)[:, None] - drawn[None]), axis=2).min(axis=1)
    assert np.all(cheb <= 1) and np.mean(cheb == 0) > 0.9
    # a thin line: no more cells than the segments cross (1 + grid lines crossed per edge)
    cross = sum(1 + np.ceil(abs(b[0] - a[0]) / FIT.m_per_col)
                + np.ceil(abs(b[1] - a[1]) / FIT.m_per_row) for a, b in EDGES)
    assert len(outline) <= cross
    # each vertex is a corner (in both sets); the outline has no gap (8-connected)
    for corner in zip(*(x.tolist() for x in FIT.cells(*np.array(HEXAGON).T)), strict=True):
        assert corner in wc.fence_h and corner in wc.fence_v
    seen: set[tuple[int, int]] = set()
    todo = [next(iter(outline))]
    while todo:
        c, r = todo.pop()
        if (c, r) in seen:
            continue
        seen.add((c, r))
        todo += [(c + i, r + j) for i in (-1, 0, 1) for j in (-1, 0, 1) if (c + i, r + j)
                 in outline]
    assert seen == outline


def test_polygon_edges_go_with_their_direction() -> None:
    """Away from the corners, a mostly horizontal edge (in cells) draws with ┄ (fence_h), a
    mostly vertical one with ┆ (fence_v)."""
    wc = world_cells(World(geofence=FENCE), "xy", FIT)
    corners = [FIT.cell(*v) for v in HEXAGON]
    n_wide = n_tall = 0
    for a, b in EDGES:
        wide = abs(b[0] - a[0]) / FIT.m_per_col >= abs(b[1] - a[1]) / FIT.m_per_row
        mine = {c for c in _touching(wc.fence_h | wc.fence_v, _dense(a, b))
                if min(max(abs(c[0] - k[0]), abs(c[1] - k[1])) for k in corners) > 1}
        assert mine and mine <= (wc.fence_h if wide else wc.fence_v)
        assert not mine & (wc.fence_v if wide else wc.fence_h)
        n_wide, n_tall = n_wide + wide, n_tall + (not wide)
    assert n_wide >= 2 and n_tall >= 2  # both kinds were checked


@pytest.mark.parametrize("plane", ["xz", "yz"])
def test_polygon_from_the_side_is_its_extent(plane: str) -> None:
    box = Geofence(FENCE.min_m, FENCE.max_m, FENCE.margin_m)
    assert FENCE.min_m[:2] == (-3.4, -2.1) and FENCE.max_m[:2] == (3.4, 1.6)
    assert world_cells(World(geofence=FENCE), plane, FIT) == world_cells(World(geofence=box),
                                                                         plane, FIT)
