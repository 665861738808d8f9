"""DESO (paper §3): regressor equals the simulator's, gain check, convergence."""


import numpy as np
import pytest
from conftest import CUBE8  # noqa: E402

from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.deso import (
    DESO,
    F_HAT_MAX,
    GATE_E1,
    GATE_HOLD_S,
    ZETA_HI,
    ZETA_LO,
    adapt_step,
    model_accel,
    regressor,
    regressor_t_times,
)
from offboard.estimation.deso_gains import gain_report
from offboard.estimation.peer_table import rows_of
from swarm_common.scenario.model import load_scenario, with_overrides
from vehicle_sim.physics.dynamics import regressor as sim_regressor


@pytest.fixture(scope="module")
def sc():
    return load_scenario(CUBE8)


def test_regressor_equals_simulator():
    rng = np.random.default_rng(3)
    for _ in range(20):
        p = rng.normal(0, 3, (5, 3))
        v = rng.normal(0, 1.5, (5, 3))
        assert np.array_equal(regressor(p, v, 0.8), sim_regressor(p, v, 0.8))
        z = rng.normal(0, 0.05, 6)  # ‖Φζ‖ below F_HAT_MAX
        e = rng.normal(0, 1, 3)
        phi = regressor(p[0], v[0], 0.8)
        assert np.allclose(model_accel(p[0], v[0], z, 0.8), phi @ z)
        phte, fro2 = regressor_t_times(p[0], v[0], e, 0.8)
        assert np.allclose(phte, phi.T @ e)
        assert np.isclose(fro2, np.sum(phi**2))


def test_gain_report_paper_gains_unstable_ours_ok(sc):
    f = formation_from_scenario(sc)
    paper = gain_report(f, (9, 27, 54), 0.02, 4)
    assert not paper.ok and paper.margin.min() < 0  # Departure 7
    ours = gain_report(f, tuple(sc.observer.beta), 0.02, sc.observer.substeps)
    assert ours.ok and ours.margin.min() > 0 and ours.rho_post_update < 1.0
    assert ours.rho_single_euler_stale > 1.0  # one Euler step with stale data diverges
    assert any("Hurwitz" in line for line in ours.lines())


@pytest.mark.parametrize("anchor,kappa", [(0.0, (0.0, 0.0)), (1.0, (1.0, 4.0))])
def test_deso_converges_known_answer(sc, anchor, kappa):
    """Static formation, exact relative measurements, constant disturbance: z → truth."""
    f = formation_from_scenario(sc)
    p = f.desired_positions(sc.initial_positions()[f.leader_idx])
    v = np.zeros_like(p)
    dist = np.array([0.3, -0.2, 0.1])
    dt, sub = 0.02, 4
    obs = {}
    for i in f.follower_idx:
        obs[i] = DESO(f, i, (24, 108, 108), 0.0, 0.15, sub, dt, 0.8,
                      p[i] + np.array([0.3, -0.2, 0.25]), np.array([0.1, 0.0, -0.1]),
                      anchor, kappa)
    rel_p = {i: p - p[i] for i in f.follower_idx}
    rel_v = {i: np.zeros_like(p) for i in f.follower_idx}
    valid = np.ones(sc.n, bool)
    u_sub = np.tile(-dist, (sub, 1))  # the input cancels the disturbance: truth is static
    for _ in range(int(20 / dt)):
        pub = {i: (obs[i].z1.copy(), obs[i].z2.copy()) for i in f.follower_idx}
        for li in f.leader_idx:
            pub[li] = (p[li], v[li])
        for i in f.follower_idx:
            nb = {j: pub[j][0] for j in obs[i].nbrs}
            nv = {j: pub[j][1] for j in obs[i].nbrs}
            obs[i].update(rel_p[i], rel_v[i], valid, *rows_of(sc.n, nb, nv), u_sub)
    for i in f.follower_idx:
        assert np.allclose(obs[i].z1, p[i], atol=1e-3)
        assert np.allclose(obs[i].z2, 0.0, atol=1e-3)
        assert np.allclose(obs[i].lumped(), dist, atol=1e-3)


def test_leader_anchor_shifts_channels(sc):
    f = formation_from_scenario(sc)
    g0 = gain_report(f, (24, 108, 108), 0.02, 4, 0.0)
    g1 = gain_report(f, (24, 108, 108), 0.02, 4, 1.0)
    assert np.allclose(g1.lambda_ff, g0.lambda_ff + 2.0)
    assert g1.ok and g1.rho_post_update < g0.rho_post_update


def test_adaptive_law_bounded_for_any_innovation():
    """Whatever e2 and the (peaking) estimates are, ζ̂ stays in its box, one period moves
    it by at most dt μ (‖e2‖/2 + σ‖ζ̂‖), and ‖f̂‖ ≤ F_HAT_MAX (docs/estimation.md)."""
    rng = np.random.default_rng(11)
    mu, sigma, dt = 2.0, 0.15, 0.02  # the paper's μ, far above the scenario's
    zeta = np.zeros(6)
    for _ in range(2000):
        scale = 10.0 ** rng.uniform(-2, 4)
        z1 = rng.normal(0, scale, 3)
        z2 = rng.normal(0, scale, 3)
        e2 = rng.normal(0, scale, 3)
        phte, fro2 = regressor_t_times(z1, z2, e2, 0.8)
        new = adapt_step(zeta, phte, fro2, mu, sigma, dt)
        assert np.all(new >= ZETA_LO) and np.all(new <= ZETA_HI)
        lim = dt * mu * (np.linalg.norm(e2) / 2 + sigma * np.linalg.norm(zeta)) + 1e-12
        assert np.linalg.norm(new - zeta) <= lim
        assert np.linalg.norm(model_accel(z1, z2, new, 0.8)) <= F_HAT_MAX + 1e-9
        zeta = new
    f_inf = model_accel(np.zeros(3), np.full(3, np.inf), ZETA_HI, 0.8)
    assert np.linalg.norm(f_inf) <= F_HAT_MAX + 1e-9


def test_gate_freezes_adaptation_until_converged(sc):
    f = formation_from_scenario(sc)
    i = f.follower_idx[0]
    p = f.desired_positions(sc.initial_positions()[f.leader_idx])
    obs = DESO(f, i, (24, 108, 108), 1.0, 0.0, 4, 0.02, 0.8, p[i] + 1.0, np.full(3, 2.0),
               1.0, (1.0, 4.0))
    valid = np.ones(sc.n, bool)
    nb = {j: p[j] for j in obs.nbrs}
    nv = {j: np.zeros(3) for j in obs.nbrs}
    rows, have = rows_of(sc.n, nb, nv)
    obs.update(p - p[i], np.zeros_like(p), valid, rows, have, np.zeros((4, 3)))
    assert np.linalg.norm(obs.last_e1) > GATE_E1 and np.all(obs.zeta == 0.0)
    for _ in range(int(GATE_HOLD_S / 0.02) + 200):
        obs.update(p - p[i], np.zeros_like(p), valid, rows, have, np.zeros((4, 3)))
    assert obs.converged_s >= GATE_HOLD_S  # innovations small for long enough: adapting


@pytest.mark.full
@pytest.mark.parametrize("init_err,mu,seeds", [(1.0, 0.005, (1, 2, 3)), (2.0, 0.05, (1,))])
def test_closed_loop_observer_converges_from_large_initial_error(sc, init_err, mu, seeds):
    """cube8: before the adaptive-law bounds, init_pos_error 1 m with μ = 0.005 made seed 1
    diverge (v̂ peaking → ζ̂ at its bound in one step → v̂ ~ 1000 m/s). (Seeds 1–3 with
    2 m and μ = 0.05 are in docs/estimation.md; one here to keep the unit suite short.)"""
    from gcs.mission.inproc import run_inproc

    s2 = with_overrides(sc, observer={"init_pos_error_m": init_err, "mu": mu})
    f = formation_from_scenario(s2)
    fol = list(f.follower_idx)
    for seed in seeds:
        r = run_inproc(s2, seed=seed, duration=8.0)
        ser = r.series
        late = ser.t >= 5.0
        assert np.all(np.isfinite(ser.z2)) and np.abs(ser.z2[:, fol]).max() < 50.0
        assert np.linalg.norm(ser.z1[late][:, fol] - ser.p[late][:, fol], axis=2).max() < 0.05
        assert np.linalg.norm(ser.z2[late][:, fol] - ser.v[late][:, fol], axis=2).max() < 0.2
        assert r.metrics["formation_time_s"] is not None
