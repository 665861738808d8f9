"""The DESO gain check's network loop (offboard.estimation.deso_gains): the sparse one-period error
transition against the real observers, and the spectral radius, dense and sparse."""

import numpy as np
import pytest
from conftest import CUBE8, ROOT  # noqa: E402
from scipy import sparse
from scipy.sparse.linalg import ArpackNoConvergence

import offboard.estimation.deso_gains as gains
from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.deso import DESO
from offboard.estimation.peer_table import rows_of
from swarm_common.scenario.model import load_scenario

GRID27 = ROOT / "scenarios" / "grid27_knn.toml"
GRID64 = ROOT / "scenarios" / "grid64.toml"


@pytest.mark.parametrize("path", [CUBE8, GRID27], ids=["cube8", "grid27_knn"])
def test_transition_is_one_period_of_the_real_observers(path):
    """Static truth, exact measurements, no disturbance, ζ̂ = 0 (μ = 0): the followers'
    estimate errors E = [z̃1, z̃2, z̃3] after one period of the real DESO objects, each
    using the others' current estimates, equal (T0 + T1) E."""
    sc = load_scenario(path)
    f = formation_from_scenario(sc)
    ob = sc.observer
    beta, sub, dt = tuple(ob.beta), ob.substeps, sc.control_dt
    anchor, kappa = ob.leader_anchor, tuple(ob.velocity_gain)
    p = f.desired_positions(sc.initial_positions()[f.leader_idx])
    fol = list(f.follower_idx)
    e0 = np.random.default_rng(3).normal(scale=0.2, size=(len(fol), 9))
    obs = {}
    for k, i in enumerate(fol):
        obs[i] = DESO(f, i, beta, 0.0, 0.15, sub, dt, 0.8, p[i] + e0[k, 0:3], e0[k, 3:6],
                      anchor, kappa)
        obs[i].z3 = e0[k, 6:9].copy()
    pub = {i: (obs[i].z1.copy(), obs[i].z2.copy()) for i in fol}
    for j in f.leader_idx:
        pub[j] = (p[j], np.zeros(3))
    zero_v, valid = np.zeros_like(p), np.ones(sc.n, bool)
    u_sub = np.zeros((sub, 3))
    for i in fol:
        nb = {j: pub[j][0] for j in obs[i].nbrs}
        nv = {j: pub[j][1] for j in obs[i].nbrs}
        obs[i].update(p - p[i], zero_v, valid, *rows_of(sc.n, nb, nv), u_sub)
    e1 = np.concatenate([np.concatenate([obs[i].z1 - p[i], obs[i].z2, obs[i].z3]) for i in fol])
    t0, t1 = gains._network_transition(f, beta, dt, sub, euler=False, leader_anchor=anchor,
                                       kappa=kappa)
    assert sparse.issparse(t0) and sparse.issparse(t1)
    want = (t0 + t1) @ e0.ravel()
    assert np.max(np.abs(e1 - want)) < 1e-9 * max(1.0, np.max(np.abs(e1)))
    assert np.max(np.abs(e1 - e0.ravel())) > 1e-3  # the period moved the errors


@pytest.mark.full
@pytest.mark.slow  # about 20 s idle: started first, not left to the tier's end
def test_spectral_radius_sparse_equals_dense_on_grid64():
    """Above DENSE_MAX the radius comes from ARPACK: on grid64's four loops (orders 540 and
    1080) it equals every eigenvalue's maximum modulus to 1e-10."""
    sc = load_scenario(GRID64)
    f = formation_from_scenario(sc)
    ob = sc.observer
    beta, dt = tuple(ob.beta), sc.control_dt
    for sub, euler in ((ob.substeps, False), (ob.substeps, True), (1, True)):
        t0, t1 = gains._network_transition(f, beta, dt, sub, euler, ob.leader_anchor,
                                           tuple(ob.velocity_gain))
        n = t0.shape[0]
        for loop in ((t0 + t1).tocsr(),
                     sparse.bmat([[t0, t1], [sparse.identity(n), None]], format="csr")):
            assert loop.shape[0] > gains.DENSE_MAX
            dense = float(np.max(np.abs(np.linalg.eigvals(loop.toarray()))))
            assert gains.spectral_radius(loop) == pytest.approx(dense, rel=1e-10)


@pytest.mark.full
def test_spectral_radius_clustered_complex_top():
    """A top made of close complex pairs (a rotation block per pair, radii 0.99 apart by
    1e-4) and a random sparse rest: the largest modulus, as the dense answer."""
    rng = np.random.default_rng(5)
    n = 400
    blocks = []
    for k, r in enumerate((0.9900, 0.9901, 0.9899)):
        th = 0.3 + 0.1 * k
        blocks.append(r * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]))
    rest = sparse.random(n - 6, n - 6, density=0.01, random_state=rng) * 0.5
    m = sparse.block_diag([*blocks, rest], format="csr")
    dense = float(np.max(np.abs(np.linalg.eigvals(m.toarray()))))
    assert dense == pytest.approx(0.9901, abs=1e-12)
    assert gains.spectral_radius(m) == pytest.approx(dense, rel=1e-10)


def test_spectral_radius_falls_back_to_dense(monkeypatch):
    """ARPACK not converging: the dense answer, not an error."""
    def no_convergence(*args, **kwargs):
        raise ArpackNoConvergence("no", np.array([]), np.array([]))

    monkeypatch.setattr(gains, "eigs", no_convergence)
    m = sparse.diags(np.linspace(-0.5, 0.97, 300), format="csr")
    assert gains.spectral_radius(m) == pytest.approx(0.97, abs=1e-12)


def test_spectral_radius_bounds_arpack_restarts(monkeypatch):
    """ARPACK gets at most ARPACK_MAXITER restarts, whatever the order (a generated ring's
    loops ran scipy's 20 n before the fallback, minutes per scenario), and a matrix it
    answers within them keeps ARPACK's answer."""
    seen: list[int] = []
    real = gains.eigs

    def recorded(*args, **kwargs):
        seen.append(int(kwargs["maxiter"]))
        return real(*args, **kwargs)

    monkeypatch.setattr(gains, "eigs", recorded)
    m = sparse.diags(np.linspace(-0.5, 0.97, 300), format="csr") \
        + sparse.random(300, 300, density=0.005, random_state=np.random.default_rng(2)) * 1e-3
    dense = float(np.max(np.abs(np.linalg.eigvals(m.toarray()))))
    assert gains.spectral_radius(m) == pytest.approx(dense, rel=1e-10)
    assert seen == [min(20 * 300, gains.ARPACK_MAXITER)] and gains.ARPACK_MAXITER < 20 * 300


def test_a_loop_too_large_to_solve_dense_is_not_computed(monkeypatch, caplog):
    """ARPACK not converging above DENSE_FALLBACK_MAX: NaN and a warning, not a dense solve
    of hours (a 2,000-agent grid with 4 leaders has loops of order 17,964 and 35,928)."""
    def no_convergence(*args, **kwargs):
        raise ArpackNoConvergence("no", np.array([]), np.array([]))

    def dense(*args, **kwargs):
        raise AssertionError("a dense solve past DENSE_FALLBACK_MAX")

    monkeypatch.setattr(gains, "eigs", no_convergence)
    monkeypatch.setattr(gains, "DENSE_FALLBACK_MAX", 299)
    monkeypatch.setattr(gains.np.linalg, "eigvals", dense)
    m = sparse.diags(np.linspace(-0.5, 0.97, 300), format="csr")
    with caplog.at_level("WARNING", logger=gains.__name__):
        assert np.isnan(gains.spectral_radius(m))
    assert "order 300" in caplog.text and "not computed" in caplog.text


def test_a_loop_not_computed_fails_the_check_in_words(monkeypatch):
    """A report whose sampled loop could not be computed is not ok, and its problem line
    says that it could not be checked (not "spectral radius nan >= 1")."""
    sc = load_scenario(GRID27)
    form = formation_from_scenario(sc)
    obs = sc.observer
    monkeypatch.setattr(gains, "spectral_radius", lambda m: float("nan"))
    rep = gains.gain_report(form, tuple(obs.beta), sc.control_dt, obs.substeps,
                            obs.leader_anchor, tuple(obs.velocity_gain))
    assert rep.max_real_pole < 0.0 and not rep.ok
    why = rep.problem()
    assert why is not None and "could not be checked" in why and "nan" not in why
    assert any("not computed" in line for line in rep.lines())


def test_an_unstable_channel_skips_the_sampled_loops(monkeypatch):
    """A channel not Hurwitz fails the report on its own: the loops' radii (minutes on a
    large graph) are not computed, and the problem names the channel."""
    form = formation_from_scenario(load_scenario(GRID27))

    def never(m):
        raise AssertionError("a sampled loop computed for an unstable channel")

    monkeypatch.setattr(gains, "spectral_radius", never)
    rep = gains.gain_report(form, (1.0, 1.0, 1000.0), 0.02, 4)  # b1 b2 λ < b3: not Hurwitz
    assert rep.max_real_pole >= 0.0 and not rep.ok and np.isnan(rep.rho_post_update)
    assert "slowest channel pole" in (rep.problem() or "")
