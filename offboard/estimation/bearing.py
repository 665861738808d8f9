"""Bearing geometry, neighbour graph and bearing Laplacian (paper §2.1).

* ``g_ij = (p_j − p_i)/‖p_j − p_i‖`` and ``P_ij = I₃ − g_ij g_ijᵀ`` (§2.1), per graph edge
  (:func:`swarm_common.scenario.graphs.edge_bearings`).
* Desired bearings ``g*_ij`` come from the agents' formation ``vertex`` coordinates.
* Neighbour graph (Departure 3; docs/graphs.md): ``formation.graph`` is one of
  ``cube_face_diagonals``, ``complete``, ``knn`` (``formation.knn_k``), ``range``
  (``formation.sensing_range_m``) or ``edges`` (``formation.edges``), built by
  :mod:`swarm_common.scenario.graphs` (the scenario loader refuses a bad graph with the same check).
* Bearing Laplacian ``L`` (§2.1) with blocks ``−P*_ij`` off-diagonal and ``Σ_k P*_ik`` on
  the diagonal, partitioned into leaders/followers (``L_ff``, ``L_fl``).
* Rigidity check (Departure 3): ``λ_min(L_ff) > 0`` and ``rank L = 3N − 4`` (null space =
  translations + scaling), sparse; otherwise :class:`RigidityError` naming the key.
* Sensed sets: per agent, the graph neighbours and every agent within the sensing range in
  the desired formation; a follower's observer anchors only on the leaders in it, and
  :func:`check_observable` requires the observer matrix ``L_ff + anchors`` to be
  positive definite.

Agents are addressed by their *index* in scenario order; ``ids`` maps index → id.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from swarm_common.scenario import graphs, spectra
from swarm_common.scenario.graphs import GraphSpec


class RigidityError(ValueError):
    """The formation's bearing graph is not bearing rigid or leaders do not fix it."""


def build_edges(
    vertices: np.ndarray, kind: str | GraphSpec, ids: list[int] | None = None
) -> list[tuple[int, int]]:
    """Undirected edges (i < j) of the neighbour graph over the vertex coordinates
    (:func:`swarm_common.scenario.graphs.build_edges`; a plain ``kind`` uses the default keys)."""
    v = np.asarray(vertices, dtype=float)
    spec = kind if isinstance(kind, GraphSpec) else GraphSpec(kind=str(kind))
    return graphs.build_edges(v, spec, ids if ids is not None else list(range(1, len(v) + 1)))


def bearing_laplacian(vertices: np.ndarray, edges: list[tuple[int, int]]) -> np.ndarray:
    """(3N, 3N) bearing Laplacian of the desired bearings (§2.1), dense: the one
    implementation, :func:`swarm_common.scenario.graphs.sparse_laplacian`, made dense."""
    return graphs.sparse_laplacian(np.asarray(vertices, dtype=float), edges).toarray()


def _canonical(m: sp.spmatrix) -> sp.csr_matrix:
    """``m`` as CSR with no stored zeros and sorted indices: the matrix a dense one's
    ``csr_matrix`` would give, so a sparse LU or Lanczos over it orders its work (and
    rounds) as over that one."""
    out = sp.csr_matrix(m, dtype=np.float64, copy=True)
    out.sum_duplicates()
    out.eliminate_zeros()
    out.sort_indices()
    return out


@dataclass
class Formation:
    """Desired bearing formation over N agents (scenario order)."""

    ids: list[int]
    leader_idx: list[int]
    follower_idx: list[int]
    vertices: np.ndarray  # (N, 3)
    edges: list[tuple[int, int]]
    neighbours: list[list[int]]  # per index, sorted neighbour indices
    # per graph edge, both directions: (i, j) -> the desired bearing g*_ij (3,) and its
    # projector P*_ij (3, 3); O(edges) memory, where (N, N, ...) arrays grew with N²
    g_star: dict[tuple[int, int], np.ndarray]
    p_star: dict[tuple[int, int], np.ndarray]
    # the bearing Laplacian (3N, 3N) and its follower/leader blocks L_ff (3F, 3F), L_fl
    # (3F, 3L), sparse (CSR, no stored zeros, sorted indices): .toarray() is the dense
    # matrix, bit for bit, and spectra's solves and spectra take either
    laplacian: sp.csr_matrix
    l_ff: sp.csr_matrix
    l_fl: sp.csr_matrix
    rank: int
    # eigenvalues of L_ff, ascending: above spectra.DENSE_SPECTRUM_MAX rows only the two
    # ends [λ_min, λ_max] (spectra.spectrum)
    lambda_ff: np.ndarray
    # per index, the agents sensed in the desired formation (graph neighbours and every
    # agent within the sensing range; everyone when the range is not given)
    sensed: list[list[int]] = field(default_factory=list)
    _kfl: np.ndarray | None = None
    _obs_eigs: dict[float, np.ndarray] = field(default_factory=dict)
    _digest: str | None = None

    def content_digest(self) -> str:
        """SHA-256 (hex) of what defines the formation's observers and their gain check:
        the agents' roles, the graph (neighbours, the sensed sets), the projectors P*_ij
        and L_ff. Two formations built from equal scenarios have equal digests, so a
        result that depends on these alone can be shared between them (the runs of a
        sweep; :attr:`offboard.agent.follower.FollowerAgent.gains`). Computed once."""
        if self._digest is None:
            h = hashlib.sha256()
            for part in (self.ids, self.leader_idx, self.follower_idx, self.neighbours,
                         self.sensed):
                h.update(repr(part).encode())
            for key in sorted(self.p_star):
                h.update(repr(key).encode())
                h.update(np.ascontiguousarray(self.p_star[key], dtype=np.float64).tobytes())
            h.update(repr(self.l_ff.shape).encode())
            for arr in (self.l_ff.data, self.l_ff.indices, self.l_ff.indptr):
                h.update(np.ascontiguousarray(arr).tobytes())
            self._digest = h.hexdigest()
        return self._digest

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

    def anchor_leaders(self, i: int) -> list[int]:
        """Leaders follower ``i`` senses in the desired formation: the ones its observer's
        leader anchor may use (docs/graphs.md)."""
        lead = set(self.leader_idx)
        return [j for j in self.sensed[i] if j in lead]

    def observer_laplacian(self, leader_anchor: float) -> sp.csr_matrix:
        """(3F, 3F) L_ff + leader_anchor · blockdiag(m_i I₃), m_i = len(anchor_leaders(i)):
        the DESO's network matrix (paper §3 with the anchor of D21), sparse as L_ff."""
        m = np.array([len(self.anchor_leaders(i)) for i in self.follower_idx], dtype=float)
        return _canonical(self.l_ff + sp.diags(leader_anchor * np.repeat(m, 3)))

    def projectors(self, i: int, js: list[int] | tuple[int, ...]) -> np.ndarray:
        """(k, 3, 3) P*_ij of agent ``i`` and its graph neighbours ``js``, in that order."""
        return np.array([self.p_star[i, j] for j in js], dtype=np.float64).reshape(-1, 3, 3)

    def observer_eigs(self, leader_anchor: float) -> np.ndarray:
        """Eigenvalues (ascending) of :meth:`observer_laplacian` (cached per anchor; above
        ``spectra.DENSE_SPECTRUM_MAX`` rows the two ends only, :func:`spectra.spectrum`)."""
        key = float(leader_anchor)
        if key not in self._obs_eigs:
            lap = self.observer_laplacian(key)
            self._obs_eigs[key] = spectra.spectrum(lap)
        return self._obs_eigs[key]

    def desired_positions(self, leader_pos: np.ndarray) -> np.ndarray:
        """(N,3) desired positions p* given leaders' positions: p*_f = −L_ff⁻¹ L_fl p_l."""
        lp = np.asarray(leader_pos, dtype=float)
        out = np.zeros((self.n, 3))
        out[self.leader_idx] = lp
        out[self.follower_idx] = (self._leader_map() @ lp.reshape(-1)).reshape(-1, 3)
        return out

    def desired_positions_series(self, leader_pos: np.ndarray) -> np.ndarray:
        """(K,N,3) :meth:`desired_positions` of K rows of leaders' positions (K,L,3) (m, or
        any leader quantity the map is linear in: velocities) in one product. Equal to the
        row-by-row map up to the rounding of the product's summation order."""
        lp = np.asarray(leader_pos, dtype=float)
        k, n_l, n_f = len(lp), len(self.leader_idx), len(self.follower_idx)
        out = np.zeros((k, self.n, 3))
        out[:, self.leader_idx] = lp
        fol = lp.reshape(k, 3 * n_l) @ self._leader_map().T  # k may be 0 (nothing recorded)
        out[:, self.follower_idx] = fol.reshape(k, n_f, 3)
        return out

    def _leader_map(self) -> np.ndarray:
        """(3F, 3L) −L_ff⁻¹ L_fl (:func:`spectra.leader_map`, computed once; L_ff is
        positive definite: :func:`build_formation` checked it)."""
        if self._kfl is None:
            self._kfl = spectra.leader_map(self.l_ff, self.l_fl)
        return self._kfl


def build_formation(
    ids: list[int], leader_ids: list[int], vertices: np.ndarray, graph: str | GraphSpec
) -> Formation:
    """Graph, desired bearings, Laplacian and partition; raises :class:`RigidityError`
    (one line naming the key) unless the graph passes :func:`graphs.rigidity_problem`."""
    v = np.asarray(vertices, dtype=float)
    n = len(ids)
    spec = graph if isinstance(graph, GraphSpec) else GraphSpec(kind=str(graph))
    try:
        edges = graphs.build_edges(v, spec, ids)
    except ValueError as exc:
        raise RigidityError(str(exc)) from None
    leader_idx = [ids.index(i) for i in leader_ids]
    problem = graphs.rigidity_problem(v, edges, ids, leader_idx)
    if problem is not None:
        raise RigidityError(f"{spec.describe()}: {problem}")
    # the observers read P*_ij of graph neighbours only: O(edges) work and memory
    g_star, p_star = graphs.edge_bearings(v, edges)
    lap = _canonical(graphs.sparse_laplacian(v, edges, p_star))
    lead = set(leader_idx)
    follower_idx = [k for k in range(n) if k not in lead]
    nbrs: list[list[int]] = [[] for _ in range(n)]
    for i, j in edges:
        nbrs[i].append(j)
        nbrs[j].append(i)
    fb, lb = graphs.blocks(follower_idx), graphs.blocks(leader_idx)
    rows_f = lap[fb]
    l_ff = _canonical(rows_f[:, fb])
    return Formation(
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
        l_fl=_canonical(rows_f[:, lb]),
        rank=3 * n - 4,
        lambda_ff=spectra.spectrum(l_ff),
        sensed=graphs.sensed_sets(v, edges, spec.range_vu),
    )


def check_rigidity(form: Formation, graph: str | GraphSpec = "") -> None:
    """Raise :class:`RigidityError` unless λ_min(L_ff) > 0 and rank L = 3N − 4
    (Departure 3; :func:`graphs.rigidity_problem`)."""
    spec = graph if isinstance(graph, GraphSpec) else GraphSpec(kind=str(graph))
    problem = graphs.rigidity_problem(form.vertices, form.edges, form.ids, form.leader_idx)
    if problem is not None:
        raise RigidityError(f"{spec.describe()}: {problem}")


def check_observable(form: Formation, leader_anchor: float) -> None:
    """Raise :class:`RigidityError` unless the DESO's network matrix
    :meth:`Formation.observer_laplacian` is positive definite (paper §3: every channel
    s³ + β1λ s² + β2λ s + β3λ needs λ > 0)."""
    lam = form.observer_eigs(leader_anchor)
    if len(lam) and lam[0] <= spectra.EIG_TOL * max(1.0, float(lam[-1])):
        raise RigidityError(
            f"observer.leader_anchor = {leader_anchor:g}: the observer matrix L_ff + anchors "
            f"is not positive definite (lambda_min = {lam[0]:.3g}); the followers' positions "
            "are not observable from their neighbours and sensed leaders"
        )


def formation_from_scenario(sc) -> Formation:  # sc: swarm_common.scenario.model.Scenario
    """Build the :class:`Formation` of a scenario (``[formation]``: graph, knn_k, edges,
    sensing_range_m; docs/graphs.md)."""
    lead = [sc.index_of(i) for i in sc.leader_ids]
    spec = graphs.graph_spec(sc.formation, sc.initial_positions(), sc.vertices(), lead)
    return build_formation(sc.ids, sc.leader_ids, sc.vertices(), spec)
