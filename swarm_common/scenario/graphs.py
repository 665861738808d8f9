"""Neighbour (sensing) graphs of a bearing formation and their rigidity check (paper §2.1;
Departure 3; docs/graphs.md). Pure numpy/scipy, no product package imported: the scenario
loader, the feasibility check and ``offboard.estimation.bearing`` all build the graph from here.

Kinds (``formation.graph``, :class:`~swarm_common.enums.GraphKind`), over the agents'
``vertex`` coordinates (scenario order, index pairs ``i < j``):

* ``cube_face_diagonals``: pairs at the shortest vertex distance or √2 times it;
* ``complete``: every pair;
* ``knn``: every vertex to its ``formation.knn_k`` nearest vertices (a vertex tied with the
  k-th nearest is included too, so the graph does not depend on the agents' order),
  symmetrised (an edge if either end chose the other);
* ``range``: every pair within ``formation.sensing_range_m`` in the desired formation (the
  vertices scaled by the leaders' separation, Departure 1);
* ``edges``: the pairs of agent ids listed in ``formation.edges``.

Check (:func:`rigidity_problem`): the sparse bearing Laplacian L (§2.1) must have rank
3N − 4 (null space: translations and scaling; checked as L + QQᵀ positive definite, Q an
orthonormal basis of those four motions) and its follower block L_ff must be positive
definite (the leaders fix every follower's desired position). Small matrices use a dense
eigen-decomposition; larger ones the smallest eigenvalue by shift-invert Lanczos over a
sparse LU (scipy.sparse), so the check stays cheap for a few hundred agents.

The eigenvalues and solves of these matrices are :mod:`swarm_common.scenario.spectra`'s.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from swarm_common.memo import ContentMemo
from swarm_common.scenario.schema import MAX_EDGES, FormationConfig
from swarm_common.scenario.spectra import EIG_TOL, smallest_eig, zero_tol

DIST_TOL = 1e-6  # relative tolerance on vertex distances (ties, ranges)
LEGACY_KINDS = ("cube_edges",)  # accepted by the builders (tests), not by scenario files


@dataclass(frozen=True)
class GraphSpec:
    """Which graph to build: ``kind`` plus the keys it reads (``formation.*``).

    ``scale`` (m per vertex unit) converts ``sensing_range_m`` to vertex units; both are
    only needed by ``range`` and by :func:`sensed_sets` (inf range: unlimited)."""

    kind: str
    knn_k: int = 6
    edges: tuple[tuple[int, int], ...] = ()  # agent ids
    sensing_range_m: float = math.inf
    scale: float = 1.0

    @property
    def range_vu(self) -> float:
        """Sensing range in vertex units."""
        return self.sensing_range_m / self.scale

    def describe(self) -> str:
        """The key that chose the graph, for one-line errors."""
        head = f'formation.graph = "{self.kind}"'
        if self.kind == "knn":
            return f"{head} (knn_k = {self.knn_k})"
        if self.kind == "range":
            return f"{head} (sensing_range_m = {self.sensing_range_m:g})"
        if self.kind == "edges":
            return f"{head} (formation.edges, {len(self.edges)} pairs)"
        return head


def formation_scale(positions: np.ndarray, vertices: np.ndarray, k1: int, k2: int) -> float:
    """Metres per vertex unit: the separation of agents ``k1``, ``k2`` (the first two
    leaders) over their vertex separation (Departure 1)."""
    p, v = np.asarray(positions, float), np.asarray(vertices, float)
    return float(np.linalg.norm(p[k1] - p[k2]) / np.linalg.norm(v[k1] - v[k2]))


def _dist(v: np.ndarray) -> np.ndarray:
    diff = v[:, None, :] - v[None, :, :]
    return np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))


def _upper_pairs(adj: np.ndarray) -> list[tuple[int, int]]:
    i, j = np.nonzero(np.triu(adj | adj.T, 1))
    return [(int(a), int(b)) for a, b in zip(i, j, strict=True)]


def shell_edges(v: np.ndarray, multiples: Sequence[float]) -> list[tuple[int, int]]:
    """Pairs whose distance is one of ``multiples`` times the shortest vertex distance."""
    d = _dist(v)
    off = ~np.eye(len(v), dtype=bool)
    edge = float(d[off].min())
    tol = DIST_TOL * max(1.0, edge)
    adj = np.zeros_like(off)
    for a in multiples:
        adj |= off & (np.abs(d - a * edge) <= tol)
    return _upper_pairs(adj)


def knn_edges(v: np.ndarray, k: int) -> list[tuple[int, int]]:
    """Each vertex to its ``k`` nearest (ties with the k-th included), symmetrised."""
    if k < 1:
        raise ValueError(f"knn_k = {k}: must be >= 1")
    d = _dist(v)
    n = len(v)
    np.fill_diagonal(d, np.inf)
    kk = min(k, n - 1)
    kth = np.sort(d, axis=1)[:, kk - 1]
    adj = d <= (kth * (1.0 + DIST_TOL))[:, None]
    return _upper_pairs(adj)


def range_edges(v: np.ndarray, r: float) -> list[tuple[int, int]]:
    """Pairs at most ``r`` apart (vertex units)."""
    d = _dist(v)
    adj = d <= r * (1.0 + DIST_TOL)
    np.fill_diagonal(adj, False)
    return _upper_pairs(adj)


def close_pairs(x: np.ndarray, r: float) -> set[tuple[int, int]]:
    """Index pairs (i < j) of the rows of ``x`` (N, d) that may be closer than ``r``: every
    pair within ``r`` plus a relative 1e-9 (a k-d tree, O(N log N)), so a caller that tests
    each pair with its own formula misses none; every pair when ``r`` or a coordinate is
    not finite."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    if not (math.isfinite(r) and np.all(np.isfinite(x))):
        return {(i, j) for i in range(n) for j in range(i + 1, n)}
    if n < 2 or r <= 0.0:
        return set()
    return {(int(i), int(j)) for i, j in cKDTree(x).query_pairs(r * (1.0 + 1e-9) + 1e-12)}


def id_edges(ids: Sequence[int], pairs: Sequence[Sequence[int]]) -> list[tuple[int, int]]:
    """Index pairs (i < j, sorted, unique) of id pairs; ValueError for an unknown id, a
    self-loop or a repeated pair (one line naming ``formation.edges``)."""
    pos = {int(a): k for k, a in enumerate(ids)}
    out: set[tuple[int, int]] = set()
    for n, pr in enumerate(pairs):
        a, b = (int(x) for x in pr)
        for x in (a, b):
            if x not in pos:
                raise ValueError(f"formation.edges[{n}] = [{a}, {b}]: id {x} is not an agent id")
        if a == b:
            raise ValueError(f"formation.edges[{n}] = [{a}, {b}]: self-loop")
        e = (min(pos[a], pos[b]), max(pos[a], pos[b]))
        if e in out:
            raise ValueError(f"formation.edges[{n}] = [{a}, {b}]: pair listed twice")
        out.add(e)
    return sorted(out)


def build_edges(v: np.ndarray, spec: GraphSpec, ids: Sequence[int]) -> list[tuple[int, int]]:
    """Undirected edges (i < j) of the graph ``spec`` over vertices ``v`` (N, 3); a
    ValueError (one line) past :data:`~swarm_common.scenario.schema.MAX_EDGES` of them."""
    edges = _kind_edges(np.asarray(v, dtype=float), spec, ids)
    if len(edges) > MAX_EDGES:
        raise ValueError(f"{spec.describe()}: {len(edges)} edges, at most {MAX_EDGES}: use a "
                         "sparser graph")
    return edges


def _kind_edges(v: np.ndarray, spec: GraphSpec, ids: Sequence[int]) -> list[tuple[int, int]]:
    kind = str(spec.kind)
    if kind == "complete":
        n = len(v)
        if n * (n - 1) // 2 > MAX_EDGES:  # not even listed
            raise ValueError(f'formation.graph = "complete": {n} agents have {n * (n - 1) // 2} '
                             f"pairs, at most {MAX_EDGES} edges: use knn or range")
        return [(i, j) for i in range(n) for j in range(i + 1, n)]
    if kind == "cube_face_diagonals":
        return shell_edges(v, (1.0, math.sqrt(2.0)))
    if kind == "cube_edges":
        return shell_edges(v, (1.0,))
    if kind == "knn":
        return knn_edges(v, spec.knn_k)
    if kind == "range":
        return range_edges(v, spec.range_vu)
    if kind == "edges":
        return id_edges(ids, spec.edges)
    raise ValueError(
        f"unknown formation graph {kind!r}; use cube_face_diagonals, complete, knn, range "
        "or edges"
    )


def sensed_sets(
    v: np.ndarray, edges: Sequence[tuple[int, int]], range_vu: float
) -> list[list[int]]:
    """Per index, the agents it senses in the desired formation: graph neighbours and every
    agent within ``range_vu`` (vertex units). Sorted."""
    n = len(v)
    near = _dist(np.asarray(v, float)) <= range_vu * (1.0 + DIST_TOL) if math.isfinite(
        range_vu) else np.ones((n, n), dtype=bool)
    for i, j in edges:
        near[i, j] = near[j, i] = True
    np.fill_diagonal(near, False)
    return [sorted(int(j) for j in np.nonzero(near[i])[0]) for i in range(n)]


def long_edges(
    v: np.ndarray, edges: Sequence[tuple[int, int]], range_vu: float
) -> list[tuple[int, int, float]]:
    """Edges longer than ``range_vu`` (never sensed in the desired formation), with their
    length in vertex units."""
    v = np.asarray(v, float)
    out = []
    for i, j in edges:
        d = float(np.linalg.norm(v[i] - v[j]))
        if d > range_vu * (1.0 + DIST_TOL):
            out.append((i, j, d))
    return out


def bearing(p_i: np.ndarray, p_j: np.ndarray) -> np.ndarray:
    """Unit bearing g_ij from i to j (§2.1)."""
    d = np.asarray(p_j, dtype=float) - np.asarray(p_i, dtype=float)
    return d / np.linalg.norm(d)


def projector(g: np.ndarray) -> np.ndarray:
    """Orthogonal projector P = I − g gᵀ onto the plane normal to g (§2.1)."""
    g = np.asarray(g, dtype=float)
    return np.eye(3) - np.outer(g, g)


def edge_bearings(
    v: np.ndarray, edges: Sequence[tuple[int, int]]
) -> tuple[dict[tuple[int, int], np.ndarray], dict[tuple[int, int], np.ndarray]]:
    """Per edge, in both directions, the desired bearing g*_ij between the vertices and
    its projector P*_ij: ``({(i, j): g*_ij}, {(i, j): P*_ij})``, O(edges)."""
    v = np.asarray(v, dtype=float)
    g_star: dict[tuple[int, int], np.ndarray] = {}
    p_star: dict[tuple[int, int], np.ndarray] = {}
    for i, j in edges:
        for a, b in ((i, j), (j, i)):
            g_star[a, b] = bearing(v[a], v[b])
            p_star[a, b] = projector(g_star[a, b])
    return g_star, p_star


def sparse_laplacian(
    v: np.ndarray,
    edges: Sequence[tuple[int, int]],
    p_star: dict[tuple[int, int], np.ndarray] | None = None,
) -> sp.csr_matrix:
    """(3N, 3N) bearing Laplacian (§2.1): −P*_ij off the diagonal, Σ_k P*_ik on it, with
    P*_ij the projector of the unit bearing from vertex i to vertex j (:func:`edge_bearings`;
    ``p_star``: those already computed).

    The one implementation (the dense form is ``.toarray()``): every 3×3 block is summed
    in edge order, so the same vertices and edges give the same bits in either form."""
    v = np.asarray(v, dtype=float)
    n = len(v)
    if p_star is None:
        p_star = edge_bearings(v, edges)[1]
    blocks: dict[tuple[int, int], np.ndarray] = {}
    for i, j in edges:
        p = p_star[i, j]
        for a, b, s in ((i, j, -1.0), (j, i, -1.0), (i, i, 1.0), (j, j, 1.0)):
            blocks[a, b] = blocks.get((a, b), np.zeros((3, 3))) + s * p
    if not blocks:
        return sp.csr_matrix((3 * n, 3 * n))
    r3, c3 = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    keys = list(blocks)
    rows = np.concatenate([(3 * a + r3).ravel() for a, _ in keys])
    cols = np.concatenate([(3 * b + c3).ravel() for _, b in keys])
    vals = np.concatenate([blocks[k].ravel() for k in keys])
    return sp.coo_matrix((vals, (rows, cols)), shape=(3 * n, 3 * n)).tocsr()


def blocks(idx: Sequence[int]) -> np.ndarray:
    """Row indices of the 3×3 blocks of the agents ``idx``."""
    return np.array([3 * i + k for i in idx for k in range(3)], dtype=int)


def trivial_null_space(v: np.ndarray) -> np.ndarray:
    """(3N, 4) orthonormal basis of the motions every bearing Laplacian of ``v`` annihilates:
    the three translations and the scaling about the centroid (§2.1)."""
    v = np.asarray(v, float)
    n = len(v)
    q = np.zeros((3 * n, 4))
    for a in range(3):
        q[a::3, a] = 1.0 / math.sqrt(n)
    c = (v - v.mean(axis=0)).reshape(-1)
    q[:, 3] = c / np.linalg.norm(c)
    return q


def free_followers(l_ff: np.ndarray, follower_ids: Sequence[int]) -> list[int]:
    """Ids of the followers with a component in the null space of ``l_ff`` (dense)."""
    w, vec = np.linalg.eigh(l_ff)
    null = vec[:, w <= EIG_TOL * max(1.0, float(w[-1]))]
    weight = np.sum(null.reshape(len(follower_ids), 3, -1) ** 2, axis=(1, 2))
    return [int(a) for a, x in zip(follower_ids, weight, strict=True) if x > 1e-6]


def rigidity_problem(
    v: np.ndarray, edges: Sequence[tuple[int, int]], ids: Sequence[int],
    leader_idx: Sequence[int],
) -> str | None:
    """What is wrong with the graph (one line, without the key), or None: λ_min(L_ff) > 0
    (naming the followers the leaders leave free) and rank L = 3N − 4 are required (§2.1,
    Departure 3). Once per content in a process: the loader and the formation both ask
    (two sparse eigenvalue problems, about 2 s at 2,048 agents)."""
    v = np.asarray(v, dtype=float)
    h = hashlib.sha256(np.ascontiguousarray(v).tobytes())
    h.update(repr((list(edges), list(ids), list(leader_idx))).encode())
    return _rigidity.get(h.hexdigest(), lambda: _rigidity_problem(v, edges, ids, leader_idx))


_rigidity: ContentMemo[str | None] = ContentMemo()


def _rigidity_problem(
    v: np.ndarray, edges: Sequence[tuple[int, int]], ids: Sequence[int],
    leader_idx: Sequence[int],
) -> str | None:
    n = len(v)
    lap = sparse_laplacian(v, edges)
    fol = [k for k in range(n) if k not in set(leader_idx)]
    if fol:
        fb = blocks(fol)
        l_ff = lap[fb][:, fb]
        if smallest_eig(l_ff) <= zero_tol(l_ff):
            free = free_followers(l_ff.toarray(), [ids[k] for k in fol])
            names = ", ".join(str(a) for a in free[:12])
            more = f" ({len(free)} in all)" if len(free) > 12 else ""
            return (
                "the bearing Laplacian's follower block is singular: the leaders do not fix "
                f"followers {names}{more}"
            )
    # rank 3N − 4 ⇔ L + Q Qᵀ is positive definite (Q: the trivial null space)
    if n >= 2 and smallest_eig(lap, trivial_null_space(v)) <= zero_tol(lap):
        rank = int(np.sum(np.linalg.eigvalsh(lap.toarray()) > zero_tol(lap)))
        return (
            f"not bearing rigid: the bearing Laplacian has rank {rank}, need 3N-4 = "
            f"{3 * n - 4} (N = {n}); add edges"
        )
    return None


def graph_spec(
    formation: FormationConfig, positions: np.ndarray, vertices: np.ndarray,
    leader_idx: Sequence[int],
) -> GraphSpec:
    """The :class:`GraphSpec` of a scenario's ``[formation]`` (scale from the first two
    leaders' start positions, Departure 1)."""
    k1, k2 = leader_idx[0], leader_idx[1]
    return GraphSpec(
        kind=str(formation.graph),
        knn_k=int(formation.knn_k),
        edges=tuple(formation.edges),
        sensing_range_m=float(formation.sensing_range_m),
        scale=formation_scale(positions, vertices, k1, k2),
    )
