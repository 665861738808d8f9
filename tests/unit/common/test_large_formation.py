"""Start-up of a large formation: the sparse spectrum and solve above
``spectra.DENSE_SPECTRUM_MAX``, the k-d tree pair search of the loader's checks, the gain
report's channels when only the ends of the spectrum are known, and the formation's
matrices held on the graph's edges (docs/performance.md)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import ROOT  # noqa: E402

from offboard.estimation.bearing import (
    bearing_laplacian,
    build_formation,
    formation_from_scenario,
)
from offboard.estimation.deso_gains import CHANNEL_SAMPLES, channels, gain_report
from swarm_common.scenario import feasibility, graphs, spectra
from swarm_common.scenario.checks import check_separation
from swarm_common.scenario.model import load_scenario
from swarm_common.scenario.spec import AgentSpec, Role

GRID27 = ROOT / "scenarios" / "grid27_knn.toml"
# a 5 × 5 × 5 grid, knn 6, its four corners (0, 4, 20, 24 of the bottom layer) as leaders
GRID125 = np.array(list(itertools.product(range(5), repeat=3)), dtype=float)
LEADERS = [0, 4, 20, 24]


def _blocks_125() -> tuple[object, object]:
    lap = graphs.sparse_laplacian(GRID125, graphs.knn_edges(GRID125, 6))
    fol = [k for k in range(len(GRID125)) if k not in LEADERS]
    fb, lb = graphs.blocks(fol), graphs.blocks(LEADERS)
    return lap[fb][:, fb], lap[fb][:, lb]


def test_sparse_spectrum_ends_are_the_dense_ones():
    l_ff, _ = _blocks_125()
    dense = np.linalg.eigvalsh(l_ff.toarray())
    full = spectra.spectrum(l_ff)  # 363 rows: below the threshold, every eigenvalue
    assert len(full) == l_ff.shape[0] and np.array_equal(full, dense)
    ends = spectra.spectrum(l_ff, dense_max=0)  # forced onto the sparse path
    assert len(ends) == 2
    assert ends[0] == pytest.approx(dense[0], rel=1e-8) and dense[0] > 1e-3
    assert ends[1] == pytest.approx(dense[-1], rel=1e-8)


def test_sparse_follower_solve_matches_the_dense_solve():
    l_ff, l_fl = _blocks_125()
    dense = spectra.follower_solve(l_ff, l_fl)
    assert np.array_equal(dense, np.linalg.solve(l_ff.toarray(), l_fl.toarray()))
    sparse = spectra.follower_solve(l_ff, l_fl, dense_max=0)
    assert np.max(np.abs(sparse - dense)) <= 1e-9 * max(1.0, float(np.max(np.abs(dense))))
    # and it is the map: the followers' desired positions of the grid itself (scale 1)
    p = (-sparse @ GRID125[LEADERS].reshape(-1)).reshape(-1, 3)
    fol = [k for k in range(len(GRID125)) if k not in LEADERS]
    assert np.allclose(p, GRID125[fol], atol=1e-9)


def test_close_pairs_keeps_every_close_pair_and_little_else():
    rng = np.random.default_rng(7)
    x = rng.uniform(0.0, 10.0, size=(400, 3))
    r = 0.9
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    got = graphs.close_pairs(x, r)
    within = {(i, j) for i in range(400) for j in range(i + 1, 400) if d[i, j] < r}
    assert within and within <= got
    assert all(d[i, j] <= r * (1.0 + 1e-6) for i, j in got)
    x[3, 1] = np.nan  # not finite: every pair, the caller's formula decides
    assert len(graphs.close_pairs(x, r)) == 400 * 399 // 2
    assert graphs.close_pairs(x[:1], r) == set()
    assert graphs.close_pairs(np.zeros((5, 3)), 0.0) == set()


def _agent(k: int, p: tuple[float, float, float], v: tuple[float, float, float]) -> AgentSpec:
    role = Role.LEADER if k < 2 else Role.FOLLOWER
    return AgentSpec(k + 1, role, np.array(p, float), np.zeros(3), np.array(v, float))


def test_separation_names_the_first_close_pair_in_index_order():
    # pairs (1, 4) start too close and (2, 3) have vertices too close: (1, 4) comes first
    agents = [_agent(0, (0, 0, 0), (0, 0, 0)), _agent(1, (10, 0, 0), (10, 0, 0)),
              _agent(2, (20, 0, 0), (20, 0, 0)), _agent(3, (30, 0, 0), (20.1, 0, 0)),
              _agent(4, (10.2, 0, 0), (40, 0, 0))]
    with pytest.raises(ValueError, match=r"agent\[4\]\.position .* from agent id 2,"):
        check_separation(agents, [1, 2], 0.5, ValueError)
    agents[4] = _agent(4, (50, 0, 0), (40, 0, 0))
    with pytest.raises(ValueError, match=r"agent\[3\]\.vertex .* from agent id 3's vertex"):
        check_separation(agents, [1, 2], 0.5, ValueError)
    agents[3] = _agent(3, (30, 0, 0), (30, 0, 0))
    check_separation(agents, [1, 2], 0.5, ValueError)  # nothing close: no error


def test_a_formation_above_the_threshold_takes_the_sparse_path(monkeypatch):
    """grid27 with the threshold lowered below its 3F = 69 rows: the ends of the spectra,
    the leader map and the loader's formation map agree with the dense ones, and the gain
    report samples its channels between the ends."""
    sc = load_scenario(GRID27)
    dense_form = formation_from_scenario(sc)
    dense_map = feasibility.formation_map(sc)
    dense_report = gain_report(dense_form, tuple(sc.observer.beta), sc.control_dt,
                               sc.observer.substeps, sc.observer.leader_anchor)
    monkeypatch.setattr(spectra, "DENSE_SPECTRUM_MAX", 30)
    sc2 = load_scenario(GRID27)
    form = formation_from_scenario(sc2)
    assert len(form.lambda_ff) == 2 and len(dense_form.lambda_ff) == 3 * len(form.follower_idx)
    assert form.lambda_min == pytest.approx(dense_form.lambda_min, rel=1e-8)
    assert form.lambda_max == pytest.approx(dense_form.lambda_max, rel=1e-8)
    assert np.allclose(form.desired_positions_series(np.ones((1, len(form.leader_idx), 3))),
                       dense_form.desired_positions_series(
                           np.ones((1, len(form.leader_idx), 3))), atol=1e-9)
    sparse_map = feasibility.formation_map(sc2)
    assert sparse_map is not None and dense_map is not None
    assert np.max(np.abs(sparse_map - dense_map)) <= 1e-9
    report = gain_report(form, tuple(sc2.observer.beta), sc2.control_dt,
                         sc2.observer.substeps, sc2.observer.leader_anchor)
    assert len(report.lambda_ff) == CHANNEL_SAMPLES
    assert report.ok == dense_report.ok
    b1, b2, b3 = report.beta
    lam0 = dense_report.lambda_ff[0]
    assert report.margin.min() == pytest.approx(b1 * b2 * lam0 - b3, rel=1e-8)
    # the samples cover the eigenvalues' range, so the slowest pole is at least as slow
    assert report.max_real_pole >= dense_report.max_real_pole - 1e-9


def test_channels_keep_a_full_spectrum_and_sample_its_ends():
    full = np.array([0.5, 1.0, 2.0, 4.0])
    assert channels(full, 4) is full
    got = channels(np.array([0.5, 4.0]), 300)
    assert len(got) == CHANNEL_SAMPLES and got[0] == 0.5 and got[-1] == pytest.approx(4.0)
    assert np.all(np.diff(got) > 0.0)


def test_the_formation_is_sparse_and_densifies_to_the_dense_matrices():
    edges = graphs.knn_edges(GRID125, 6)
    ids = list(range(1, len(GRID125) + 1))
    form = build_formation(ids, [ids[k] for k in LEADERS], GRID125,
                           graphs.GraphSpec(kind="knn", knn_k=6))
    dense = bearing_laplacian(GRID125, form.edges)
    fb, lb = graphs.blocks(form.follower_idx), graphs.blocks(LEADERS)
    for got, want in ((form.laplacian, dense), (form.l_ff, dense[np.ix_(fb, fb)]),
                      (form.l_fl, dense[np.ix_(fb, lb)])):
        assert np.array_equal(got.toarray(), want)  # the former dense matrix, bit for bit
        assert got.has_sorted_indices and np.all(got.data != 0.0)  # as csr_matrix(dense)
    # one bearing and projector per edge and direction, and nothing else
    assert set(form.p_star) == set(form.g_star) == {k for i, j in form.edges
                                                    for k in ((i, j), (j, i))}
    assert sorted(form.edges) == sorted(edges)
    i, j = form.edges[0]
    g = form.g_star[i, j]
    assert np.allclose(form.p_star[i, j] @ g, 0.0) and np.isclose(np.trace(form.p_star[i, j]), 2)
    # memory on the edges (about 400 bytes each): dense (N, N, 3, 3) projectors alone took
    # 9 × 8 × N² bytes
    held = sum(a.nbytes for d in (form.p_star, form.g_star) for a in d.values())
    held += sum(m.data.nbytes + m.indices.nbytes + m.indptr.nbytes
                for m in (form.laplacian, form.l_ff, form.l_fl))
    assert held <= 600 * len(form.edges) < 9 * 8 * len(GRID125) ** 2
