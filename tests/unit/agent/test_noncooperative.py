"""A non-cooperative follower ([[agent]] cooperative = false; docs/safety.md 5b): it flies its
nominal command with no filter whatever the run's method, says so in its estimates, and the
others keep their distance from it by taking the whole avoidance budget."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT

from gcs.mission.inproc import run_inproc
from offboard.agent.factory import make_agent
from swarm_common.enums import Method
from swarm_common.scenario.model import ScenarioError, load_scenario, parse_scenario

ROGUE = ROOT / "scenarios" / "cube8_rogue.toml"
ROGUE_ID = 4


def test_the_key_parses_round_trips_and_is_refused_for_a_leader() -> None:
    sc = load_scenario(ROGUE)
    assert [a.id for a in sc.agents if not a.cooperative] == [ROGUE_ID]
    data = sc.to_toml_dict()
    assert parse_scenario(data).agents[sc.index_of(ROGUE_ID)].cooperative is False
    bad = sc.to_toml_dict()
    bad["agent"][3]["cooperative"] = "no"
    msg = r"agent\[3\]\.cooperative = 'no': must be true or false"
    with pytest.raises(ScenarioError, match=msg):
        parse_scenario(bad)
    lead = sc.to_toml_dict()
    lead["agent"][0]["cooperative"] = False
    with pytest.raises(ScenarioError, match="only a follower can be non-cooperative"):
        parse_scenario(lead)
    plain = load_scenario(ROOT / "scenarios" / "cube8.toml").to_toml_dict()
    assert all("cooperative" not in a for a in plain["agent"])  # the default is not written


def test_it_flies_no_filter_and_says_so() -> None:
    sc = load_scenario(ROGUE)
    rogue = make_agent(sc, ROGUE_ID, method="dcbf")
    other = make_agent(sc, 5, method="dcbf")
    assert rogue.method is Method.NONE and other.method is Method.DCBF
    rogue.set_method("rcbf")
    assert rogue.method is Method.NONE
    p = np.array([a.position for a in sc.agents])
    v = np.array([a.velocity for a in sc.agents])
    nb = {a.id: make_agent(sc, a.id).initial_estimate() for a in sc.agents if a.id != ROGUE_ID}
    out = rogue.step(0, 0.0, p, v, nb)
    assert out.estimate.cooperative is False and out.status.method is Method.NONE


@pytest.mark.full
def test_the_others_keep_their_distance_from_it() -> None:
    sc = load_scenario(ROGUE)
    res = run_inproc(sc, "dcbf", seed=1, duration=12.0)
    s = res.series
    k = sc.index_of(ROGUE_ID)
    d = np.linalg.norm(s.p - s.p[:, k : k + 1], axis=2)
    d[:, k] = np.inf
    start = np.linalg.norm(s.p[0, k] - np.array([2.0, 2.0, 4.0]))  # the cube's centre
    assert start > 5.0 and np.linalg.norm(s.p[-1, k] - s.p_des[-1, k]) < 0.5  # it went through
    assert d.min() >= sc.controller.d_safe_m
    assert res.metrics["collisions"] == 0
