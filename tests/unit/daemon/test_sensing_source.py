"""offboard.daemon.sensing_source.SwarmSensing (one class; the Zenoh bus is a stand-in): in a
lockstep run on odometry, our own odometry of step k is put again while we wait for the
others', so a peer whose subscription came after our first put still gets it."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from conftest import CUBE8

from offboard.daemon.runner_loss import RunnerLoss
from offboard.daemon.sensing_source import OWN_REPUT_S, SwarmSensing
from swarm_common import wire
from swarm_common.enums import SensingSource
from swarm_common.scenario.model import load_scenario


class _Bus:
    """What SwarmSensing uses of SwarmBus: the odometry store, wait, publish_odometry."""

    def __init__(self) -> None:
        self.odometry: dict[int, dict[int, wire.Odometry]] = {}
        self.latest_odometry: dict[int, wire.Odometry] = {}
        self.put: list[wire.Odometry] = []

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(0.01)
        return predicate()

    def publish_odometry(self, odo: wire.Odometry) -> None:
        self.put.append(odo)


def test_own_odometry_is_put_again_while_waiting_for_the_others() -> None:
    sc = load_scenario(CUBE8)
    bus = _Bus()
    sensing = SwarmSensing(
        SensingSource.ODOMETRY, list(sc.ids), 3, bus, RunnerLoss(50),  # type: ignore[arg-type]
        lockstep=True, solo=False, truth_timeout=1.0, neighbour_timeout=1.0,
        startup_timeout=4 * OWN_REPUT_S + 0.1, sensing_range_m=10.0,
        stopped=lambda: False, on_lost=lambda: None)
    own = wire.Odometry(3, 0, 0.0, np.zeros(3), np.zeros(3))
    sensing.set_own(own)
    t0 = time.monotonic()
    sensing.for_step(0)  # nobody else's odometry ever comes: waits out the start-up timeout
    waited = time.monotonic() - t0
    assert waited >= 4 * OWN_REPUT_S
    assert len(bus.put) >= 3 and all(o is own for o in bus.put)
    assert len(bus.put) <= waited / OWN_REPUT_S + 1  # every OWN_REPUT_S, not every poll
