"""The daemon's agent loop (offboard.daemon.loop) on test doubles of its two ports
(offboard.daemon.ports): no socket, no Zenoh session. Lockstep driver: one step per new
ODOMETRY stamp once the step's truth is there, the agent's answer to the vehicle, its
estimate and status to the swarm, the ground station's commands at the step."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import SupportsFloat

import numpy as np
from conftest import CUBE8

from offboard.agent.factory import make_agent
from offboard.daemon.commands import GroundCommands
from offboard.daemon.drivers import LockstepDriver
from offboard.daemon.loop import AgentLoop
from offboard.daemon.mavlink.mode_requests import SwarmReady
from offboard.daemon.mavlink.odometry import Odometry
from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper
from offboard.daemon.runner_loss import RunnerLoss
from offboard.daemon.sensing_source import OWN_REPUT_S, SwarmSensing
from offboard.daemon.stream import EstimateOutbox, SetpointStream
from offboard.daemon.wire_convert import estimates_from_wire
from swarm_common import wire
from swarm_common.enums import SensingSource
from swarm_common.scenario.model import load_scenario

HZ = 50


class _Vehicle:
    def __init__(self) -> None:
        self.odometry: Odometry | None = None
        self.armed = self.in_offboard = self.offboard_reported = False
        self.custom_mode = 0
        self.sent: list[tuple[int, list[float], float]] = []

    def send_attitude_target(self, time_boot_ms: int, q_wxyz: Iterable[SupportsFloat],
                             thrust_norm: SupportsFloat) -> None:
        self.sent.append((time_boot_ms, [float(c) for c in q_wxyz], float(thrust_norm)))

    def stamp(self, k: int) -> None:
        self.odometry = Odometry(time_usec=k * 1_000_000 // HZ, x=0.0, y=0.0, z=0.0,
                                 received=0.0)


class _Swarm:
    """The SwarmPort of a test, and the truth store the sensing source reads."""

    def __init__(self) -> None:
        self.estimates: dict[int, dict[int, wire.Estimate]] = {}
        self.latest_estimate: dict[int, wire.Estimate] = {}
        self.heard: set[int] = set()
        self.odometry_matched = False
        self.truth: dict[int, wire.Truth] = {}
        self.latest_truth: wire.Truth | None = None
        self.commands: list[wire.Command] = []
        self.reference = -1
        self.published: list[wire.Estimate | wire.Status | wire.Odometry] = []

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        return predicate()  # nothing more will arrive

    def estimates_at(self, step: int) -> dict[int, wire.Estimate]:
        return dict(self.estimates.get(step, {}))

    def set_reference(self, step: int) -> None:
        self.reference = step

    def end_readiness(self) -> None:
        pass

    def pop_commands(self) -> list[wire.Command]:
        out, self.commands = self.commands, []
        return out

    def publish_estimate(self, est: wire.Estimate) -> None:
        self.published.append(est)

    def publish_status(self, status: wire.Status) -> None:
        self.published.append(status)

    def publish_odometry(self, odo: wire.Odometry) -> None:
        self.published.append(odo)


def _truth(k: int, n: int) -> wire.Truth:
    z = np.zeros((n, 3))
    return wire.Truth(k, k / HZ, list(range(1, n + 1)), z, z, z, np.zeros(n), z)


def _loop() -> tuple[AgentLoop, _Vehicle, _Swarm]:
    sc = load_scenario(CUBE8)
    assert int(sc.run.control_hz) == HZ
    agent = make_agent(sc, 1)  # a leader: it reads no peer's estimate
    vehicle, swarm, loss = _Vehicle(), _Swarm(), RunnerLoss(HZ)
    index_of = {aid: j for j, aid in enumerate(sc.ids)}
    driver = LockstepDriver(swarm, 1, [], index_of, None, solo=True, startup_timeout=1.0,
                            neighbour_timeout=0.45, stopped=lambda: False)
    sensing = SwarmSensing(
        SensingSource.TRUTH, list(sc.ids), 1, swarm, loss,  # type: ignore[arg-type]
        lockstep=True, solo=True, truth_timeout=0.1, neighbour_timeout=0.45,
        startup_timeout=1.0, sensing_range_m=sc.formation.sensing_range_m,
        stopped=lambda: False, on_lost=lambda: None)
    keeper = OffboardKeeper(0.6, False)
    loop = AgentLoop(
        1, agent, HZ, vehicle, swarm, source=SensingSource.TRUTH, sensing=sensing,
        commands=GroundCommands(sc, agent, 1), outbox=EstimateOutbox(swarm),
        stream=SetpointStream(1, vehicle, keeper, loss, driver.answer_fresh),
        ready=SwarmReady(1, [], True, 3.0), driver=driver)
    return loop, vehicle, swarm


def test_one_step_per_odometry_stamp_with_its_truth() -> None:
    loop, vehicle, swarm = _loop()
    loop.publish_initial_estimate()
    assert [p.step for p in swarm.published if isinstance(p, wire.Estimate)] == [-1]
    vehicle.stamp(0)
    swarm.truth[0] = _truth(0, 8)
    swarm.commands = [wire.Command(kind="land", at_s=30.0)]
    loop.vehicle_clock()
    assert loop.stream.vehicle_step == 0 and swarm.reference == 0
    loop.on_odometry()
    assert loop.last_step == 0 and loop.control_steps == 1
    assert [s[0] for s in vehicle.sent] == [0]  # time_boot_ms = t_0
    est = [p for p in swarm.published if isinstance(p, wire.Estimate)]
    status = [p for p in swarm.published if isinstance(p, wire.Status)]
    assert [e.step for e in est] == [-1, 0] and [s.step for s in status] == [0]
    assert loop.commands.land_at == 30.0  # the command applied at the step
    loop.on_odometry()  # the same stamp again: no second step
    assert loop.control_steps == 1
    # step 1 without its truth: no step, and the answer of step 0 no longer goes out
    vehicle.stamp(1)
    loop.vehicle_clock()
    loop.on_odometry()
    loop.stream.send()
    assert loop.last_step == 0 and len(vehicle.sent) == 1
    swarm.truth[1] = _truth(1, 8)
    loop.on_odometry()
    assert loop.last_step == 1 and [s[0] for s in vehicle.sent] == [0, 20]


def test_the_loop_hands_the_agent_what_the_in_process_runner_would() -> None:
    """The answer the loop sends is the agent's own output for the step's truth."""
    loop, vehicle, swarm = _loop()
    vehicle.stamp(0)
    swarm.truth[0] = _truth(0, 8)
    loop.vehicle_clock()
    loop.on_odometry()
    alone = make_agent(load_scenario(CUBE8), 1)
    t0 = swarm.truth[0]
    out = alone.step(0, 0.0, t0.p, t0.v, estimates_from_wire({}, 8, {}), True)
    assert vehicle.sent[0][1] == [float(c) for c in out.q_ned]
    assert vehicle.sent[0][2] == float(out.thrust_norm)


def test_own_odometry_is_put_again_while_the_vehicle_waits_at_a_step() -> None:
    """Lockstep: a peer whose subscription came after our put of step k still gets it
    while our vehicle waits at k (for that very peer's setpoint): the same record goes out
    again every OWN_REPUT_S, never more often, and a new step puts the new record."""
    loop, vehicle, swarm = _loop()
    swarm.odometry_matched = True  # someone reads our odometry
    vehicle.stamp(0)
    loop.vehicle_clock()
    loop.on_odometry()

    def puts() -> list[wire.Odometry]:
        return [p for p in swarm.published if isinstance(p, wire.Odometry)]

    assert [o.step for o in puts()] == [0]
    loop.on_odometry()  # at once: not again
    assert len(puts()) == 1
    loop.sensing.own_put_at -= OWN_REPUT_S  # as if OWN_REPUT_S had passed at step 0
    loop.on_odometry()
    assert [o.step for o in puts()] == [0, 0] and puts()[1] is puts()[0]
    vehicle.stamp(1)
    loop.vehicle_clock()
    loop.on_odometry()
    assert [o.step for o in puts()] == [0, 0, 1]
