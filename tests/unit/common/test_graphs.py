"""Sensing-graph kinds, their validation and rigidity check, and the observers on a sparse
graph (docs/graphs.md)."""

import dataclasses
import itertools

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import CUBE8, ROOT  # noqa: E402

from offboard.estimation.bearing import (
    RigidityError,
    build_formation,
    check_observable,
    formation_from_scenario,
)
from offboard.estimation.deso import DESO, observer_weights
from offboard.estimation.deso_gains import gain_report
from offboard.estimation.peer_table import rows_of
from offboard.estimation.reference import DesiredStateObserver, LeaderTrajectory
from swarm_common.scenario import graphs, spectra
from swarm_common.scenario.model import ScenarioError, load_scenario, with_overrides

GRID27 = ROOT / "scenarios" / "grid27_knn.toml"
GRID = np.array(list(itertools.product(range(3), repeat=3)), dtype=float)  # 27 vertices


@pytest.fixture(scope="module")
def sc27():
    return load_scenario(GRID27)


def _degrees(edges, n):
    return np.bincount(np.array(edges).ravel(), minlength=n)


def _adjacency(edges, n):
    a = np.zeros((n, n), dtype=bool)
    for i, j in edges:
        a[i, j] = True
    return a


def test_knn_degrees_ties_and_symmetry():
    e = graphs.knn_edges(GRID, 6)
    assert all(i < j for i, j in e) and len(set(e)) == len(e)
    deg = _degrees(e, 27)
    # every vertex keeps at least its k nearest; a corner exactly its 3 axis and 3 diagonal
    # neighbours; the centre chooses its 6 axis neighbours and is chosen by the 12 edge
    # middles (whose 6th-nearest distance, √2, it ties): 18 after symmetrising
    assert deg.min() >= 6 and deg[0] == 6 and deg[13] == 18
    assert deg[4] == 13  # face centre (0,1,1): 5 at distance 1, 8 tied at √2
    a = _adjacency(e, 27)
    d = np.linalg.norm(GRID[:, None] - GRID[None], axis=2)
    assert d[a].max() == pytest.approx(np.sqrt(2.0))  # longest edge: a face diagonal
    # order of the vertices does not change the graph (ties are included, not broken)
    perm = np.random.default_rng(1).permutation(27)
    ep = graphs.knn_edges(GRID[perm], 6)
    back = {tuple(sorted((int(perm[i]), int(perm[j])))) for i, j in ep}
    assert back == set(e)
    assert graphs.knn_edges(GRID[:5], 10) == [(i, j) for i in range(5) for j in range(i + 1, 5)]
    with pytest.raises(ValueError, match="knn_k = 0"):
        graphs.knn_edges(GRID, 0)


def test_range_edges():
    e = graphs.range_edges(GRID, 1.0)
    assert len(e) == 54  # the 3x3x3 grid's axis edges
    e2 = graphs.range_edges(GRID, np.sqrt(2.0))
    assert len(e2) == 54 + 72 and set(e) < set(e2)
    assert graphs.range_edges(GRID, 0.5) == []


def test_edge_list_validation():
    ids = [10, 11, 12, 13]
    assert graphs.id_edges(ids, [[13, 10], [11, 12]]) == [(0, 3), (1, 2)]
    with pytest.raises(ValueError, match=r"^formation.edges\[1\] = \[11, 99\]: id 99 is not"):
        graphs.id_edges(ids, [[10, 11], [11, 99]])
    with pytest.raises(ValueError, match=r"^formation.edges\[0\] = \[12, 12\]: self-loop$"):
        graphs.id_edges(ids, [[12, 12]])
    with pytest.raises(ValueError, match=r"formation.edges\[1\] = \[11, 10\]: pair listed twice"):
        graphs.id_edges(ids, [[10, 11], [11, 10]])


def test_sparse_and_dense_checks_agree(monkeypatch):
    e = graphs.knn_edges(GRID, 6)
    lap = graphs.sparse_laplacian(GRID, e)
    q = graphs.trivial_null_space(GRID)
    assert np.allclose(lap @ q, 0.0) and np.allclose(q.T @ q, np.eye(4))
    sparse = spectra.smallest_eig(lap, q)  # 81 > DENSE_MAX: Lanczos
    monkeypatch.setattr(spectra, "DENSE_MAX", 10**6)
    dense = spectra.smallest_eig(lap, q)
    assert sparse == pytest.approx(dense, rel=1e-8) and dense > 0.1
    # knn_k = 3 keeps only the grid's axis edges: the grid can shear, rank is lost
    loose = graphs.sparse_laplacian(GRID, graphs.knn_edges(GRID, 3))
    monkeypatch.setattr(spectra, "DENSE_MAX", 60)
    assert spectra.smallest_eig(loose, q) < 1e-8


def test_scenario_defaults_keep_old_files_valid():
    sc = load_scenario(CUBE8)
    assert sc.formation.knn_k == 6 and sc.formation.edges == ()
    assert "knn_k" in sc.to_toml_dict()["formation"]


@pytest.mark.parametrize(
    "over,pattern",
    [
        ({"knn_k": 3}, r'formation.graph = "knn" \(knn_k = 3\): the bearing Laplacian\'s '
                       r"follower block is singular: the leaders do not fix followers 6, 7, "
                       r".* \(19 in all\)$"),
        ({"knn_k": 27}, r"formation.knn_k = 27: must be below the number of agents \(27\)"),
        ({"knn_k": 0}, r"formation.knn_k = 0: must be an integer in \[1, 254\]"),
        ({"edges": [[1, 5]]}, r'formation.edges: only read with formation.graph = "edges"'),
        ({"graph": "edges"}, r'formation.edges = \[\]: formation.graph = "edges" needs'),
        ({"graph": "edges", "edges": [[1, 40]]}, r"formation.edges\[0\] = \[1, 40\]: id 40"),
        ({"graph": "edges", "edges": [[2, 2]]}, r"formation.edges\[0\] = \[2, 2\]: self-loop"),
        ({"graph": "edges", "edges": [[1, 2.5]]}, r"formation.edges = .*: must be a list of"),
        ({"graph": "edges", "edges": [[5, 6], [6, 7], [5, 7]]},
         r'formation.graph = "edges" \(formation.edges, 3 pairs\): .*do not fix followers'),
        ({"graph": "range", "sensing_range_m": 3.5},
         r'formation.graph = "range" \(sensing_range_m = 3.5\): .*not bearing rigid|do not fix'),
        ({"sensing_range_m": 4.0},
         r"formation.sensing_range_m = 4: formation.graph = \"knn\" \(knn_k = 6\) links ids "
         r"\d+ and \d+, 4.24 m apart in the desired formation, never sensed there"),
    ],
)
def test_bad_graph_refused_at_load_naming_the_key(sc27, over, pattern):
    with pytest.raises(ScenarioError, match=pattern) as ei:
        with_overrides(sc27, formation=over)
    assert "\n" not in str(ei.value)


def test_range_graph_loads_and_is_the_range_rule(sc27):
    # the shorter range takes a smaller transient speed limit (docs/safety.md §5i)
    sc = with_overrides(sc27, formation={"graph": "range", "sensing_range_m": 4.3},
                        controller={"max_transient_speed_mps": 0.7})
    f = formation_from_scenario(sc)
    assert len(f.edges) == 54 + 72  # 4.3 m at 3 m per unit: axis edges and face diagonals


def test_edges_graph_builds_the_listed_pairs(sc27):
    f0 = formation_from_scenario(sc27)
    pairs = [[sc27.ids[i], sc27.ids[j]] for i, j in f0.edges]
    sc = with_overrides(sc27, formation={"graph": "edges", "edges": pairs})
    assert formation_from_scenario(sc).edges == f0.edges


@pytest.mark.full
def test_anchor_uses_only_sensed_leaders(sc27):
    f = formation_from_scenario(sc27)
    a = sc27.observer.leader_anchor
    assert a > 0
    r = sc27.formation.sensing_range_m / 3.0  # 3 m per vertex unit
    n_none = 0
    for i in f.follower_idx:
        w = observer_weights(f, i, a)
        sensed = [j for j in f.leader_idx
                  if np.linalg.norm(f.vertices[i] - f.vertices[j]) <= r or j in f.neighbours[i]]
        assert sorted(set(w) & set(f.leader_idx)) == sorted(sensed) == f.anchor_leaders(i)
        assert set(w) == set(f.neighbours[i]) | set(sensed)
        for j in sensed:
            assert np.allclose(w[j], f.p_star.get((i, j), np.zeros((3, 3))) + a * np.eye(3))
        n_none += not sensed
    assert n_none == 5  # these rely on the bearing innovations only
    # the gain check's channels are the eigenvalues of L_ff + anchors of the sensed leaders
    m = np.array([len(f.anchor_leaders(i)) for i in f.follower_idx])
    want = np.linalg.eigvalsh(f.l_ff.toarray() + a * np.diag(np.repeat(m, 3)))
    rep = gain_report(f, tuple(sc27.observer.beta), 0.02, 1, a)
    assert np.allclose(rep.lambda_ff, want) and not np.allclose(want, f.lambda_ff + 4 * a)


def test_deso_ignores_data_of_unsensed_leaders(sc27):
    f = formation_from_scenario(sc27)
    i = next(k for k in f.follower_idx if not f.anchor_leaders(k))
    far = [j for j in f.leader_idx if j not in f.neighbours[i]]
    assert far
    p = f.desired_positions(sc27.initial_positions()[f.leader_idx])
    obs = sc27.observer

    def run(extra: bool) -> np.ndarray:
        d = DESO(f, i, tuple(obs.beta), 0.0, 0.0, 4, 0.02, 0.8, p[i] + 0.5, np.zeros(3),
                 obs.leader_anchor, tuple(obs.velocity_gain))
        nbr_p = {j: p[j] for j in f.neighbours[i]}
        nbr_v = {j: np.zeros(3) for j in f.neighbours[i]}
        if extra:  # a far leader's (wrong) data arriving anyway must not be used
            nbr_p.update({j: p[j] + 7.0 for j in far})
            nbr_v.update({j: np.ones(3) for j in far})
        valid = np.ones(sc27.n, dtype=bool)
        valid[i] = False
        for _ in range(50):
            d.update(p - p[i], np.zeros((sc27.n, 3)), valid, *rows_of(sc27.n, nbr_p, nbr_v),
                     np.zeros((4, 3)))
        return d.z1

    z_plain, z_extra = run(False), run(True)
    assert np.array_equal(z_plain, z_extra)
    assert np.linalg.norm(z_plain - p[i]) < 0.05  # converges from bearings alone


def test_observability_refused_when_observer_matrix_singular(sc27):
    f = formation_from_scenario(sc27)
    check_observable(f, 1.0)
    bad = dataclasses.replace(f, l_ff=sp.csr_matrix(f.l_ff.shape), _obs_eigs={})
    with pytest.raises(RigidityError, match=r"^observer.leader_anchor = 0: the observer matrix"):
        check_observable(bad, 0.0)


def test_desired_state_observer_neighbours_only_on_sparse_graph(sc27):
    f = formation_from_scenario(sc27)
    dt, lt = 0.02, sc27.leader_trajectory
    omega = 2 * np.pi * lt.frequency_hz
    trs = {i: LeaderTrajectory(sc27.agents[i].position, np.array(lt.amplitude_m),
                               lt.frequency_hz) for i in f.leader_idx}
    obs = {i: DesiredStateObserver(f, i, omega, sc27.observer.reference_gain, dt,
                                   np.concatenate([sc27.agents[i].position, np.zeros(9)]))
           for i in f.follower_idx}
    steps = int(12 / dt)
    for k in range(steps):
        pub = {i: o.xi.copy() for i, o in obs.items()}
        pub.update({i: trs[i].state(k * dt) for i in f.leader_idx})
        for i, o in obs.items():  # only graph neighbours' ξ̂ is handed over
            o.update(*rows_of(sc27.n, xi={j: pub[j] for j in f.neighbours[i]}))
    lead = np.array([trs[i].state(steps * dt) for i in f.leader_idx])
    want = f.desired_positions(lead[:, 0:3])
    err = max(np.linalg.norm(o.p - want[i]) for i, o in obs.items())
    assert err < 1e-3
    i, o = next(iter(obs.items()))
    assert o.rate == pytest.approx(sc27.observer.reference_gain * f.lambda_min)
    # data of a non-neighbour (even garbage) is not used
    xi0 = o.xi.copy()
    o.update(*rows_of(sc27.n, xi={j: pub[j] for j in f.neighbours[i]}))
    a = o.xi.copy()
    o.xi = xi0
    o.update(*rows_of(sc27.n, xi=pub | {j: np.full(12, 1e3) for j in range(sc27.n)
                                         if j not in f.neighbours[i]}))
    assert np.array_equal(a, o.xi)


def test_build_formation_plain_kinds_still_work():
    sc = load_scenario(CUBE8)
    f = build_formation(sc.ids, sc.leader_ids, sc.vertices(), "knn")
    assert f.rank == 3 * sc.n - 4 and len(f.edges) >= 8 * 6 // 2
    assert all(len(f.anchor_leaders(i)) == 2 for i in f.follower_idx)  # no range given


def test_the_dense_bearing_laplacian_is_the_sparse_one_and_annihilates_the_formation():
    """One implementation: the dense form is the sparse one made dense, bit for bit; and
    numerically what a bearing Laplacian must be (§2.1): symmetric, positive semidefinite,
    zero on translations and on the desired formation itself (L p* = 0)."""
    from offboard.estimation.bearing import bearing_laplacian

    e = graphs.knn_edges(GRID, 6)
    dense = bearing_laplacian(GRID, e)
    assert np.array_equal(dense, graphs.sparse_laplacian(GRID, e).toarray())
    assert np.allclose(dense, dense.T, atol=0.0)
    assert np.linalg.eigvalsh(dense).min() > -1e-12
    for k in range(3):
        shift = np.zeros((len(GRID), 3))
        shift[:, k] = 1.0
        assert np.abs(dense @ shift.ravel()).max() < 1e-12
    assert np.abs(dense @ (3.0 * GRID).ravel()).max() < 1e-12
    moved = GRID.copy()
    moved[0] += 0.3  # one vertex off its bearings: no longer in the null space
    assert np.abs(dense @ moved.ravel()).max() > 1e-3


def test_swarm_and_graph_size_limits_refused_in_one_line():
    """A scenario past MAX_AGENTS agents, or whose graph has more than MAX_EDGES edges, is
    refused at load in one line, before the checks that work agent by agent and edge by
    edge (a complete graph of 2,000 agents took minutes and gigabytes before)."""
    import argparse
    import copy

    from gcs.scenario_gen import add_scenario_parser, build
    from swarm_common.scenario.model import parse_scenario
    from swarm_common.scenario.schema import MAX_AGENTS, MAX_EDGES

    ap = argparse.ArgumentParser()
    add_scenario_parser(ap.add_subparsers())
    doc, _, sc = build(ap.parse_args(["scenario", "grid", "--agents", "400", "--leaders", "8",
                                      "--scramble", "1"]))
    assert sc.n == 400  # the sparse graph loads
    dense = copy.deepcopy(doc)
    dense["formation"]["graph"] = "complete"
    with pytest.raises(ScenarioError, match=rf'formation.graph = "complete": 400 agents have '
                       rf"79800 pairs, at most {MAX_EDGES} edges: use knn or range$") as ei:
        parse_scenario(dense, "dense")
    assert "\n" not in str(ei.value)
    many = copy.deepcopy(doc)
    extra = MAX_AGENTS + 1 - len(many["agent"])
    many["agent"] += [dict(a, id=1000 + i) for i, a in enumerate(many["agent"][-1:] * extra)]
    with pytest.raises(ScenarioError, match=rf"\[\[agent\]\] lists {MAX_AGENTS + 1} agents: "
                       rf"at most {MAX_AGENTS}$"):
        parse_scenario(many, "many")
    pts = np.random.default_rng(3).uniform(0.0, 30.0, size=(600, 3))
    with pytest.raises(ValueError, match=rf"\(knn_k = 250\): \d+ edges, at most {MAX_EDGES}"):
        graphs.build_edges(pts, graphs.GraphSpec(kind="knn", knn_k=250), range(1, 601))
    assert len(graphs.build_edges(pts, graphs.GraphSpec(kind="knn", knn_k=6), range(1, 601))) \
        < MAX_EDGES


def test_smallest_eig_and_spectrum_fall_back_to_dense_when_lanczos_stalls(monkeypatch):
    """Lanczos capped at ARPACK_MAXITER restarts; where it does not converge (a ring of
    2,048 agents: hundreds of eigenvalues within 1 % of 1.7e-7, 370 s and a traceback
    before), the dense eigenvalues answer, with and without a deflation term."""
    from scipy.sparse.linalg import ArpackNoConvergence

    rng = np.random.default_rng(7)
    a = rng.normal(size=(200, 200))
    m = spectra.sp.csr_matrix(a @ a.T / 200.0)
    q = np.linalg.qr(rng.normal(size=(200, 2)))[0]
    want = np.linalg.eigvalsh(m.toarray())
    want_q = np.linalg.eigvalsh(m.toarray() + q @ q.T)[0]
    assert spectra.smallest_eig(m) == pytest.approx(want[0], rel=1e-8)  # Lanczos converges
    seen: list[int] = []

    def stalled(*args, **kwargs):
        seen.append(int(kwargs["maxiter"]))
        raise ArpackNoConvergence("stalled", np.array([]), np.array([]))

    monkeypatch.setattr(spectra, "eigsh", stalled)
    assert spectra.smallest_eig(m) == pytest.approx(want[0], rel=1e-12)
    assert spectra.smallest_eig(m, q) == pytest.approx(want_q, rel=1e-12)
    lo, hi = spectra.spectrum(m, dense_max=10)
    assert lo == pytest.approx(want[0], rel=1e-12) and hi == pytest.approx(want[-1], rel=1e-12)
    assert seen and set(seen) == {spectra.ARPACK_MAXITER}


def test_edge_bearings_are_the_laplacians_and_both_directions_agree():
    """The per-edge bearings the formation keeps are the ones its Laplacian is built
    from: g*_ji = −g*_ij and P*_ji = P*_ij exactly, each projector annihilates its
    bearing, and the Laplacian of given projectors is the one computed from the
    vertices, while different projectors give a different one."""
    e = graphs.knn_edges(GRID, 6)
    g_star, p_star = graphs.edge_bearings(GRID, e)
    assert set(g_star) == set(p_star) == {(i, j) for i, j in e} | {(j, i) for i, j in e}
    for i, j in e:
        assert np.array_equal(g_star[j, i], -g_star[i, j])
        assert np.array_equal(p_star[j, i], p_star[i, j])
        d = GRID[j] - GRID[i]
        assert np.allclose(g_star[i, j], d / np.sqrt(d @ d), atol=1e-15)
        assert np.abs(p_star[i, j] @ g_star[i, j]).max() < 1e-15
    lap = graphs.sparse_laplacian(GRID, e)
    assert (graphs.sparse_laplacian(GRID, e, p_star) != lap).nnz == 0
    bent = {k: 2.0 * p for k, p in p_star.items()}
    assert np.allclose(graphs.sparse_laplacian(GRID, e, bent).toarray(), 2.0 * lap.toarray())
