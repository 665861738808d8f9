"""The scenario's obstacles and geofence as character cells of a formation view.

A view (:class:`Fit`) maps metres on two ENU axes (:data:`AXES`: ``xy`` from above, ``xz``
and ``yz`` from the side) to character cells; a row is :data:`ROW_ASPECT` columns tall.
:func:`world_cells` gives the cells each obstacle's footprint covers in that plane and the
cells of the geofence's outline: a box's rectangle in every view; a polygon fence's
polygon from above (each edge sampled at every half cell) and from the side the rectangle
of its extent on that axis by its z range. Footprints: a sphere is a disc; a vertical cylinder a
disc from above and a rectangle from the side; a box a rectangle turned by its yaw from
above, and from the side the axis-aligned extent of the turned box by its z extent.

A cell is the rectangle of points that round to it (:meth:`Fit.cells`), closed: a point
on the line between two cells counts in both. Only cells inside the view are returned.
No Textual here: plain numpy, tested on its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm_common.world.config import Obstacle, ObstacleKind, World

# plane -> (horizontal axis, vertical axis, their labels); ENU indices 0 = E, 1 = N, 2 = U
AXES = {"xy": (0, 1, "E", "N"), "xz": (0, 2, "E", "U"), "yz": (1, 2, "N", "U")}
ROW_ASPECT = 2.0  # a character cell is this many times as tall as it is wide
_EDGE_TOL = 1e-9  # cells, a cell's rectangle grown by this against round-off

Cell = tuple[int, int]  # (column, row); row 0 at the top


@dataclass(frozen=True)
class Fit:
    """How a view maps metres to cells: column ``(a − centre_a)/m_per_col + (width−1)/2``
    and row ``(height−1)/2 − (b − centre_b)/(ROW_ASPECT·m_per_col)``, both rounded."""

    m_per_col: float  # m per column (> 0)
    centre_a: float  # m on the horizontal axis at the middle of the view
    centre_b: float  # m on the vertical axis at the middle of the view
    width: int  # columns
    height: int  # rows

    @property
    def m_per_row(self) -> float:
        return ROW_ASPECT * self.m_per_col

    def cell(self, a: float, b: float) -> Cell:
        """The (column, row) the point (a, b) m falls in (maybe outside the view)."""
        col = round((a - self.centre_a) / self.m_per_col + (self.width - 1) / 2)
        row = round((self.height - 1) / 2 - (b - self.centre_b) / self.m_per_row)
        return col, row

    def cells(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`cell` of arrays of points: (columns, rows) as int arrays."""
        col = np.rint((np.asarray(a, float) - self.centre_a) / self.m_per_col
                      + (self.width - 1) / 2)
        row = np.rint((self.height - 1) / 2
                      - (np.asarray(b, float) - self.centre_b) / self.m_per_row)
        return col.astype(np.int64), row.astype(np.int64)

    def centres(self, col: np.ndarray, row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The point (a, b) m at the middle of each cell; a cell reaches half a column and
        half a row (m_per_col/2, m_per_row/2) either side of it."""
        a = self.centre_a + (np.asarray(col, float) - (self.width - 1) / 2) * self.m_per_col
        b = self.centre_b + ((self.height - 1) / 2 - np.asarray(row, float)) * self.m_per_row
        return a, b


@dataclass(frozen=True)
class WorldCells:
    """The cells of a world in one view."""

    obstacles: tuple[frozenset[Cell], ...]  # per obstacle, in the world's order
    fence_h: frozenset[Cell]  # the fence's edges along the horizontal axis
    fence_v: frozenset[Cell]  # its edges along the vertical axis (corners are in both)


@dataclass(frozen=True)
class Footprint:
    """An obstacle seen in a plane: a disc (``half`` = (r, r), ``disc``) or a rectangle of
    half sides ``half`` (m) turned by ``angle_rad`` (counter-clockwise, a toward b)."""

    centre: tuple[float, float]  # m
    half: tuple[float, float]  # m
    angle_rad: float = 0.0
    disc: bool = False


def footprint(ob: Obstacle, plane: str) -> Footprint:
    """``ob``'s shadow on ``plane`` (module docstring)."""
    ia, ib, _, _ = AXES[plane]
    c = ob.centre_m
    if ob.kind is ObstacleKind.SPHERE:
        return Footprint((c[ia], c[ib]), (ob.radius_m, ob.radius_m), disc=True)
    top = ib != 2
    if ob.kind is ObstacleKind.CYLINDER:
        if top:
            return Footprint((c[ia], c[ib]), (ob.radius_m, ob.radius_m), disc=True)
        z0, z1 = ob.z_range_m
        return Footprint((c[ia], 0.5 * (z0 + z1)), (ob.radius_m, 0.5 * (z1 - z0)))
    hx, hy, hz = (0.5 * s for s in ob.size_m)
    yaw = float(np.deg2rad(ob.yaw_deg))
    if top:
        return Footprint((c[0], c[1]), (hx, hy), angle_rad=yaw)
    co, si = abs(np.cos(yaw)), abs(np.sin(yaw))
    half_a = co * hx + si * hy if ia == 0 else si * hx + co * hy  # the turned box's extent
    return Footprint((c[ia], c[2]), (float(half_a), hz))


def _box_of(fp: Footprint) -> tuple[float, float]:
    """Half extents (m) of the axis-aligned box around a footprint."""
    if fp.disc:
        return fp.half
    co, si = abs(np.cos(fp.angle_rad)), abs(np.sin(fp.angle_rad))
    hu, hv = fp.half
    return float(co * hu + si * hv), float(si * hu + co * hv)


def footprint_cells(fp: Footprint, fit: Fit) -> frozenset[Cell]:
    """The cells of the view that ``fp`` touches (closed cells and footprint)."""
    ea, eb = _box_of(fp)
    pa, pb = fp.centre
    cols, rows = fit.cells(np.array([pa - ea, pa + ea]), np.array([pb + eb, pb - eb]))
    c0, c1 = max(int(cols[0]), 0), min(int(cols[1]), fit.width - 1)
    r0, r1 = max(int(rows[0]), 0), min(int(rows[1]), fit.height - 1)
    if c0 > c1 or r0 > r1:
        return frozenset()
    grid_c, grid_r = np.meshgrid(np.arange(c0, c1 + 1), np.arange(r0, r1 + 1))
    col, row = grid_c.ravel(), grid_r.ravel()
    qa, qb = fit.centres(col, row)
    wa = (0.5 + _EDGE_TOL) * fit.m_per_col  # a cell's half width and half height (m)
    wb = (0.5 + _EDGE_TOL) * fit.m_per_row
    da, db = qa - pa, qb - pb
    if fp.disc:
        ga = np.maximum(np.abs(da) - wa, 0.0)
        gb = np.maximum(np.abs(db) - wb, 0.0)
        hit = ga * ga + gb * gb <= fp.half[0] ** 2
    else:  # separating axes: the view's two and the rectangle's own two
        co, si = np.cos(fp.angle_rad), np.sin(fp.angle_rad)
        hu, hv = fp.half
        du, dv = co * da + si * db, -si * da + co * db
        hit = ((np.abs(da) <= wa + ea) & (np.abs(db) <= wb + eb)
               & (np.abs(du) <= hu + abs(co) * wa + abs(si) * wb)
               & (np.abs(dv) <= hv + abs(si) * wa + abs(co) * wb))
    return frozenset(zip(col[hit].tolist(), row[hit].tolist(), strict=True))


def _inside(cells: set[Cell], fit: Fit) -> frozenset[Cell]:
    return frozenset((c, r) for c, r in cells if 0 <= c < fit.width and 0 <= r < fit.height)


def world_cells(world: World, plane: str, fit: Fit) -> WorldCells:
    """Every obstacle's cells and the fence outline's cells of ``world`` in ``plane``."""
    obstacles = tuple(footprint_cells(footprint(o, plane), fit) for o in world.obstacles)
    fence_h: set[Cell] = set()
    fence_v: set[Cell] = set()
    f = world.geofence
    if f is not None and f.polygon_m and plane == "xy":
        fence_h, fence_v = _polygon_outline(f.polygon_m, fit)
    elif f is not None:  # a box, or a polygon's bounding extent from the side
        ia, ib, _, _ = AXES[plane]
        lo, hi = f.min_m, f.max_m
        c0, r1 = fit.cell(lo[ia], lo[ib])  # r1: the bottom row (rows grow downwards)
        c1, r0 = fit.cell(hi[ia], hi[ib])
        for c in range(max(c0, -1), min(c1, fit.width) + 1):
            fence_h |= {(c, r0), (c, r1)}
        for r in range(max(r0, -1), min(r1, fit.height) + 1):
            fence_v |= {(c0, r), (c1, r)}
    return WorldCells(obstacles, _inside(fence_h, fit), _inside(fence_v, fit))


_MAX_EDGE_SAMPLES = 20_000  # per polygon edge


def _polygon_outline(vertices: tuple[tuple[float, float], ...],
                     fit: Fit) -> tuple[set[Cell], set[Cell]]:
    """The cells (from above) of a fence polygon's edges: an edge that crosses more columns
    than rows goes with the horizontal edges, else with the vertical ones; each vertex is
    in both (a corner)."""
    fence_h: set[Cell] = set()
    fence_v: set[Cell] = set()
    v = np.array(vertices, dtype=float)
    for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
        span_c = abs(b[0] - a[0]) / fit.m_per_col
        span_r = abs(b[1] - a[1]) / fit.m_per_row
        n = int(min(_MAX_EDGE_SAMPLES, np.ceil(2.0 * max(span_c, span_r)) + 1))
        s = np.linspace(0.0, 1.0, max(n, 2))
        col, row = fit.cells(a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]))
        cells = set(zip(col.tolist(), row.tolist(), strict=True))
        (fence_h if span_c >= span_r else fence_v).update(cells)
    corners = set(zip(*(x.tolist() for x in fit.cells(v[:, 0], v[:, 1])), strict=True))
    return fence_h | corners, fence_v | corners


def world_extent(world: World) -> np.ndarray:
    """(N, 3) m ENU points whose per-axis min and max bound every obstacle and the fence
    (two corners of each one's axis-aligned box; a polygon fence's is its bounding box);
    (0, 3) for an empty world."""
    pts: list[tuple[float, float, float]] = []
    for o in world.obstacles:
        c = np.asarray(o.centre_m, float)
        if o.kind is ObstacleKind.SPHERE:
            h = np.full(3, o.radius_m)
        elif o.kind is ObstacleKind.CYLINDER:
            h = np.array([o.radius_m, o.radius_m, 0.5 * (o.z_range_m[1] - o.z_range_m[0])])
        else:
            ea, _ = _box_of(footprint(o, "xz"))
            eb, _ = _box_of(footprint(o, "yz"))
            h = np.array([ea, eb, 0.5 * o.size_m[2]])
        pts += [tuple(c - h), tuple(c + h)]
    if world.geofence is not None:
        pts += [world.geofence.min_m, world.geofence.max_m]
    return np.array(pts, dtype=float).reshape(-1, 3)
