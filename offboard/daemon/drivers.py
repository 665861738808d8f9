"""The two drivers of the daemon's agent loop (:mod:`offboard.daemon.loop`): what differs
between a lockstep and a real-time daemon, and nothing else.

Both step the agent once per new ODOMETRY stamp of the vehicle (the vehicle's clock).

* :class:`LockstepDriver` - the simulator's clock waits for the swarm: step k waits for
  every live neighbour's estimate of step k-1 (a neighbour silent for
  ``neighbour_timeout`` is lost and no longer waited for until it speaks); a setpoint
  answers the vehicle's step it was computed for, and no other. Steps equal those of the
  in-process runner bit for bit.
* :class:`RealtimeDriver` - the wall clock runs on: step k uses the latest estimates it
  holds (stale ones predicted by the agent); a setpoint is valid one control period. With
  the real-time failsafes: the runner-loss hold and landing on the vehicle's own ODOMETRY
  (:mod:`offboard.daemon.runner_loss`), the navigation check
  (:mod:`offboard.daemon.nav_check`), the leaders' trajectory start once flying in
  OFFBOARD, and a ground start held on its pad for the take-off command (``--manual-start``).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Protocol

import numpy as np

from offboard.agent.factory import FollowerAgent, LeaderAgent
from offboard.daemon.mavlink.mode_requests import ModeRequests
from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper
from offboard.daemon.nav_check import NavigationCheck
from offboard.daemon.ports import SwarmPort, VehiclePort
from offboard.daemon.runner_loss import LossFlight, RunnerLoss
from offboard.daemon.stream import SetpointStream
from offboard.daemon.wire_convert import estimates_from_wire, measured_state
from offboard.daemon.zenoh.shared_batch import SharedBatch
from offboard.estimation.peer_table import EstimateBatch
from swarm_common import wire
from swarm_common.scenario.model import Scenario

log = logging.getLogger("offboard.daemon.core")  # the daemon's lines keep one logger name


def vehicle_state(vehicle: VehiclePort, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The vehicle's (position, velocity) ENU from its latest ODOMETRY, the position
    carried ``dt`` s ahead (offboard.daemon.wire_convert.measured_state); None without one."""
    odo = vehicle.odometry
    return None if odo is None else measured_state(odo, dt)


class StepDriver(Protocol):
    """What the agent loop asks of its driver at each step."""

    def answer_fresh(self, stream: SetpointStream, now: float) -> bool:
        """Whether the stream's answer still answers the vehicle."""
        ...

    def before_step(self, t: float) -> None:
        """Before the agent's step of mission time ``t`` (after the commands)."""
        ...

    def neighbours(self, k: int) -> dict[int, wire.Estimate]:
        """The neighbours' estimates the step k uses (outside outages), by id."""
        ...

    def neighbour_batch(self, k: int, received: Mapping[int, wire.Estimate]) -> EstimateBatch:
        """``received`` as the agent consumes it."""
        ...

    def after_step(self, k: int, t: float) -> None:
        """After the agent's step k."""
        ...

    def fallback_step(self, k: int, t: float, time_boot_ms: int, stream: SetpointStream) -> bool:
        """When the agent could not step (no sensing for step k): an answer of the driver's
        own, True when one went out."""
        ...

    def summary(self) -> str:
        """The driver's part of the daemon's last line ("" or "; ...")."""
        ...


class LockstepDriver:
    """The lockstep rules (module docstring)."""

    def __init__(
        self, swarm: SwarmPort, agent_id: int, others: list[int], index_of: Mapping[int, int],
        batch: SharedBatch | None, *, solo: bool, startup_timeout: float,
        neighbour_timeout: float, stopped: Callable[[], bool],
    ) -> None:
        """``others``: the peers whose estimates the agent reads; ``index_of``: id ->
        scenario index; ``batch``: the packed process's shared batch, None for batches of
        its own."""
        self.swarm = swarm
        self.id = agent_id
        self.others = others
        self.index_of = index_of
        self.peer_idx = np.array([index_of[j] for j in others], dtype=np.int64)
        self.batch = batch
        self.solo = solo
        self.startup_timeout = startup_timeout
        self.neighbour_timeout = neighbour_timeout
        self.stopped = stopped
        self.lost: set[int] = set()  # neighbours no longer waited for (until they speak)

    def answer_fresh(self, stream: SetpointStream, now: float) -> bool:
        """The vehicle's clock waits for the answer to its current step."""
        return stream.vehicle_step <= stream.answer_step

    def before_step(self, t: float) -> None:
        pass

    def neighbours(self, k: int) -> dict[int, wire.Estimate]:
        """Neighbour estimates of step k-1: wait for every live one."""
        want = [j for j in self.others if j not in self.lost]
        swarm = self.swarm

        def have_all() -> bool:
            got = swarm.estimates.get(k - 1, {})
            return all(j in got for j in want)

        # Step 0 waits for every agent's initial estimate as long as start-up may take
        # (the others may still be importing); later a silent neighbour is declared lost.
        # (--solo: no start-up wait for neighbours that may never come)
        startup = k == 0 and not self.solo
        timeout = self.startup_timeout if startup else self.neighbour_timeout
        complete = swarm.wait(lambda: self.stopped() or have_all(), timeout) and not self.stopped()
        got = swarm.estimates_at(k - 1)
        if not complete:
            for j in want:
                if j not in got:
                    log.warning("agent %d: neighbour %d silent at step %d: lost", self.id, j, k)
                    self.lost.add(j)
        for j in list(self.lost):
            if j in got:
                self.lost.discard(j)
                log.info("agent %d: neighbour %d back", self.id, j)
        return got

    def neighbour_batch(self, k: int, received: Mapping[int, wire.Estimate]) -> EstimateBatch:
        if self.batch is None:
            return estimates_from_wire(self.index_of, len(self.index_of), received)
        return self.batch.batch_for(k - 1, received, self.peer_idx)

    def after_step(self, k: int, t: float) -> None:
        pass

    def fallback_step(self, k: int, t: float, time_boot_ms: int, stream: SetpointStream) -> bool:
        """No step without the simulator's data: the vehicle's clock waits."""
        return False

    def summary(self) -> str:
        return ""


class RealtimeDriver:
    """The real-time rules and failsafes (module docstring)."""

    def __init__(
        self, sc: Scenario, agent: LeaderAgent | FollowerAgent, agent_id: int,
        vehicle: VehiclePort, swarm: SwarmPort, index_of: Mapping[int, int], *,
        keeper: OffboardKeeper, modes: ModeRequests, loss: RunnerLoss, nav_gate_m: float,
        manual_start: bool,
    ) -> None:
        """``nav_gate_m``: the navigation check's gate of a follower (0: no check);
        ``manual_start``: a ground start waits on its pad for the take-off command."""
        self.sc = sc
        self.agent = agent
        self.id = agent_id
        self.vehicle = vehicle
        self.swarm = swarm
        self.index_of = index_of
        self.control_hz = int(sc.run.control_hz)
        self.keeper = keeper
        self.modes = modes
        self.loss = loss
        self.loss_flight = LossFlight(sc, agent.index, agent_id, loss)
        # followers: the DESO estimate against the vehicle's own odometry
        checked = isinstance(agent, FollowerAgent) and nav_gate_m > 0.0
        self.nav = NavigationCheck(self.control_hz, nav_gate_m) if checked else None
        self.trajectory_started = False
        if manual_start and agent.hold_for_takeoff():
            log.info("agent %d: on its pad until the take-off command", agent_id)

    def answer_fresh(self, stream: SetpointStream, now: float) -> bool:
        """A setpoint is valid for one control period."""
        return now - stream.answer_at <= 1.0 / self.control_hz

    def before_step(self, t: float) -> None:
        if isinstance(self.agent, LeaderAgent):
            self._maybe_start_trajectory(self.agent, t)

    def _maybe_start_trajectory(self, agent: LeaderAgent, t: float) -> None:
        """Hold p_L(0) until flying in OFFBOARD, then start the trajectory at the next
        whole period (both leaders pick the same instant)."""
        if self.trajectory_started:
            return
        if self.vehicle.armed and self.vehicle.in_offboard:
            f_hz = float(self.sc.leader_trajectory.frequency_hz)
            period = 1.0 / f_hz if f_hz > 0.0 else 1.0  # a mission starts on a whole second
            agent.start_time = math.ceil(t / period) * period
            self.trajectory_started = True
            log.info("agent %d: trajectory starts at t = %.2f s", self.id, agent.start_time)
        else:
            agent.start_time = math.inf

    def neighbours(self, k: int) -> dict[int, wire.Estimate]:
        """The latest estimate of each neighbour, however old (the agent predicts)."""
        return dict(self.swarm.latest_estimate)

    def neighbour_batch(self, k: int, received: Mapping[int, wire.Estimate]) -> EstimateBatch:
        return estimates_from_wire(self.index_of, len(self.index_of), received)

    def after_step(self, k: int, t: float) -> None:
        """A follower's estimate ẑ₁ (valid a period ahead) against its vehicle's ODOMETRY
        predicted as far (offboard.daemon.nav_check): once diverged, the runner-loss hold
        and landing on odometry from the next step on, for good."""
        if self.nav is None or not isinstance(self.agent, FollowerAgent) or not self.nav.due(k):
            return
        got = vehicle_state(self.vehicle, 1.0 / self.control_hz)
        if got is not None and self.nav.update(k, self.agent.deso.z1, got[0]):
            self.loss.navigation_fault(t)
            self.keeper.fault(time.monotonic())
            t_land = self.loss.t_land
            log.error("agent %d: estimate off its odometry by more than %g m at t=%.2f s: "
                      "holding on odometry; %s", self.id, self.nav.gate_m, t,
                      "no landing (--loss-land-after 0)" if t_land is None
                      else f"landing at t={t_land:.2f} s")

    def fallback_step(self, k: int, t: float, time_boot_ms: int, stream: SetpointStream) -> bool:
        """Runner or router lost: the setpoint of offboard.daemon.runner_loss's LossFlight
        from the vehicle's own ODOMETRY (brake and hold, then the landing)."""
        if not self.loss.lost:
            return False
        got = vehicle_state(self.vehicle, 0.0)
        sp = None if got is None else self.loss_flight.setpoint(t, *got)
        if got is None or sp is None:
            return False
        stream.set_answer((time_boot_ms, sp.q_ned, sp.thrust_norm), k, from_loss=True)
        # the lost runner is a standing fault: a failsafe HOLD on the way down (a stalled
        # host) is taken back to OFFBOARD even when the vehicle's STATUSTEXT was missed
        self.keeper.fault(stream.answer_at)
        stream.send()
        if self.loss_flight.disarm_due(t, float(got[0][2]), self.vehicle.armed):
            self.modes.disarm()
        return True

    def summary(self) -> str:
        return ("" if self.nav is None
                else f"; estimate at most {self.nav.worst_m:.3f} m from odometry (after grace)")
