"""Leader trajectory, exosystem and desired-state observer (paper §4.1; Departure 9)."""


import numpy as np
import pytest
from conftest import CUBE8  # noqa: E402

from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.peer_table import rows_of
from offboard.estimation.reference import DesiredStateObserver, LeaderTrajectory, exo_propagator
from swarm_common.scenario.model import load_scenario


@pytest.fixture(scope="module")
def sc():
    return load_scenario(CUBE8)


def test_trajectory_derivatives_and_exosystem():
    tr = LeaderTrajectory(np.array([4.0, 0, 6]), np.array([0.8, 0.4, 0.2]), 0.2)
    h = 1e-5
    for t in (0.3, 2.0, 7.7):
        x, xp, xm = tr.state(t), tr.state(t + h), tr.state(t - h)
        assert np.allclose((xp[:9] - xm[:9]) / (2 * h), x[3:], atol=1e-6)
        # the exosystem reproduces the trajectory exactly
        assert np.allclose(exo_propagator(tr.omega, 1.234) @ x, tr.state(t + 1.234), atol=1e-9)
    assert np.allclose(tr.state(0.0)[:3], [4.0, 0, 6])


def test_desired_state_observer_converges(sc):
    f = formation_from_scenario(sc)
    dt = 0.02
    lt = sc.leader_trajectory
    amp = np.array(lt.amplitude_m)
    trs = {i: LeaderTrajectory(sc.agents[i].position, amp, lt.frequency_hz)
           for i in f.leader_idx}
    omega = 2 * np.pi * lt.frequency_hz
    obs = {i: DesiredStateObserver(f, i, omega, 4.0, dt,
                                   np.concatenate([sc.agents[i].position, np.zeros(9)]))
           for i in f.follower_idx}
    for k in range(int(15 / dt)):
        t = k * dt
        pub = {i: o.xi.copy() for i, o in obs.items()}
        pub.update({i: trs[i].state(t) for i in f.leader_idx})
        for i, o in obs.items():
            o.update(*rows_of(sc.n, xi={j: pub[j] for j in f.neighbours[i]}))
    t = int(15 / dt) * dt
    lead = np.array([trs[i].state(t) for i in f.leader_idx])  # (2, 12)
    for d in range(4):
        want = f.desired_positions(lead[:, 3 * d : 3 * d + 3])
        for i, o in obs.items():
            assert np.allclose(o.xi[3 * d : 3 * d + 3], want[i], atol=2e-3), (i, d)


def test_compiled_observer_step_equals_numpy_formulation(sc):
    """observer_step against the numpy update it replaced (einsum of the stacked P*_ij,
    two BLAS matrix-vector products): equal to rounding, for every neighbour subset."""
    from offboard.estimation.reference import observer_step

    f = formation_from_scenario(sc)
    i = f.follower_idx[0]
    obs = DesiredStateObserver(f, i, 0.5, 4.0, 0.02, np.zeros(12))
    rng = np.random.default_rng(9)
    nbrs = obs.nbrs
    for trial in range(200):
        used = tuple(j for j in nbrs if rng.random() < 0.7) or (nbrs[0],)
        mx, mc, pu, idx = obs._matrices(used)
        assert idx.tolist() == list(used)
        xs = rng.normal(0.0, 3.0, (len(used), 12))
        xi = rng.normal(0.0, 3.0, 12)
        c = np.einsum("kij,kdj->di", pu, xs.reshape(len(used), 4, 3)).reshape(12)
        want = mx @ xi + mc @ c
        rows, _ = rows_of(f.n, xi=dict(zip(used, xs, strict=True)))
        rows[[j for j in range(f.n) if j not in used], 9:] = np.nan  # others never read
        got = np.full(12, np.nan)
        observer_step(mx, mc, pu, idx, rows, xi, got)
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12), trial
