"""Who takes the whole avoidance budget (offboard.agent.shares.ShareRule, docs/safety.md A5)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import CUBE8

from offboard.agent.factory import FollowerAgent, make_agent
from swarm_common.scenario.model import load_scenario


@pytest.mark.full
def test_a_neighbour_never_heard_from_gets_the_full_share() -> None:
    sc = load_scenario(CUBE8)
    agents = [make_agent(sc, a.id, seed=1) for a in sc.agents]
    me = agents[3]
    assert isinstance(me, FollowerAgent)
    followers = [i for i, a in enumerate(agents) if isinstance(a, FollowerAgent) and a is not me]
    sel = np.array(followers)
    assert me.shares.full(sel, 0.0).all()  # nothing heard yet: no one is assumed to cooperate
    heard = {agents[i].id: agents[i].initial_estimate() for i in followers[:2]}
    me.pred.ingest(heard, True)
    share = me.shares.full(sel, 0.0)
    assert not share[:2].any() and share[2:].all()
    leaders = np.array([i for i, a in enumerate(agents) if not isinstance(a, FollowerAgent)])
    me.pred.ingest({agents[i].id: agents[i].initial_estimate() for i in leaders}, True)
    assert me.shares.full(leaders, 0.0).all()  # leaders never share


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
    assert not me.shares.full(sel, 0.0)[0]
    for t, coop in ((0.02, False), (0.04, False), (0.06, True)):
        e = replace(e, t=t, cooperative=coop)
        me.pred.ingest({e.id: e}, True)
        assert me.shares.full(sel, t)[0] == (not coop)
    stale = replace(e, t=0.0, cooperative=False)  # older than the last: ignored
    me.pred.ingest({e.id: stale}, True)
    assert not me.shares.full(sel, 0.06)[0]


def test_a_neighbour_that_alone_fell_silent_gets_the_full_share_until_heard_again() -> None:
    """A cooperative follower whose last estimate is older than ``silent_after`` while
    others are still heard (its daemon stopped, died or was cut off: docs/safety.md §5b)
    no longer gets its half; the next estimate gives it back. When everyone is silent
    (this agent's own link is out) nobody is singled out. The cached mask is not touched
    (a copy is marked)."""
    sc = load_scenario(CUBE8)
    agents = [make_agent(sc, a.id, seed=1) for a in sc.agents]
    me = agents[3]
    assert isinstance(me, FollowerAgent)
    assert me.shares.silent_after == max(0.1, 3 * sc.control_dt)
    others = [i for i, a in enumerate(agents) if isinstance(a, FollowerAgent) and a is not me]
    sel = np.array(others[:2])
    limit = 1.0 + me.shares.silent_after
    for i in others:
        e = replace(agents[i].initial_estimate(), t=1.0)
        me.pred.ingest({e.id: e}, True)
    assert not me.shares.full(sel, limit).any()  # at the limit: still heard
    assert not me.shares.full(sel, limit + 1e-6).any()  # everyone silent: our link is out
    e = replace(agents[others[-1]].initial_estimate(), t=1.2)
    me.pred.ingest({e.id: e}, True)  # a third follower is heard: the two stand out
    assert me.shares.full(sel, 1.2).all()
    e = replace(agents[others[0]].initial_estimate(), t=1.5)
    me.pred.ingest({e.id: e}, True)  # the first one speaks again
    assert me.shares.full(sel, 1.52).tolist() == [False, True]
    assert not me.shares.mask()[sel].any()  # the cached mask only holds who cooperates
