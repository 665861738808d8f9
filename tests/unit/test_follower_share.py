"""Who takes the whole avoidance budget (FollowerAgent._full_share, docs/safety.md A5)."""

from __future__ import annotations

from dataclasses import replace

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


def test_the_share_follows_a_neighbour_that_stops_and_resumes_cooperating() -> None:
    """The mask is kept between steps (NeighbourPredictor.revision): a later estimate
    whose ``cooperative`` flag changed must change it, in both directions."""
    sc = load_scenario(CUBE8)
    agents = [make_agent(sc, a.id, seed=1) for a in sc.agents]
    me = agents[3]
    assert isinstance(me, FollowerAgent)
    other = next(i for i, a in enumerate(agents) if isinstance(a, FollowerAgent) and a is not me)
    sel = np.array([other])
    e = agents[other].initial_estimate()
    me.pred.ingest({e.id: e}, True)
    assert not me._full_share(sel)[0]
    for t, coop in ((0.02, False), (0.04, False), (0.06, True)):
        e = replace(e, t=t, cooperative=coop)
        me.pred.ingest({e.id: e}, True)
        assert me._full_share(sel)[0] == (not coop)
    stale = replace(e, t=0.0, cooperative=False)  # older than the last: ignored
    me.pred.ingest({e.id: stale}, True)
    assert not me._full_share(sel)[0]
