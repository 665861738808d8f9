"""Who takes the whole avoidance budget (FollowerAgent._full_share, docs/safety.md A5)."""

from __future__ import annotations

import numpy as np
from conftest import CUBE8

from offboard.agent import FollowerAgent, make_agent
from swarm_common.scenario import load_scenario


def test_a_neighbour_never_heard_from_gets_the_full_share() -> None:
    sc = load_scenario(CUBE8)
    agents = [make_agent(sc, a.id, seed=1) for a in sc.agents]
    me = agents[3]
    assert isinstance(me, FollowerAgent)
    followers = [i for i, a in enumerate(agents) if isinstance(a, FollowerAgent) and a is not me]
    sel = np.array(followers)
    assert me._full_share(sel).all()  # nothing heard yet: no one is assumed to cooperate
    heard = {agents[i].id: agents[i].initial_estimate() for i in followers[:2]}
    me.pred.ingest(heard, True)
    share = me._full_share(sel)
    assert not share[:2].any() and share[2:].all()
    leaders = np.array([i for i, a in enumerate(agents) if not isinstance(a, FollowerAgent)])
    me.pred.ingest({agents[i].id: agents[i].initial_estimate() for i in leaders}, True)
    assert me._full_share(leaders).all()  # leaders never share
