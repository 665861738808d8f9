"""A daemon's odometry goes on Zenoh only while someone subscribes to it (the publisher's
matching status, offboard.daemon.zenoh.link.SwarmBus.publish_odometry): real sessions over
loopback TCP, one publishing agent and one subscriber that comes and goes."""

from __future__ import annotations

import numpy as np
from conftest import free_tcp_port, wait_for

from offboard.daemon.zenoh.link import SwarmBus
from swarm_common import wire
from swarm_common.zenoh_session import open_session


def test_odometry_is_published_only_while_matched() -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    agent = open_session(listen=[ep])
    other = open_session(connect=[ep])
    bus = SwarmBus(agent, "odo", 3)
    got: list[bytes] = []

    def odo(step: int) -> wire.Odometry:
        return wire.Odometry(3, step, step / 50.0, np.zeros(3), np.zeros(3))

    try:
        for step in range(20):  # nobody listens: nothing is put
            bus.publish_odometry(odo(step))
        assert not bus.odometry_matched
        sub = other.declare_subscriber(wire.key_odometry("odo", 3),
                                       lambda s: got.append(s.payload.to_bytes()))
        assert wait_for(lambda: bus.odometry_matched)

        def published() -> bool:  # delivery is asynchronous: keep publishing until one lands
            bus.publish_odometry(odo(20))
            return bool(got)

        assert wait_for(published)
        first = wire.decode(got[0])
        assert isinstance(first, wire.Odometry) and first.id == 3 and first.step == 20
        sub.undeclare()
        assert wait_for(lambda: not bus.odometry_matched)
    finally:
        bus.close()
        other.close()
        agent.close()
