"""Whom a daemon listens to (offboard.agent.peers): a leader reads no estimate, so it
listens to the swarm only until it has heard from the agents it waits for before flying
(``SwarmBus(ready=...)``, then ``end_readiness``); a follower keeps its peers' estimates
and hears the others of its readiness set without keeping them. Real Zenoh sessions over
loopback TCP."""

from __future__ import annotations

from typing import Any

import numpy as np
from conftest import free_tcp_port, wait_for

from offboard.daemon.zenoh.link import SwarmBus
from swarm_common import wire
from swarm_common.zenoh_session import open_session

SWARM = "ready"


def _estimate(aid: int, step: int) -> bytes:
    return wire.encode(wire.Estimate(
        id=aid, step=step, t=step / 50.0, role="follower", z1=np.full(3, float(aid)),
        z2=np.zeros(3), z3=np.zeros(3), xi=np.zeros(12), zeta=np.zeros(6),
    ))


def _heard_all(bus: SwarmBus, pubs: dict[int, Any], want: set[int]) -> bool:
    """Publish one estimate of each agent and pump (delivery is asynchronous)."""
    for aid, pub in pubs.items():
        pub.put(_estimate(aid, 0))
    bus.pump()
    return want <= bus.heard


def test_leader_hears_for_readiness_then_stops_listening() -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    leader_s = open_session(listen=[ep])
    others_s = open_session(connect=[ep])
    bus = SwarmBus(leader_s, SWARM, 1, peers=[], ready=[2, 3])
    pubs = {aid: others_s.declare_publisher(wire.key_estimate(SWARM, aid)) for aid in (2, 3)}
    try:
        assert wait_for(lambda: _heard_all(bus, pubs, {2, 3}))
        assert bus.estimates == {} and bus.latest_estimate == {}  # heard, never kept
        assert all(p.matching_status.matching for p in pubs.values())
        bus.end_readiness()
        bus.end_readiness()  # idempotent
        # nobody subscribes to the followers' estimates any more
        assert wait_for(lambda: not any(p.matching_status.matching for p in pubs.values()))
        for step in range(1, 6):
            for aid, pub in pubs.items():
                pub.put(_estimate(aid, step))
        assert bus.pump() == 0 and bus.estimates == {}
    finally:
        bus.close()
        others_s.close()
        leader_s.close()


def test_follower_keeps_its_peers_and_only_hears_the_rest() -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    own = open_session(listen=[ep])
    others_s = open_session(connect=[ep])
    bus = SwarmBus(own, SWARM, 4, peers=[1, 2], ready=[1, 2, 3])
    pubs = {aid: others_s.declare_publisher(wire.key_estimate(SWARM, aid)) for aid in (1, 2, 3)}
    try:
        assert wait_for(lambda: _heard_all(bus, pubs, {1, 2, 3}))
        assert set(bus.latest_estimate) == {1, 2}
        bus.end_readiness()
        assert wait_for(lambda: not pubs[3].matching_status.matching)
        assert pubs[1].matching_status.matching and pubs[2].matching_status.matching
        assert wait_for(lambda: _heard_all(bus, {1: pubs[1]}, {1})
                        and bus.latest_estimate[1].step == 0)
    finally:
        bus.close()
        others_s.close()
        own.close()
