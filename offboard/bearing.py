"""Bearing geometry, neighbour graph and bearing Laplacian (paper §2.1).

* ``g_ij = (p_j − p_i)/‖p_j − p_i‖`` and ``P_ij = I₃ − g_ij g_ijᵀ`` (§2.1).
* Desired bearings ``g*_ij`` come from the agents' formation ``vertex`` coordinates.
* Neighbour graph (Departure 3): ``"cube_face_diagonals"`` links pairs whose vertex distance
  is the shortest one (cube edge) or √2 times it (face diagonal); ``"complete"`` links all.
* Bearing Laplacian ``L`` (§2.1) with blocks ``−P*_ij`` off-diagonal and ``Σ_k P*_ik`` on
  the diagonal, partitioned into leaders/followers (``L_ff``, ``L_fl``).
* Rigidity check (Departure 3): ``rank L = 3N − 4`` (null space = translations + scaling) and
  ``λ_min(L_ff) > 0``; otherwise :class:`RigidityError`.

Agents are addressed by their *index* in scenario order; ``ids`` maps index → id.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class RigidityError(ValueError):
    """The formation's bearing graph is not bearing rigid or leaders do not fix it."""


def bearing(p_i: np.ndarray, p_j: np.ndarray) -> np.ndarray:
    """Unit bearing g_ij from i to j (§2.1)."""
    d = np.asarray(p_j, dtype=float) - np.asarray(p_i, dtype=float)
    return d / np.linalg.norm(d)


def projector(g: np.ndarray) -> np.ndarray:
    """Orthogonal projector P = I − g gᵀ onto the plane normal to g (§2.1)."""
    g = np.asarray(g, dtype=float)
    return np.eye(3) - np.outer(g, g)


def build_edges(vertices: np.ndarray, kind: str, tol: float = 1e-6) -> list[tuple[int, int]]:
    """Undirected edges (i < j) of the neighbour graph over the vertex coordinates."""
    v = np.asarray(vertices, dtype=float)
    n = len(v)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if kind == "complete":
        return pairs
    dist = {pr: float(np.linalg.norm(v[pr[0]] - v[pr[1]])) for pr in pairs}
    allowed: tuple[float, ...]
    if kind == "cube_edges":
        allowed = (1.0,)
    elif kind == "cube_face_diagonals":
        allowed = (1.0, np.sqrt(2.0))
    else:
        raise ValueError(f"unknown formation graph {kind!r}; use cube_face_diagonals or complete")
    edge = min(dist.values())
    tol_abs = tol * max(1.0, edge)
    return [pr for pr in pairs if any(abs(dist[pr] - a * edge) <= tol_abs for a in allowed)]


def bearing_laplacian(vertices: np.ndarray, edges: list[tuple[int, int]]) -> np.ndarray:
    """(3N, 3N) bearing Laplacian of the desired bearings (§2.1)."""
    v = np.asarray(vertices, dtype=float)
    n = len(v)
    lap = np.zeros((3 * n, 3 * n))
    for i, j in edges:
        pij = projector(bearing(v[i], v[j]))
        lap[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] -= pij
        lap[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] -= pij
        lap[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += pij
        lap[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] += pij
    return lap


def _blocks(idx: list[int]) -> np.ndarray:
    return np.array([3 * i + k for i in idx for k in range(3)], dtype=int)


@dataclass
class Formation:
    """Desired bearing formation over N agents (scenario order)."""

    ids: list[int]
    leader_idx: list[int]
    follower_idx: list[int]
    vertices: np.ndarray  # (N, 3)
    edges: list[tuple[int, int]]
    neighbours: list[list[int]]  # per index, sorted neighbour indices
    g_star: np.ndarray  # (N, N, 3) desired bearings (0 on the diagonal)
    p_star: np.ndarray  # (N, N, 3, 3) desired projectors P*_ij
    laplacian: np.ndarray  # (3N, 3N)
    l_ff: np.ndarray
    l_fl: np.ndarray
    rank: int
    lambda_ff: np.ndarray  # eigenvalues of L_ff, ascending
    _kfl: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.ids)

    @property
    def lambda_min(self) -> float:
        return float(self.lambda_ff[0])

    @property
    def lambda_max(self) -> float:
        return float(self.lambda_ff[-1])

    def index_of(self, agent_id: int) -> int:
        return self.ids.index(agent_id)

    def desired_positions(self, leader_pos: np.ndarray) -> np.ndarray:
        """(N,3) desired positions p* given leaders' positions: p*_f = −L_ff⁻¹ L_fl p_l."""
        lp = np.asarray(leader_pos, dtype=float)
        out = np.zeros((self.n, 3))
        out[self.leader_idx] = lp
        if self._kfl is None:
            self._kfl = -np.linalg.solve(self.l_ff, self.l_fl)
        out[self.follower_idx] = (self._kfl @ lp.reshape(-1)).reshape(-1, 3)
        return out


def build_formation(
    ids: list[int], leader_ids: list[int], vertices: np.ndarray, graph: str
) -> Formation:
    """Graph, desired bearings, Laplacian and partition; raises :class:`RigidityError`."""
    v = np.asarray(vertices, dtype=float)
    n = len(ids)
    edges = build_edges(v, graph)
    lap = bearing_laplacian(v, edges)
    leader_idx = [ids.index(i) for i in leader_ids]
    follower_idx = [k for k in range(n) if k not in leader_idx]
    nbrs: list[list[int]] = [[] for _ in range(n)]
    for i, j in edges:
        nbrs[i].append(j)
        nbrs[j].append(i)
    g_star = np.zeros((n, n, 3))
    p_star = np.zeros((n, n, 3, 3))
    for i in range(n):
        for j in range(n):
            if i != j:
                g_star[i, j] = bearing(v[i], v[j])
                p_star[i, j] = projector(g_star[i, j])
    fb, lb = _blocks(follower_idx), _blocks(leader_idx)
    l_ff = lap[np.ix_(fb, fb)]
    l_fl = lap[np.ix_(fb, lb)]
    ev_all = np.linalg.eigvalsh(lap)
    rank = int(np.sum(ev_all > 1e-9 * max(1.0, ev_all[-1])))
    lam = np.linalg.eigvalsh(l_ff) if len(fb) else np.zeros(0)
    form = Formation(
        ids=list(ids),
        leader_idx=leader_idx,
        follower_idx=follower_idx,
        vertices=v,
        edges=edges,
        neighbours=[sorted(x) for x in nbrs],
        g_star=g_star,
        p_star=p_star,
        laplacian=lap,
        l_ff=l_ff,
        l_fl=l_fl,
        rank=rank,
        lambda_ff=lam,
    )
    check_rigidity(form, graph)
    return form


def check_rigidity(form: Formation, graph: str = "") -> None:
    """Raise :class:`RigidityError` unless rank L = 3N−4 and λ_min(L_ff) > 0 (Departure 3)."""
    n = form.n
    need = 3 * n - 4
    if form.rank != need:
        raise RigidityError(
            f"formation graph {graph!r} is not bearing rigid: rank of the bearing Laplacian "
            f"is {form.rank}, need 3N-4 = {need} (N = {n}); add edges (e.g. face diagonals)"
        )
    if len(form.lambda_ff) and form.lambda_ff[0] <= 1e-9:
        raise RigidityError(
            f"formation graph {graph!r}: L_ff is singular (lambda_min = {form.lambda_ff[0]:.3g}); "
            "the leaders do not fix the followers' desired positions"
        )


def formation_from_scenario(sc) -> Formation:  # sc: swarm_common.scenario.Scenario
    """Build the :class:`Formation` of a scenario (``[formation].graph``)."""
    return build_formation(sc.ids, sc.leader_ids, sc.vertices(), sc.formation.graph)
