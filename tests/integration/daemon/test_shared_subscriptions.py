"""The Zenoh subscriptions of a packed process (offboard.daemon.zenoh.shared_subs): one subscriber
per
key for all its daemons, each daemon still judging what it is handed. Real Zenoh sessions
over loopback TCP: one process-side session with two daemons' buses, one for the swarm."""

from __future__ import annotations

from typing import Any

import numpy as np
from conftest import free_tcp_port, wait_for

from offboard.daemon.link_guard import PayloadGuard
from offboard.daemon.zenoh.link import FIFO_DEPTH, SwarmBus
from offboard.daemon.zenoh.shared_subs import SharedSubscriptions
from swarm_common import wire
from swarm_common.zenoh_session import open_session

SWARM = "shared"
IDS = [1, 2, 3, 4, 5, 6]


def _estimate(aid: int, step: int, *, aid_on_wire: int | None = None) -> bytes:
    return wire.encode(wire.Estimate(
        id=aid if aid_on_wire is None else aid_on_wire, step=step, t=(step + 1) / 50.0,
        role="leader" if aid == 1 else "follower", z1=np.full(3, float(aid)),
        z2=np.zeros(3), z3=np.zeros(3), xi=np.zeros(12), zeta=np.zeros(6),
    ))


def _bus(session: Any, aid: int, peers: list[int], ready: list[int],
         shared: SharedSubscriptions) -> SwarmBus:
    guard = PayloadGuard(IDS, [1], 50.0, aid)
    guard.ref = 0
    return SwarmBus(session, SWARM, aid, guard, peers=peers, ready=ready, shared=shared)


def test_packed_daemons_share_subscribers_and_judge_alone() -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    own = open_session(listen=[ep])
    swarm = open_session(connect=[ep])
    shared = SharedSubscriptions(own, FIFO_DEPTH)
    a = _bus(own, 4, peers=[1, 2], ready=[1, 2, 3, 6], shared=shared)
    b = _bus(own, 5, peers=[1, 3], ready=[1, 2, 3, 6], shared=shared)
    pubs = {aid: swarm.declare_publisher(wire.key_estimate(SWARM, aid)) for aid in (1, 2, 3, 6)}
    est_keys = {wire.key_estimate(SWARM, j) for j in (1, 2, 3, 6)}
    try:
        # one subscriber per key for both buses: truth, commands, estimates 1, 2, 3, 6
        assert est_keys <= set(shared.keys()) and len(shared.keys()) == 6

        def both_heard() -> bool:
            for aid, pub in pubs.items():
                pub.put(_estimate(aid, 0))
            a.pump()  # one bus's pump hands every payload to both
            return {1, 2, 3, 6} <= a.heard and {1, 2, 3, 6} <= b.heard

        assert wait_for(both_heard)
        assert set(a.latest_estimate) == {1, 2} and set(b.latest_estimate) == {1, 3}
        assert a.latest_estimate[1] is b.latest_estimate[1]  # decoded once, shared read-only

        # a forged estimate (agent 2's key, an id not in the scenario) is dropped and
        # counted by each bus that subscribed to the key, like with subscribers of its own
        pubs[2].put(_estimate(2, 1, aid_on_wire=9))
        assert wait_for(lambda: (a.pump(), a.drops.counts.get("estimate", 0) == 1
                                 and b.drops.counts.get("estimate", 0) == 1)[1])
        assert 1 not in a.estimates

        # readiness ends for one bus: every key stays (3 is b's peer, 6 b's readiness)
        a.end_readiness()
        assert est_keys <= set(shared.keys())
        b.end_readiness()  # nobody listens to agent 6 any more: its subscriber goes
        assert set(shared.keys()) >= est_keys - {wire.key_estimate(SWARM, 6)}
        assert wire.key_estimate(SWARM, 6) not in shared.keys()
        assert wait_for(lambda: not pubs[6].matching_status.matching)
        assert pubs[2].matching_status.matching and pubs[3].matching_status.matching

        # one daemon ends; the other keeps receiving
        a.close()
        assert wire.key_estimate(SWARM, 3) in shared.keys()

        def b_got_step_2() -> bool:
            pubs[3].put(_estimate(3, 2))
            b.pump()
            return 2 in b.estimates and 3 in b.estimates[2]

        assert wait_for(b_got_step_2)
    finally:
        b.close()
        a.close()
        assert shared.keys() == []
        swarm.close()
        own.close()
