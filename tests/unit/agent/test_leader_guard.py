"""A dcbf leader keeps its pairs with the scenario's non-cooperative agents
(offboard.agent.leader_guard; docs/safety.md 5b): nobody else does."""

from __future__ import annotations

import numpy as np
from conftest import ROOT

from gcs.mission.inproc import run_inproc
from offboard.agent.factory import make_agent
from offboard.records import AgentStatus
from swarm_common.enums import Method
from swarm_common.scenario.model import load_scenario

ROGUE = ROOT / "scenarios" / "cube8_rogue.toml"
ROGUE_ID = 4


def test_only_a_scenario_with_a_rogue_gives_its_leaders_a_guard() -> None:
    sc = load_scenario(ROGUE)
    leaders = [make_agent(sc, i, method="dcbf") for i in sc.leader_ids]
    assert all(ld.guard is not None for ld in leaders)
    assert list(leaders[0].guard.mask.nonzero()[0]) == [sc.index_of(ROGUE_ID)]
    plain = load_scenario(ROOT / "scenarios" / "cube8.toml")
    assert all(make_agent(plain, i, method="dcbf").guard is None for i in plain.leader_ids)


def _pair(gap: float, closing: float) -> tuple[np.ndarray, np.ndarray]:
    """Every agent far apart, the rogue ``gap`` m from leader 1 along +x, closing at
    ``closing`` m/s."""
    sc = load_scenario(ROGUE)
    n = sc.n
    p = np.array([[30.0 * j, 40.0, 5.0] for j in range(n)])
    v = np.zeros((n, 3))
    i, k = sc.index_of(sc.leader_ids[0]), sc.index_of(ROGUE_ID)
    p[i] = [0.0, 0.0, 5.0]
    p[k] = [gap, 0.0, 5.0]
    v[k] = [-closing, 0.0, 0.0]
    return p, v


def test_the_guard_leaves_a_far_command_and_turns_a_near_one_away() -> None:
    sc = load_scenario(ROGUE)
    ld = make_agent(sc, sc.leader_ids[0], method="dcbf")
    guard = ld.guard
    u_nom = np.array([0.5, 0.0, 0.0])  # toward the rogue
    far = AgentStatus(method=Method.DCBF, u_nom=u_nom)
    p, v = _pair(sc.formation.sensing_range_m + 5.0, 0.0)
    assert guard.apply(0.0, p, v, u_nom, np.zeros(3), far) is u_nom  # nobody sensed: as is
    assert far.n_sensed == 0 and far.h_min == np.inf
    near = AgentStatus(method=Method.DCBF, u_nom=u_nom)
    p, v = _pair(2.0, 2.0)
    u = guard.apply(0.02, p, v, u_nom, np.zeros(3), near)
    assert near.n_sensed == 1 and np.isfinite(near.h_min)
    assert u[0] < -1.0  # it brakes away from the rogue instead of closing
    assert near.correction > 1.0


def test_the_leader_rogue_pair_stays_above_zero_where_it_broke() -> None:
    """Seed 2 broke the leader–rogue barrier at t = 0.86 s before the guard (h −1.54 m²)."""
    sc = load_scenario(ROGUE)
    res = run_inproc(sc, "dcbf", seed=2, duration=3.0)
    s, ctl = res.series, sc.controller
    k = sc.index_of(ROGUE_ID)
    for lead in sc.leader_ids:
        i = sc.index_of(lead)
        dp, dv = s.p[:, i] - s.p[:, k], s.v[:, i] - s.v[:, k]
        h = (np.einsum("ij,ij->i", dp, dp) + 2.0 * ctl.tau_safe_s * np.einsum("ij,ij->i", dv, dp)
             - ctl.d_safe_m**2)
        assert h.min() >= 0.0, (lead, h.min())
    assert res.metrics["h_min"] >= 0.0 and res.metrics["own_h_min"] >= 0.0
