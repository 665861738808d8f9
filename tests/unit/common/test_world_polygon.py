"""The polygon geofence (docs/world.md): its keys and refusals, its half-spaces against a
brute-force distance to the prism, the compiled kernel against a numpy reference, and a box
fence that still gives exactly what the box-only code gave."""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from typing import Any

import numpy as np
import pytest
from conftest import ROOT
from scipy.spatial import ConvexHull

from gcs.report.world_metrics import world_truth
from swarm_common.scenario.files import UnsafeScenarioError, dump_toml
from swarm_common.scenario.model import load_scenario, parse_scenario
from swarm_common.world.config import (
    Geofence,
    World,
    WorldError,
    make_world,
    parse_world,
    polygon_fence,
    world_toml,
)
from swarm_common.world.geometry import fence_margins, world_planes

D_SAFE = 0.5
TOL = 1e-9  # m: the prism distance against the brute force
HEX = [[-3.0, 2.5], [-1.2, -2.2], [7.2, -2.2], [9.0, 2.5], [7.2, 7.2], [-1.2, 7.2]]  # ccw


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261129)


def _fence(**keys: Any) -> dict[str, Any]:
    return {"geofence": {"polygon_m": HEX, "z_range_m": [0.0, 9.5]} | keys}


# --- parsing ------------------------------------------------------------------------------

def test_parse_polygon_either_winding_and_round_trip() -> None:
    w = parse_world(_fence(margin_m=0.7), D_SAFE)
    f = w.geofence
    assert f is not None and f.polygon_m == tuple(tuple(v) for v in HEX)
    assert f.min_m == (-3.0, -2.2, 0.0) and f.max_m == (9.0, 7.2, 9.5) and f.margin_m == 0.7
    cw = parse_world(_fence(polygon_m=HEX[::-1]), D_SAFE).geofence
    assert cw is not None and cw.margin_m == D_SAFE
    # the same half-spaces whichever way it is written (as a set of rows; tolerance 1e-12)
    a, b = f.planes(), cw.planes()
    assert a.shape == b.shape == (8, 4)
    for row in a:
        assert np.min(np.max(np.abs(b - row), axis=1)) < 1e-12
    assert parse_world(world_toml(w), 99.0) == w  # every default written out
    assert parse_world(tomllib.loads(dump_toml(world_toml(w))), 99.0) == w


def test_scenario_file_round_trip_of_a_polygon() -> None:
    sc = load_scenario(ROOT / "scenarios" / "cube8_obstacles.toml")
    fence = parse_world(_fence(), D_SAFE).geofence
    poly = dataclasses.replace(sc, world=make_world(sc.world.obstacles, fence))
    doc = tomllib.loads(dump_toml(poly.to_toml_dict()))
    assert "min_m" not in doc["geofence"] and doc["geofence"]["polygon_m"] == HEX
    back = parse_scenario(doc, "poly.toml")
    assert back.world == poly.world and back.world.geofence == fence


SQUARE = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]
REFUSED: list[tuple[str, dict[str, Any], str]] = [
    ("non-convex arrow", {"polygon_m": [[0, 0], [4, 0], [2, 1], [4, 4], [0, 4]]}, "not convex"),
    ("collinear vertex", {"polygon_m": [[0, 0], [2, 0], [4, 0], [4, 4], [0, 4]]}, "collinear"),
    ("repeated vertex", {"polygon_m": [[0, 0], [4, 0], [4, 0], [4, 4], [0, 4]]}, "repeat"),
    ("zero area", {"polygon_m": [[0, 0], [1, 1], [2, 2]]}, "collinear"),
    ("bow tie", {"polygon_m": [[0, 0], [4, 4], [4, 0], [0, 4]]}, "not convex"),
    ("pentagram", {"polygon_m": [[math.cos(a) * 4, math.sin(a) * 4]
                                 for a in np.arange(5) * 4 * math.pi / 5]}, "crosses itself"),
    ("two vertices", {"polygon_m": [[0, 0], [4, 0]]}, "3 to 64"),
    ("65 vertices", {"polygon_m": [[10 * math.cos(a), 10 * math.sin(a)]
                                   for a in np.arange(65) * 2 * math.pi / 65]}, "3 to 64"),
    ("nan vertex", {"polygon_m": [[0, 0], [4, float("nan")], [4, 4]]}, "polygon_m[1]"),
    ("inf vertex", {"polygon_m": [[0, 0], [math.inf, 0], [4, 4]]}, "polygon_m[1]"),
    ("3-d vertex", {"polygon_m": [[0, 0, 0], [4, 0], [4, 4]]}, "polygon_m[0]"),
    ("not a list", {"polygon_m": "square"}, "3 to 64"),
    ("bottom at top", {"z_range_m": [5.0, 5.0]}, "bottom must be below top"),
    ("bottom above top", {"z_range_m": [6.0, 5.0]}, "bottom must be below top"),
    ("nan z", {"z_range_m": [0.0, math.nan]}, "geofence.z_range_m"),
    ("too low for margin", {"z_range_m": [0.0, 0.9]}, "twice margin_m"),
    ("too thin for margin", {"polygon_m": [[0, 0], [10, 0], [10, 0.8], [0, 0.8]]},
     "narrowest"),
    ("box key beside polygon", {"min_m": [0, 0, 0]}, "geofence.min_m"),
    ("unknown key", {"yaw_deg": 3.0}, "geofence.yaw_deg"),
]


@pytest.mark.parametrize(("what", "keys", "says"), REFUSED, ids=[r[0] for r in REFUSED])
def test_polygon_refusals(what: str, keys: dict[str, Any], says: str) -> None:
    doc = {"geofence": {"polygon_m": SQUARE, "z_range_m": [0.0, 9.0]} | keys}
    with pytest.raises(WorldError) as e:
        parse_world(json.loads(json.dumps(doc)) if "nan" not in what and "inf" not in what
                    else doc, D_SAFE)
    msg = str(e.value)
    assert "\n" not in msg and says in msg and "geofence" in msg, msg


def test_missing_z_range_and_box_with_polygon_key() -> None:
    with pytest.raises(WorldError, match=r"missing key geofence\.z_range_m"):
        parse_world({"geofence": {"polygon_m": SQUARE}}, D_SAFE)
    box = {"min_m": [0, 0, 0], "max_m": [4, 4, 4], "z_range_m": [0, 4]}
    with pytest.raises(WorldError, match=r"geofence\.(min_m|max_m)"):
        parse_world({"geofence": box}, D_SAFE)
    assert parse_world(_fence(polygon_m=SQUARE), D_SAFE).geofence is not None  # a square is fine


# --- the half-spaces against the prism ------------------------------------------------------

def _seg_dist(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (m) of the points ``q`` (N,2) to the segment a–b."""
    e = b - a
    s = np.clip(((q - a) @ e) / (e @ e), 0.0, 1.0)
    return np.linalg.norm(q - (a + s[:, None] * e), axis=1)


def _inside_ray(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Point in polygon by casting a ray along +x and counting crossings."""
    inside = np.zeros(len(q), dtype=bool)
    for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
        straddles = (a[1] > q[:, 1]) != (b[1] > q[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = a[0] + (q[:, 1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        inside ^= straddles & (q[:, 0] < x_cross)
    return inside


def _random_polygon(rng: np.random.Generator) -> np.ndarray:
    pts = rng.normal(size=(int(rng.integers(3, 30)), 2)) * rng.uniform(1.0, 8.0, 2)
    hull = ConvexHull(pts)
    v = pts[hull.vertices]  # counter-clockwise
    return v[::-1] if rng.random() < 0.5 else v


def test_planes_are_the_prism_distance(rng: np.random.Generator) -> None:
    n_in = n_out = 0
    for _ in range(40):
        v = _random_polygon(rng)
        z0 = rng.uniform(-2.0, 2.0)
        z1 = z0 + rng.uniform(3.0, 8.0)
        f = polygon_fence(tuple((float(x), float(y)) for x, y in v), (z0, z1), 0.5)
        planes = f.planes()
        assert planes.shape == (len(v) + 2, 4)
        np.testing.assert_allclose(np.linalg.norm(planes[:, :3], axis=1), 1.0, atol=1e-12)
        lo, hi = np.array(f.min_m) - 1.0, np.array(f.max_m) + 1.0
        p = rng.uniform(lo, hi, (3000, 3))
        got = fence_margins(planes, p)
        inside = _inside_ray(p[:, :2], v) & (p[:, 2] > z0) & (p[:, 2] < z1)
        edge = np.min([_seg_dist(p[:, :2], a, b) for a, b in zip(v, np.roll(v, -1, 0),
                                                                  strict=True)], axis=0)
        truth = np.minimum(edge, np.minimum(p[:, 2] - z0, z1 - p[:, 2]))
        np.testing.assert_allclose(got[inside], truth[inside], rtol=0, atol=TOL)
        assert np.all(got[~inside] < 0.0)
        n_in += int(inside.sum())
        n_out += int((~inside).sum())
    assert n_in > 20_000 and n_out > 20_000


# --- the kernel ---------------------------------------------------------------------------

def _reference(fence: np.ndarray, margin: float, p: np.ndarray,
               range_m: float) -> tuple[np.ndarray, np.ndarray]:
    s = fence[:, 0] * p[0] + fence[:, 1] * p[1] + fence[:, 2] * p[2] - fence[:, 3]
    keep = s < range_m
    return fence[keep, :3], fence[keep, 3] + margin


def _kernel(fence: np.ndarray, margin: float, p: np.ndarray,
            range_m: float) -> tuple[np.ndarray, np.ndarray]:
    normals, offsets = np.full((len(fence), 3), np.nan), np.full(len(fence), np.nan)
    m = world_planes(np.zeros((0, 11)), np.zeros(0), fence, margin, p, range_m, normals,
                     offsets)
    return normals[:m], offsets[:m]


def test_world_planes_polygon_matches_numpy(rng: np.random.Generator) -> None:
    counts = set()
    for _ in range(30):
        v = _random_polygon(rng)
        f = polygon_fence(tuple((float(x), float(y)) for x, y in v), (0.0, 6.0), 0.4)
        fence = f.planes()
        for p in rng.uniform(np.array(f.min_m) - 1.0, np.array(f.max_m) + 1.0, (50, 3)):
            range_m = float(rng.uniform(0.5, 6.0))
            n_ref, c_ref = _reference(fence, 0.4, p, range_m)
            n_got, c_got = _kernel(fence, 0.4, p, range_m)
            np.testing.assert_array_equal(n_got, n_ref)
            np.testing.assert_array_equal(c_got, c_ref)
            counts.add(len(c_got))
    assert 0 in counts and max(counts) >= 5  # both none and many planes were seen
    none = np.zeros((0, 4))
    assert len(_kernel(none, 0.4, np.zeros(3), 1e6)[1]) == 0  # no fence: no plane


# --- a box: exactly the old outputs --------------------------------------------------------

def _old_box_planes(fence: np.ndarray, margin: float, p: np.ndarray,
                    range_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The box-only kernel's fence part as it was, line for line."""
    normals, offsets = [], []
    for a in range(3):
        if p[a] - fence[0, a] < range_m:
            n = [0.0, 0.0, 0.0]
            n[a] = 1.0
            normals.append(n)
            offsets.append(fence[0, a] + margin)
        if fence[1, a] - p[a] < range_m:
            n = [0.0, 0.0, 0.0]
            n[a] = -1.0
            normals.append(n)
            offsets.append(-(fence[1, a] - margin))
    return np.array(normals).reshape(-1, 3), np.array(offsets)


def _old_margins(fence: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.minimum(np.min(p - fence[0], axis=-1), np.min(fence[1] - p, axis=-1))


def _old_rate(fence: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
    both = np.concatenate([p - fence[0], fence[1] - p], axis=-1)
    face = np.argmin(both, axis=-1)
    return np.take_along_axis(np.concatenate([v, -v], axis=-1), face[..., None], -1)[..., 0]


def test_box_is_bit_identical_to_the_old_box(rng: np.random.Generator) -> None:
    for _ in range(20):
        lo = rng.uniform(-20.0, 0.0, 3)
        hi = lo + rng.uniform(2.0, 30.0, 3)
        margin = float(rng.uniform(0.1, 0.9))
        box = np.array([lo, hi])
        f = Geofence(tuple(lo.tolist()), tuple(hi.tolist()), margin)
        planes = f.planes()
        assert not np.any(np.signbit(planes[:, :3]) & (planes[:, :3] == 0.0))  # no −0
        p = rng.uniform(lo - 3.0, hi + 3.0, (400, 3))
        assert np.array_equal(fence_margins(planes, p), _old_margins(box, p))
        for x in p[:100]:
            range_m = float(rng.uniform(0.5, 20.0))
            n_old, c_old = _old_box_planes(box, margin, x, range_m)
            n_new, c_new = _kernel(planes, margin, x, range_m)
            assert n_new.tobytes() == n_old.tobytes() and c_new.tobytes() == c_old.tobytes()
        v = rng.normal(size=(50, 8, 3))
        pk = rng.uniform(lo - 1.0, hi + 1.0, (50, 8, 3))
        truth = world_truth(World(geofence=f), pk, v, 0.7)
        assert truth.margin is not None and truth.h_fence is not None
        assert np.array_equal(truth.margin, _old_margins(box, pk))
        old_h = _old_margins(box, pk) - margin + 0.7 * _old_rate(box, pk, v)
        assert np.array_equal(truth.h_fence, old_h)


def test_polygon_truth_rate_is_the_margin_derivative(rng: np.random.Generator) -> None:
    """h_fence's rate term is d/dt of the margin along v (central difference, h = 1e-7 s,
    tolerance 1e-5 m/s) away from the prism's ridges (where the nearest face changes)."""
    f = parse_world(_fence(), D_SAFE).geofence
    assert f is not None
    p = rng.uniform(np.array(f.min_m), np.array(f.max_m), (1, 4000, 3))
    v = rng.normal(size=p.shape)
    w = World(geofence=f)
    t = world_truth(w, p, v, 1.0)
    assert t.margin is not None and t.h_fence is not None
    rate = t.h_fence - t.margin + f.margin_m  # τ = 1 s
    h = 1e-7
    ahead = world_truth(w, p + h * v, v, 1.0).margin
    behind = world_truth(w, p - h * v, v, 1.0).margin
    assert ahead is not None and behind is not None
    d = _face_gap(f.planes(), p[0])
    ok = (d > 1e-3) & (t.margin[0] > 0)
    assert ok.sum() > 1000
    np.testing.assert_allclose(rate[0][ok], ((ahead - behind) / (2 * h))[0][ok], rtol=0,
                               atol=1e-5)


def _face_gap(planes: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The gap (m) between the nearest and second-nearest face of each point."""
    s = np.sort(p @ planes[:, :3].T - planes[:, 3], axis=1)
    return s[:, 1] - s[:, 0]


# --- checked at load ----------------------------------------------------------------------

SLANT = 6.4 + 0.3 * math.sqrt(2)  # the line x + y = SLANT passes 0.3 m inside agent 7 at
# (6, 0.4) and leaves agent 8 at (6, 3.6) (9.6 − SLANT)/√2 = 1.96 m outside


@pytest.mark.parametrize(("fence", "says"), [
    ({"polygon_m": [[-2.0, -2.0], [6.2, -2.0], [6.2, 7.0], [-2.0, 7.0]]},  # agents 7, 8 at x = 6
     "agent 7 starts 0.20 m inside it (nearest face: side polygon_m[1]–[2])"),
    ({"polygon_m": [[-2.0, -2.0], [-2.0, SLANT + 2.0], [SLANT + 2.0, -2.0]]},  # clockwise
     f"agent 8 starts {(9.6 - SLANT) / math.sqrt(2):.2f} m outside it (nearest face: side "
     "polygon_m[2]–[1])"),
    ({"polygon_m": [[-2.0, -2.0], [5.5, -2.0], [5.5, 7.0], [-2.0, 7.0]]},
     "agent 7 starts 0.50 m outside it (nearest face: side polygon_m[1]–[2])"),
    ({"polygon_m": [[-2.0, -2.0], [8.0, -2.0], [8.0, 7.0], [-2.0, 7.0]],
      "z_range_m": [2.1, 9.5]}, "agent 8 starts 0.10 m outside it (nearest face: floor)"),
    ({"min_m": [-2.0, -2.0, 0.0], "max_m": [6.2, 7.0, 9.5]},
     "agent 7 starts 0.20 m inside it (nearest face: max_m.x)"),
])
def test_load_check_names_the_agent_and_face(fence: dict[str, Any], says: str) -> None:
    with open(ROOT / "scenarios" / "cube8_obstacles.toml", "rb") as fh:
        doc = tomllib.load(fh)
    doc["geofence"] = {"z_range_m": [0.0, 9.5]} | fence if "polygon_m" in fence else fence
    with pytest.raises(UnsafeScenarioError) as e:
        parse_scenario(doc, "poly.toml")
    assert f"geofence: {says}, less than geofence.margin_m = 0.5;" in str(e.value)
