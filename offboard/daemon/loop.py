"""The daemon's agent loop: one agent step per new ODOMETRY stamp of the vehicle, and what
it sends (docs/architecture.md, "Lockstep, step by step").

It drives the same :mod:`offboard.agent.factory` object the in-process runner drives, in
the same order:

1. the vehicle's ODOMETRY stamped t_k tells the step k (the clock; a follower never
   uses the position in it);
2. get the sensor's inputs of step k (:mod:`offboard.daemon.sensing_source`), apply the
   ground station's commands, and take every neighbour's ``Estimate`` of step k-1
   (skipped inside the scenario's communication outages, which are deterministic);
3. ``agent.step(...)`` -> SET_ATTITUDE_TARGET with ``time_boot_ms`` = t_k, then publish
   the estimate for t_{k+1} and a status record.

It talks to its links through :mod:`offboard.daemon.ports` only, and leaves what differs
between lockstep and real time to its driver (:mod:`offboard.daemon.drivers`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from offboard.agent.factory import FollowerAgent, LeaderAgent
from offboard.daemon.commands import GroundCommands
from offboard.daemon.drivers import StepDriver, vehicle_state
from offboard.daemon.mavlink.mode_requests import SwarmReady
from offboard.daemon.ports import SwarmPort, VehiclePort
from offboard.daemon.sensing_source import SwarmSensing
from offboard.daemon.stream import EstimateOutbox, SetpointStream
from offboard.daemon.wire_convert import estimate_to_wire, status_to_wire
from offboard.safety.monitor import ALARM_TEXT, alarm_onsets
from swarm_common import px4, wire
from swarm_common.enums import SensingSource

log = logging.getLogger("offboard.daemon.core")  # the daemon's lines keep one logger name


class AgentLoop:
    """One agent's steps, and its outputs to the vehicle and the swarm."""

    def __init__(
        self, agent_id: int, agent: LeaderAgent | FollowerAgent, control_hz: int,
        vehicle: VehiclePort, swarm: SwarmPort, *, source: SensingSource,
        sensing: SwarmSensing, commands: GroundCommands, stream: SetpointStream,
        outbox: EstimateOutbox, ready: SwarmReady, driver: StepDriver,
    ) -> None:
        self.id = agent_id
        self.agent = agent
        self.control_hz = control_hz
        self.vehicle = vehicle
        self.swarm = swarm
        self.source = source
        self.sensing = sensing
        self.commands = commands
        self.stream = stream
        self.outbox = outbox
        self.ready = ready
        self.driver = driver
        self.last_step = -1
        self.odo_pub_step = -1  # the last step whose own odometry went out
        self.alarms = 0  # the last step's AgentAlarm bits (a WARNING at each onset)
        # alarm bits that the daemon, not the agent's step, finds (the vehicle's fence that
        # the filter could not take: offboard.daemon.fence_sync), added to every step's
        self.daemon_alarms: Callable[[], int] = _no_alarms
        self.cooperative = True
        # CPU of this thread inside agent.step (s): the control law runs on the main thread
        # alone (numba kernels, single-threaded BLAS). Not the process's CPU clock: it
        # counted Zenoh's threads as control, and reading it sums every thread and locks
        # the run queue of each one running on another core (19 % of the wall-clock
        # samples of a busy packed process; docs/performance.md, seventh round)
        self.control_cpu_s = 0.0
        self.control_steps = 0

    def zeta(self) -> np.ndarray | None:
        return self.agent.deso.zeta if isinstance(self.agent, FollowerAgent) else None

    def publish_initial_estimate(self) -> None:
        self.outbox.publish(estimate_to_wire(self.agent.initial_estimate(), -1, self.zeta()))

    # -- the vehicle's clock ------------------------------------------------------------
    def vehicle_clock(self) -> None:
        """The vehicle's step from its latest ODOMETRY: the reference of the Zenoh guard."""
        odo = self.vehicle.odometry
        k = -1 if odo is None else int(round(odo.time_usec * 1e-6 * self.control_hz))
        if k != self.stream.vehicle_step and k >= 0:
            self.stream.vehicle_step = k
            self.swarm.set_reference(k)

    def on_odometry(self) -> None:
        """One control step per new ODOMETRY stamp (both drivers), once the swarm is ready
        (the arming policy: no setpoint, so no OFFBOARD or arm, before)."""
        k = self.stream.vehicle_step
        if k >= 0:
            self.publish_odometry(k)
        if k > self.last_step and self.ready.check(self.swarm.heard, time.monotonic()):
            self.swarm.end_readiness()
            t = k / self.control_hz
            ms = int(round(t * 1000))
            if (self.control_step(k, t, ms)
                    or self.driver.fallback_step(k, t, ms, self.stream)):
                self.last_step = k

    def publish_odometry(self, k: int) -> None:
        """Our vehicle's measured state at t_k on Zenoh, once per step (the others'
        ``--sensing odometry``), and handed to our own sensing source."""
        if self.source is SensingSource.TRUTH and not self.swarm.odometry_matched:
            return  # nobody reads it: neither our sensing (truth) nor a subscriber
        if k == self.odo_pub_step:
            self.sensing.put_own_again()  # a peer that subscribed late still gets it
            return
        got = vehicle_state(self.vehicle, 0.0)
        if got is None:
            return
        self.odo_pub_step = k
        msg = wire.Odometry(self.id, k, k / self.control_hz, wire.f32(got[0]), wire.f32(got[1]))
        self.sensing.set_own(msg)
        self.swarm.publish_odometry(msg)

    # -- the control step ---------------------------------------------------------------
    def control_step(self, k: int, t: float, time_boot_ms: int) -> bool:
        """The agent's step k at mission time t; False without the sensor's inputs."""
        sensed = self.sensing.for_step(k)
        if sensed is None:
            return False
        self.commands.apply(self.swarm.pop_commands(), t)
        self.commands.maybe_start_landing(t)
        self.driver.before_step(t)
        comm_ok = self.commands.comm_ok(t)
        received = self.driver.neighbours(k) if comm_ok else {}
        neighbours = self.driver.neighbour_batch(k, received)
        cpu0 = time.thread_time()
        out = self.agent.step(k, t, sensed[0], sensed[1], neighbours, comm_ok)
        self.control_cpu_s += time.thread_time() - cpu0
        out.status.alarms |= self.daemon_alarms()
        self.control_steps += 1
        self.driver.after_step(k, t)
        self.stream.set_answer((time_boot_ms, out.q_ned, out.thrust_norm), k, from_loss=False)
        self.stream.send()
        est = estimate_to_wire(out.estimate, k, self.zeta())
        self.outbox.publish(self._mark_cooperation(est, t))
        mode = px4.short_name(self.vehicle.custom_mode)
        self.swarm.publish_status(status_to_wire(self.id, k, t, out, mode, comm_ok))
        for bit in alarm_onsets(self.alarms, out.status.alarms):
            log.warning("agent %d: safety alarm %s at t=%.2f s: %s", self.id, bit.name,
                        t, ALARM_TEXT[bit])
        self.alarms = out.status.alarms
        return True

    def _mark_cooperation(self, est: wire.Estimate, t: float) -> wire.Estimate:
        """Out of OFFBOARD after the mission had it there (a third party's AUTO.LAND, HOLD,
        ...): the agent's setpoints no longer fly, so publish cooperative=False and the
        vehicle's measured state instead of the estimate of a controller that does not fly
        it (docs/lifecycle.md, "Third-party AUTO.LAND"). Control is not taken back."""
        # the mission has had the vehicle in OFFBOARD: latched by the link, backlog included
        cooperative = self.vehicle.in_offboard or not self.vehicle.offboard_reported
        if cooperative != self.cooperative:
            self.cooperative = cooperative
            mode = px4.short_name(self.vehicle.custom_mode)
            if cooperative:
                log.info("agent %d: vehicle back in OFFBOARD at t=%.2f s", self.id, t)
            else:
                log.warning("agent %d: vehicle left OFFBOARD (%s) at t=%.2f s: publishing "
                            "its measured state as non-cooperative", self.id, mode, t)
        if cooperative:
            return est
        est.cooperative = False
        got = vehicle_state(self.vehicle, 1.0 / self.control_hz)
        if got is not None:
            est.z1, est.z2 = got
            est.z3 = np.zeros(3)
        return est


def _no_alarms() -> int:
    """No alarm bit of the daemon's own (:attr:`AgentLoop.daemon_alarms`' default)."""
    return 0
