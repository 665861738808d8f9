"""A packed lockstep process's burst (offboard.daemon.output_burst): a pass's setpoint datagrams
and Zenoh puts go out together at its end, in order, and an agent's own odometry is
never held. Real UDP on loopback, real Zenoh sessions over loopback TCP."""

from __future__ import annotations

import os
import socket
import time
from typing import Any

import numpy as np
from conftest import free_port_offset, free_tcp_port, received_frames, wait_for

os.environ.setdefault("MAVLINK20", "1")

from offboard.daemon.link_guard import PayloadGuard  # noqa: E402
from offboard.daemon.mavlink.link import VehicleLink  # noqa: E402
from offboard.daemon.output_burst import OutputBurst  # noqa: E402
from offboard.daemon.zenoh.link import SwarmBus  # noqa: E402
from swarm_common import wire  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402
from swarm_common.zenoh_session import open_session  # noqa: E402

SWARM = "burst"


def test_vehicle_link_setpoints_wait_for_the_flush_in_order() -> None:
    port = vehicle_ports(3, free_port_offset()).api_remote
    link = VehicleLink(f"udpin:127.0.0.1:{port}", 3, 50.0, lockstep=True)
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.3)
    try:
        link.peer = vehicle.getsockname()  # as locked to this vehicle
        link.burst = burst = OutputBurst()
        for ms in (10, 20, 30):
            link.send_attitude_target(ms, (1.0, 0.0, 0.0, 0.0), 0.5)
        time.sleep(0.2)
        assert received_frames(vehicle) == [] and link.sent == 0 and len(burst) == 3
        burst.flush()
        got: list[Any] = []
        assert wait_for(lambda: bool(got.extend(received_frames(vehicle))) or len(got) >= 3)
        assert [m.time_boot_ms for m in got] == [10, 20, 30]
        seqs = [m.get_seq() for m in got]
        assert seqs == [seqs[0], seqs[0] + 1, seqs[0] + 2] and link.sent == 3
        link.burst = None  # outside a burst: at once
        link.send_attitude_target(40, (1.0, 0.0, 0.0, 0.0), 0.5)
        more: list[Any] = []
        assert wait_for(lambda: bool(more.extend(received_frames(vehicle))) or len(more) >= 1)
        assert [m.time_boot_ms for m in more] == [40]
    finally:
        link.close()
        vehicle.close()


def test_swarm_bus_holds_estimates_but_never_odometry() -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    own = open_session(listen=[ep])
    swarm = open_session(connect=[ep])
    guard = PayloadGuard([1, 2], [1], 50.0, 2)
    bus = SwarmBus(own, SWARM, 2, guard)
    seen: dict[str, list[bytes]] = {"est": [], "odo": []}
    subs = [
        swarm.declare_subscriber(wire.key_estimate(SWARM, 2),
                                 lambda s: seen["est"].append(s.payload.to_bytes())),
        swarm.declare_subscriber(wire.key_odometry(SWARM, 2),
                                 lambda s: seen["odo"].append(s.payload.to_bytes())),
    ]
    try:
        assert wait_for(lambda: bus.odometry_matched)
        bus.burst = burst = OutputBurst()
        est = wire.Estimate(id=2, step=4, t=0.1, role="follower", z1=np.ones(3),
                            z2=np.zeros(3), z3=np.zeros(3), xi=np.zeros(12), zeta=np.zeros(6))
        bus.publish_estimate(est)
        bus.publish_odometry(wire.Odometry(2, 4, 0.08, np.ones(3), np.zeros(3)))
        assert wait_for(lambda: len(seen["odo"]) == 1)
        time.sleep(0.2)
        assert seen["est"] == [] and len(burst) == 1  # the estimate waits for the pass's end
        burst.flush()
        assert wait_for(lambda: len(seen["est"]) == 1)
        got = wire.decode(seen["est"][0])
        assert isinstance(got, wire.Estimate) and got.step == 4
    finally:
        for s in subs:
            s.undeclare()
        bus.close()
        own.close()
        swarm.close()
