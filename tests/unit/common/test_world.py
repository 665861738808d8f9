"""The world module (swarm_common.world): closest points of obstacles checked against
brute-force membership and dense sampling, the half-spaces an agent keeps, the verdict's
distances (finite differences) and fence margins, and the ``[[obstacle]]``/``[geofence]``
tables (round trip, one-line refusals naming the key)."""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

from swarm_common.world.config import (
    MAX_OBSTACLES,
    Geofence,
    Obstacle,
    ObstacleKind,
    World,
    WorldError,
    parse_world,
    world_toml,
)
from swarm_common.world.geometry import (
    closest_point,
    fence_margins,
    obstacle_distances,
    world_planes,
)

EXACT = 1e-9  # m: floating-point agreement of exact identities
GRID = 0.02  # m: spacing of the surface grids below (covering radius ≤ GRID/√2 ≈ 0.014)
SAMPLING_TOL = 0.02  # m: how far a grid's nearest point may be beyond the true distance
# (≤ the covering radius by the triangle inequality; measured ≤ 0.01 with these grids)
N_SOLID = 20_000  # points drawn uniformly inside each obstacle

SPHERE = Obstacle(ObstacleKind.SPHERE, (1.0, -2.0, 3.0), 0.4, radius_m=1.5)
CYLINDER = Obstacle(ObstacleKind.CYLINDER, (-1.0, 2.0, 2.0), 0.3, radius_m=0.8,
                    z_range_m=(0.5, 3.5))
BOX = Obstacle(ObstacleKind.BOX, (2.0, 1.0, -1.0), 0.5, size_m=(3.0, 1.2, 2.0), yaw_deg=30.0)
OBSTACLES = (SPHERE, CYLINDER, BOX)
IDS = [str(o.kind) for o in OBSTACLES]


# --- brute-force geometry of each kind (independent of the kernel) -------------------------

def _box_local(o: Obstacle, x: np.ndarray) -> np.ndarray:
    """Points ``x`` (N,3) in the box's frame: x − centre turned by −yaw about z."""
    a = math.radians(o.yaw_deg)
    rot = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                    [0.0, 0.0, 1.0]])  # box frame → world
    return (x - np.array(o.centre_m)) @ rot  # rowwise rotᵀ (x − c)


def _box_world(o: Obstacle, local: np.ndarray) -> np.ndarray:
    a = math.radians(o.yaw_deg)
    rot = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                    [0.0, 0.0, 1.0]])
    return local @ rot.T + np.array(o.centre_m)


def inside(o: Obstacle, x: np.ndarray) -> np.ndarray:
    """(N,) whether each point of ``x`` (N,3) lies strictly inside the obstacle."""
    c = np.array(o.centre_m)
    if o.kind is ObstacleKind.SPHERE:
        return np.linalg.norm(x - c, axis=1) < o.radius_m
    if o.kind is ObstacleKind.CYLINDER:
        rho = np.hypot(x[:, 0] - c[0], x[:, 1] - c[1])
        return (rho < o.radius_m) & (x[:, 2] > o.z_range_m[0]) & (x[:, 2] < o.z_range_m[1])
    half = 0.5 * np.array(o.size_m)
    return np.all(np.abs(_box_local(o, x)) < half, axis=1)


def on_surface(o: Obstacle, q: np.ndarray, tol: float = EXACT) -> np.ndarray:
    """(N,) whether each point of ``q`` (N,3) lies on the obstacle's surface within ``tol``."""
    c = np.array(o.centre_m)
    if o.kind is ObstacleKind.SPHERE:
        return np.abs(np.linalg.norm(q - c, axis=1) - o.radius_m) <= tol
    if o.kind is ObstacleKind.CYLINDER:
        lo, hi = o.z_range_m
        rho = np.hypot(q[:, 0] - c[0], q[:, 1] - c[1])
        side = (np.abs(rho - o.radius_m) <= tol) & (q[:, 2] >= lo - tol) & (q[:, 2] <= hi + tol)
        cap = (((np.abs(q[:, 2] - lo) <= tol) | (np.abs(q[:, 2] - hi) <= tol))
               & (rho <= o.radius_m + tol))
        return side | cap
    half = 0.5 * np.array(o.size_m)
    local = _box_local(o, q)
    within = np.all(np.abs(local) <= half + tol, axis=1)
    on_face = np.any(np.abs(np.abs(local) - half) <= tol, axis=1)
    return within & on_face


def solid_sample(o: Obstacle, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points drawn uniformly inside the obstacle (N,3)."""
    c = np.array(o.centre_m)
    if o.kind is ObstacleKind.SPHERE:
        u = rng.normal(size=(n, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        return c + o.radius_m * rng.random((n, 1)) ** (1.0 / 3.0) * u
    if o.kind is ObstacleKind.CYLINDER:
        rho = o.radius_m * np.sqrt(rng.random(n))
        th = rng.uniform(0.0, 2.0 * math.pi, n)
        z = rng.uniform(*o.z_range_m, n)
        return np.column_stack([c[0] + rho * np.cos(th), c[1] + rho * np.sin(th), z])
    half = 0.5 * np.array(o.size_m)
    return _box_world(o, rng.uniform(-half, half, (n, 3)))


def _grid(lo: float, hi: float) -> np.ndarray:
    return np.linspace(lo, hi, max(2, math.ceil((hi - lo) / GRID) + 1))


def surface_grid(o: Obstacle) -> np.ndarray:
    """Points of the obstacle's surface no further than GRID apart along the surface (N,3)."""
    c = np.array(o.centre_m)
    if o.kind is ObstacleKind.SPHERE:  # latitude rings, each sampled at GRID arc length
        r = o.radius_m
        pts = []
        for phi in _grid(0.0, math.pi * r) / r:
            ring = max(1, math.ceil(2.0 * math.pi * r * math.sin(phi) / GRID))
            th = np.linspace(0.0, 2.0 * math.pi, ring, endpoint=False)
            pts.append(np.column_stack([r * math.sin(phi) * np.cos(th),
                                        r * math.sin(phi) * np.sin(th),
                                        np.full(ring, r * math.cos(phi))]))
        return c + np.vstack(pts)
    if o.kind is ObstacleKind.CYLINDER:
        r, (lo, hi) = o.radius_m, o.z_range_m
        th = np.linspace(0.0, 2.0 * math.pi, math.ceil(2.0 * math.pi * r / GRID),
                         endpoint=False)
        tt, zz = np.meshgrid(th, _grid(lo, hi))
        side = np.column_stack([c[0] + r * np.cos(tt.ravel()), c[1] + r * np.sin(tt.ravel()),
                                zz.ravel()])
        xx, yy = np.meshgrid(_grid(-r, r), _grid(-r, r))
        keep = np.hypot(xx, yy) <= r
        disc = np.column_stack([c[0] + xx[keep], c[1] + yy[keep]])
        caps = [np.column_stack([disc, np.full(len(disc), z)]) for z in (lo, hi)]
        return np.vstack([side, *caps])
    half = 0.5 * np.array(o.size_m)
    faces = []
    for a in range(3):
        b, e = [i for i in range(3) if i != a]
        gb, ge = np.meshgrid(_grid(-half[b], half[b]), _grid(-half[e], half[e]))
        for sign in (-1.0, 1.0):
            f = np.zeros((gb.size, 3))
            f[:, a], f[:, b], f[:, e] = sign * half[a], gb.ravel(), ge.ravel()
            faces.append(f)
    return _box_world(o, np.vstack(faces))


def around(o: Obstacle, n: int, rng: np.random.Generator, pad: float = 1.5) -> np.ndarray:
    """``n`` points uniform in the obstacle's bounding box grown by ``pad`` (m)."""
    pts = surface_grid(o)
    return rng.uniform(pts.min(axis=0) - pad, pts.max(axis=0) + pad, (n, 3))


def closest_all(o: Obstacle, p: np.ndarray) -> np.ndarray:
    """(N,7) the kernel's q, n, d for each point of ``p`` (N,3)."""
    row, res, out = o.row(), np.empty((len(p), 7)), np.empty(7)
    for i, (x, y, z) in enumerate(p):
        closest_point(row, float(x), float(y), float(z), out)
        res[i] = out
    return res


@pytest.fixture(scope="module")
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


# --- closest_point -------------------------------------------------------------------------

@pytest.mark.full
@pytest.mark.parametrize("o", OBSTACLES, ids=IDS)
def test_closest_point_outside(o: Obstacle, rng: np.random.Generator) -> None:
    p = around(o, 600, rng)
    p = p[~inside(o, p)][:300]
    assert len(p) >= 200
    res = closest_all(o, p)
    q, n, d = res[:, :3], res[:, 3:6], res[:, 6]
    assert np.all(on_surface(o, q))
    assert np.all(d > 0.0)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(q + d[:, None] * n, p, rtol=0.0, atol=EXACT)
    # d is |p − q| with q on the surface, so it cannot exceed the true distance; no point of
    # the solid may be nearer than d (exact), and the surface grid's nearest point is within
    # its resolution of d
    near_solid, _ = cKDTree(solid_sample(o, N_SOLID, rng)).query(p)
    assert np.all(near_solid >= d - EXACT)
    near_grid, _ = cKDTree(surface_grid(o)).query(p)
    assert np.all(near_grid >= d - EXACT)
    assert np.all(near_grid - d <= SAMPLING_TOL)


@pytest.mark.parametrize("o", OBSTACLES, ids=IDS)
def test_closest_point_inside(o: Obstacle, rng: np.random.Generator) -> None:
    p = solid_sample(o, 300, rng)
    assert np.all(inside(o, p))
    res = closest_all(o, p)
    q, n, d = res[:, :3], res[:, 3:6], res[:, 6]
    assert np.all(on_surface(o, q))
    assert np.all(d < 0.0)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(q + d[:, None] * n, p, rtol=0.0, atol=EXACT)
    # |d| is the distance to the nearest surface point: never more than any surface point's
    # distance (exact), and the grid's nearest point is within its resolution (SAMPLING_TOL)
    near, _ = cKDTree(surface_grid(o)).query(p)
    assert np.all(-d <= near + EXACT)
    assert np.all(near + d <= SAMPLING_TOL)
    # n points out of the solid at q: a step out leaves it, a step in enters it
    eps = 1e-6
    assert not np.any(inside(o, q + eps * n))
    assert np.all(inside(o, q - eps * n))


@pytest.mark.parametrize("o", OBSTACLES, ids=IDS)
def test_closest_point_normal_supports_solid(o: Obstacle, rng: np.random.Generator) -> None:
    """Inside or out, the solid lies behind the tangent plane at q: nᵀ(x − q) ≤ 0."""
    p = np.vstack([around(o, 150, rng), solid_sample(o, 150, rng)])
    res = closest_all(o, p)
    solid = solid_sample(o, N_SOLID, rng)
    for q, n in zip(res[:, :3], res[:, 3:6], strict=True):
        assert np.max((solid - q) @ n) <= EXACT


def test_closest_point_on_the_axis() -> None:
    """The documented normals at a sphere's centre (+z) and a cylinder's axis (+x)."""
    out = np.empty(7)
    closest_point(SPHERE.row(), *SPHERE.centre_m, out)
    np.testing.assert_allclose(out, [1.0, -2.0, 4.5, 0.0, 0.0, 1.0, -1.5], atol=EXACT)
    closest_point(CYLINDER.row(), -1.0, 2.0, 2.2, out)  # side 0.8, bottom 1.7, top 1.3
    np.testing.assert_allclose(out, [-0.2, 2.0, 2.2, 1.0, 0.0, 0.0, -0.8], atol=EXACT)


# --- world_planes --------------------------------------------------------------------------

FENCE = np.array([[-6.0, -7.0, -4.0], [7.0, 6.0, 6.0]])
FENCE_PLANES = Geofence((-6.0, -7.0, -4.0), (7.0, 6.0, 6.0), 0.6).planes()  # (6, 4) [n, c]
FENCE_MARGIN = 0.6
FAR = Obstacle(ObstacleKind.SPHERE, (50.0, 50.0, 50.0), 0.4, radius_m=1.0)


def _planes(table: np.ndarray, clear: np.ndarray, p: np.ndarray,
            range_m: float) -> tuple[np.ndarray, np.ndarray]:
    normals, offsets = np.full((len(table) + 6, 3), np.nan), np.full(len(table) + 6, np.nan)
    m = world_planes(table, clear, FENCE_PLANES, FENCE_MARGIN, p, range_m, normals, offsets)
    return normals[:m], offsets[:m]


def test_world_planes(rng: np.random.Generator) -> None:
    obstacles = (*OBSTACLES, FAR)
    table = np.array([o.row() for o in obstacles])
    clear = np.array([o.clearance_m for o in obstacles])
    solids = [solid_sample(o, N_SOLID, rng) for o in obstacles]
    range_m = 2.5
    pts = rng.uniform(FENCE[0] - 1.0, FENCE[1] + 1.0, (400, 3))
    seen = np.zeros(len(obstacles), dtype=int)
    for p in pts:
        normals, offsets = _planes(table, clear, p, range_m)
        d = np.array([closest_all(o, p[None])[0, 6] for o in obstacles])
        near = np.flatnonzero(d < range_m)
        faces = [(a, s) for a in range(3) for s in (0, 1)
                 if (p[a] - FENCE[0, a] if s == 0 else FENCE[1, a] - p[a]) < range_m]
        assert len(normals) == len(near) + len(faces)
        seen[near] += 1
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
        for row, k in enumerate(near):  # obstacle planes first, in table order
            n, c = normals[row], offsets[row]
            assert np.max(solids[k] @ n) <= c - clear[k] + EXACT  # the solid is beyond
            assert abs(n @ p - c - (d[k] - clear[k])) <= EXACT
        for row, (a, s) in enumerate(faces, start=len(near)):
            n, c = normals[row], offsets[row]
            e = np.zeros(3)
            e[a] = 1.0 if s == 0 else -1.0
            np.testing.assert_array_equal(n, e)  # the inward normal of that face
            on_face = p.copy()
            on_face[a] = FENCE[s, a]
            assert abs(n @ on_face - c + FENCE_MARGIN) <= EXACT  # face − margin
    assert seen[-1] == 0  # beyond range: never a plane
    assert np.all(seen[:-1] > 20) and np.all(seen[:-1] < len(pts))


def test_world_planes_fence_interior(rng: np.random.Generator) -> None:
    """A point more than the margin inside keeps every fence plane; one less than the margin
    from a face breaks that face's plane."""
    empty, none = np.zeros((0, 11)), np.zeros(0)
    p = rng.uniform(FENCE[0] - 0.5, FENCE[1] + 0.5, (2000, 3))
    y = rng.uniform(FENCE[0] - 0.5, FENCE[1] + 0.5, (2000, 3))
    deep = y[fence_margins(FENCE_PLANES, y) > FENCE_MARGIN]
    shallow = y[fence_margins(FENCE_PLANES, y) < FENCE_MARGIN]
    assert len(deep) > 500 and len(shallow) > 500
    for agent in p[:200]:
        normals, offsets = _planes(empty, none, agent, 1e6)  # every face in range
        assert len(normals) == 6
        assert np.all(deep @ normals.T >= offsets - EXACT)
        assert np.all(np.any(shallow @ normals.T < offsets, axis=1))
    far = np.mean(FENCE, axis=0)  # 6.5, 6.5, 5 m from the faces
    assert len(_planes(empty, none, far, 4.9)[0]) == 0
    assert len(_planes(empty, none, far, 5.1)[0]) == 2  # the z faces only


# --- obstacle_distances --------------------------------------------------------------------

def test_obstacle_distances(rng: np.random.Generator) -> None:
    table = np.array([o.row() for o in OBSTACLES])
    p = rng.uniform(FENCE[0], FENCE[1], (4, 150, 3))
    v = rng.normal(size=(4, 150, 3))
    dist, rate = np.empty((4, 150, 3)), np.empty((4, 150, 3))
    obstacle_distances(table, p, v, dist, rate)
    for k, o in enumerate(OBSTACLES):
        res = closest_all(o, p.reshape(-1, 3))
        np.testing.assert_array_equal(dist[:, :, k].ravel(), res[:, 6])
        n, w = res[:, 3:6], v.reshape(-1, 3)  # nᵀv summed in the kernel's order
        np.testing.assert_array_equal(rate[:, :, k].ravel(),
                                      n[:, 0] * w[:, 0] + n[:, 1] * w[:, 1] + n[:, 2] * w[:, 2])
    # rate = d/dt of the distance along v (central difference, h = 1e-6 s, tolerance 1e-5
    # m/s) at points outside by at least 1 cm (the distance is C¹ outside a convex solid)
    h = 1e-6
    ahead, behind = np.empty_like(dist), np.empty_like(dist)
    obstacle_distances(table, p + h * v, v, ahead, np.empty_like(rate))
    obstacle_distances(table, p - h * v, v, behind, np.empty_like(rate))
    out = dist > 0.01
    assert out.sum() > 1000
    np.testing.assert_allclose(rate[out], ((ahead - behind) / (2 * h))[out], rtol=0, atol=1e-5)


# --- fence_margins -------------------------------------------------------------------------

def test_fence_margins(rng: np.random.Generator) -> None:
    p = rng.uniform(FENCE[0] - 2.0, FENCE[1] + 2.0, (3000, 3))
    got = fence_margins(FENCE_PLANES, p)
    ref = np.empty(len(p))
    for i, x in enumerate(p):
        m = math.inf
        for a in range(3):
            m = min(m, x[a] - FENCE[0, a], FENCE[1, a] - x[a])
        ref[i] = m
    np.testing.assert_allclose(got, ref, rtol=0, atol=EXACT)
    assert fence_margins(FENCE_PLANES, p.reshape(30, 100, 3)).shape == (30, 100)
    inside_fence = np.all((p > FENCE[0]) & (p < FENCE[1]), axis=1)
    assert inside_fence.sum() > 500 and (~inside_fence).sum() > 500
    assert np.all((got > 0) == inside_fence)
    # inside: the distance to the boundary, as the box kernel finds it (d = −margin); outside:
    # the largest per-axis excess, never more than the Euclidean distance
    (cx, cy, cz), (sx, sy, sz) = np.mean(FENCE, axis=0), FENCE[1] - FENCE[0]
    box = Obstacle(ObstacleKind.BOX, (cx, cy, cz), 0.0, size_m=(sx, sy, sz))
    d = closest_all(box, p)[:, 6]
    np.testing.assert_allclose(got[inside_fence], -d[inside_fence], rtol=0, atol=EXACT)
    assert np.all(-got[~inside_fence] <= d[~inside_fence] + EXACT)


# --- parse_world / world_toml --------------------------------------------------------------

D_SAFE = 0.35

DOC: dict[str, Any] = {
    "obstacle": [
        {"kind": "sphere", "centre_m": [1.0, -2.0, 3.0], "radius_m": 1.5, "clearance_m": 0.4},
        {"kind": "cylinder", "centre_m": [-1, 2], "radius_m": 0.8, "z_range_m": [0.5, 3.5]},
        {"kind": "box", "centre_m": [2.0, 1.0, -1.0], "size_m": [3.0, 1.2, 2.0],
         "yaw_deg": 30.0, "clearance_m": 0.5},
        {"kind": "box", "centre_m": [0.1, 0.2, 0.3], "size_m": [1.0, 1.0, 1.0]},
    ],
    "geofence": {"min_m": [-6.0, -7.0, -4.0], "max_m": [7.0, 6.0, 6.0]},
}


def _toml_text(doc: dict[str, Any]) -> str:
    """``doc`` (``world_toml``'s shape) as TOML text (floats by ``repr``)."""
    def val(v: Any) -> str:
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return json.dumps(v) if isinstance(v, str) else repr(v)
    lines: list[str] = []
    for row in doc.get("obstacle", []):
        lines += ["[[obstacle]]", *(f"{k} = {val(v)}" for k, v in row.items())]
    if "geofence" in doc:
        lines += ["[geofence]", *(f"{k} = {val(v)}" for k, v in doc["geofence"].items())]
    return "\n".join(lines) + "\n"


def test_parse_world_values() -> None:
    w = parse_world(DOC, D_SAFE)
    assert w.obstacles[:3] == (SPHERE, Obstacle(ObstacleKind.CYLINDER, (-1.0, 2.0, 2.0),
                                                D_SAFE, radius_m=0.8, z_range_m=(0.5, 3.5)),
                               BOX)
    assert w.obstacles[3].clearance_m == D_SAFE and w.obstacles[3].yaw_deg == 0.0
    assert w.geofence == Geofence((-6.0, -7.0, -4.0), (7.0, 6.0, 6.0), D_SAFE)
    assert w.table.shape == (4, 11) and not w.table.flags.writeable
    np.testing.assert_array_equal(w.table[2], BOX.row())
    np.testing.assert_allclose(w.clearances, [0.4, D_SAFE, 0.5, D_SAFE])
    fence, margin = w.fence_arrays()
    assert margin == D_SAFE
    np.testing.assert_array_equal(fence, FENCE_PLANES)
    empty = parse_world({}, D_SAFE)
    assert empty.empty and empty.table.shape == (0, 11) and empty.fence_arrays()[0].shape == (0, 4)


def test_world_round_trip() -> None:
    w = parse_world(DOC, D_SAFE)
    back = parse_world(world_toml(w), 99.0)  # every default was written out
    assert back == w
    assert back.obstacles == w.obstacles and back.geofence == w.geofence
    np.testing.assert_array_equal(back.table, w.table)
    text = parse_world(tomllib.loads(_toml_text(world_toml(w))), 99.0)
    assert text == w
    assert parse_world(world_toml(World()), D_SAFE) == World()
    fence_only = parse_world({"geofence": DOC["geofence"]}, D_SAFE)
    assert parse_world(world_toml(fence_only), 1.0) == fence_only


def _with(mutate: Callable[[dict[str, Any]], None]) -> dict[str, Any]:
    doc = json.loads(json.dumps(DOC))
    mutate(doc)
    return doc


def _set(path: tuple[Any, ...], value: Any) -> Callable[[dict[str, Any]], None]:
    def f(doc: dict[str, Any]) -> None:
        t = doc
        for k in path[:-1]:
            t = t[k]
        t[path[-1]] = value
    return f


def _del(path: tuple[Any, ...]) -> Callable[[dict[str, Any]], None]:
    def f(doc: dict[str, Any]) -> None:
        t = doc
        for k in path[:-1]:
            t = t[k]
        del t[path[-1]]
    return f


REFUSALS: list[tuple[str, Callable[[dict[str, Any]], None], tuple[str, ...]]] = [
    ("unknown kind", _set(("obstacle", 1, "kind"), "cone"), ("obstacle[1].kind", "cone")),
    ("unknown key", _set(("obstacle", 0, "height_m"), 2.0), ("obstacle[0].height_m",)),
    ("key of another kind", _set(("obstacle", 0, "size_m"), [1.0, 1.0, 1.0]),
     ("obstacle[0].size_m",)),
    ("unknown fence key", _set(("geofence", "floor_m"), 0.0), ("geofence.floor_m",)),
    ("missing radius", _del(("obstacle", 0, "radius_m")), ("obstacle[0].radius_m",)),
    ("missing kind", _del(("obstacle", 2, "kind")), ("obstacle[2].kind",)),
    ("NaN", _set(("obstacle", 0, "radius_m"), math.nan), ("obstacle[0].radius_m", "nan")),
    ("inf in a vector", _set(("obstacle", 2, "centre_m"), [0.0, math.inf, 0.0]),
     ("obstacle[2].centre_m",)),
    ("huge int", _set(("obstacle", 0, "radius_m"), 10**400), ("obstacle[0].radius_m",)),
    ("huge int in a vector", _set(("geofence", "max_m"), [1, 10**400, 1]), ("geofence.max_m",)),
    ("negative radius", _set(("obstacle", 1, "radius_m"), -0.5), ("obstacle[1].radius_m",)),
    ("zero radius", _set(("obstacle", 0, "radius_m"), 0.0), ("obstacle[0].radius_m",)),
    ("bool radius", _set(("obstacle", 0, "radius_m"), True), ("obstacle[0].radius_m",)),
    ("string radius", _set(("obstacle", 0, "radius_m"), "1"), ("obstacle[0].radius_m",)),
    ("negative box size", _set(("obstacle", 2, "size_m"), [1.0, -1.0, 1.0]),
     ("obstacle[2].size_m",)),
    ("short centre", _set(("obstacle", 0, "centre_m"), [1.0, 2.0]), ("obstacle[0].centre_m",)),
    ("cylinder centre of 3", _set(("obstacle", 1, "centre_m"), [1.0, 2.0, 3.0]),
     ("obstacle[1].centre_m",)),
    ("bottom = top", _set(("obstacle", 1, "z_range_m"), [2.0, 2.0]), ("obstacle[1].z_range_m",)),
    ("bottom > top", _set(("obstacle", 1, "z_range_m"), [3.0, 1.0]), ("obstacle[1].z_range_m",)),
    ("negative clearance", _set(("obstacle", 0, "clearance_m"), -0.1),
     ("obstacle[0].clearance_m",)),
    ("yaw out of range", _set(("obstacle", 2, "yaw_deg"), 1000.0), ("obstacle[2].yaw_deg",)),
    ("thin fence", _set(("geofence", "max_m"), [7.0, 6.0, -3.5]),
     ("geofence", "max_m.z", "margin_m")),
    ("fence thinner than 2 margins", _set(("geofence", "margin_m"), 5.0),
     ("geofence", "max_m.z", "margin_m")),
    ("negative fence margin", _set(("geofence", "margin_m"), -1.0), ("geofence.margin_m",)),
    ("missing fence corner", _del(("geofence", "min_m")), ("geofence.min_m",)),
    ("fence not a table", _set(("geofence",), [1, 2]), ("geofence",)),
    ("obstacle not a list", _set(("obstacle",), {"kind": "sphere"}), ("obstacle =", "list")),
    ("obstacle row not a table", _set(("obstacle", 3), "box"), ("obstacle[3]",)),
    ("too many obstacles", _set(("obstacle",), [DOC["obstacle"][0]] * (MAX_OBSTACLES + 1)),
     ("obstacle", "1001", str(MAX_OBSTACLES))),
]


@pytest.mark.parametrize(("mutate", "names"), [r[1:] for r in REFUSALS],
                         ids=[r[0] for r in REFUSALS])
def test_parse_world_refusals(mutate: Callable[[dict[str, Any]], None],
                              names: tuple[str, ...]) -> None:
    with pytest.raises(WorldError) as info:
        parse_world(_with(mutate), D_SAFE)
    msg = str(info.value)
    assert "\n" not in msg and len(msg) < 200, msg
    for name in names:
        assert name in msg, msg


def test_max_obstacles_accepted() -> None:
    w = parse_world({"obstacle": [DOC["obstacle"][0]] * MAX_OBSTACLES}, D_SAFE)
    assert len(w.obstacles) == MAX_OBSTACLES and w.table.shape == (MAX_OBSTACLES, 11)
