"""What the daemon's loop keeps sending: the setpoint stream to its vehicle and the
re-sends of its estimates to the swarm.

The setpoint stream (docs/security.md, "Offboard daemon: link hygiene and failsafes"): a
setpoint goes out only while it is fresh, by the rule of the loop's driver
(:mod:`offboard.daemon.drivers`: while it answers the vehicle's current step in lockstep,
for one control period in real time); when the vehicle's clock has moved on without a new
one, the stream stops and says so, and the vehicle's offboard-loss failsafe acts.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper
from offboard.daemon.ports import SwarmPort, VehiclePort
from offboard.daemon.runner_loss import RunnerLoss
from swarm_common import wire

log = logging.getLogger("offboard.daemon.core")  # the daemon's lines keep one logger name

# s: re-publish the last two estimates after this long without a new one (late joiners,
# lost datagrams), then after twice as long, up to REPUBLISH_MAX_S: a slow lockstep run
# (64 agents packed: 75-280 ms a step) otherwise republished every 0.1 s of every step and
# each peer decoded and guarded three times the estimates it needed. The cap stays well
# below the neighbour timeout (0.45 s), so a waiting peer still hears twice in it.
REPUBLISH_S = 0.1
REPUBLISH_MAX_S = 0.2
STREAM_GAP_S = 0.1  # s: the vehicle's clock moved on this long without a new setpoint: stopped

# (time_boot_ms, q_ned float32 (4,), normalised thrust float32)
Answer = tuple[int, np.ndarray, np.float32]


class SetpointStream:
    """The current answer (setpoint) to the vehicle and the stream of its sends."""

    def __init__(
        self, agent_id: int, vehicle: VehiclePort, keeper: OffboardKeeper, loss: RunnerLoss,
        fresh: Callable[[SetpointStream, float], bool],
    ) -> None:
        """``fresh(stream, now)``: the driver's rule, whether the answer still answers the
        vehicle (asked only of an answer that is not overruled by a lost runner)."""
        self.id = agent_id
        self.vehicle = vehicle
        self.keeper = keeper
        self.loss = loss
        self.fresh = fresh
        self.answer: Answer | None = None
        self.answer_from_loss = False  # the answer is runner_loss's (valid while lost)
        self.answer_step = -1  # the vehicle step the answer is for
        self.answer_at = 0.0  # monotonic time it was computed
        self.vehicle_step = -1  # step of the vehicle's latest accepted ODOMETRY
        self.last_send = 0.0
        self.stream_since = 0.0  # start of the current gap-free setpoint stream
        self.streaming = False

    @property
    def truth_lost(self) -> bool:
        """Real time: the runner or router is lost (offboard.daemon.runner_loss)."""
        return self.loss.lost

    def set_answer(self, answer: Answer, step: int, from_loss: bool) -> None:
        """The new answer, for the vehicle's ``step``, computed now."""
        self.answer, self.answer_from_loss = answer, from_loss
        self.answer_step, self.answer_at = step, time.monotonic()

    def answer_fresh(self, now: float) -> bool:
        """A setpoint may go out while the driver's rule says it answers the vehicle, and
        while the runner is lost only if it is the loss flight's."""
        if self.answer is None or (self.truth_lost and not self.answer_from_loss):
            return False
        return self.fresh(self, now)

    def send(self) -> None:
        """Send the answer to the vehicle if it is fresh."""
        now = time.monotonic()
        if self.answer is None or not self.answer_fresh(now):
            return
        ms, q, thrust = self.answer
        self.vehicle.send_attitude_target(ms, q, thrust)
        if not self.streaming:
            self.streaming, self.stream_since = True, now
        self.last_send = now

    def streaming_s(self, now: float) -> float:
        """How long the current gap-free stream has lasted (0 when not streaming)."""
        return now - self.stream_since if self.streaming else 0.0

    def gap(self, now: float) -> None:
        """The stream had a gap (a stalled loop): the vehicle must see it again first."""
        self.keeper.fault(now)
        self.streaming = False

    def check(self, now: float) -> None:
        """Say so when the vehicle's clock has moved on for 0.1 s without a new setpoint
        (the stale one is no longer sent): the vehicle's failsafe acts."""
        behind = self.vehicle_step > self.answer_step or (
            self.truth_lost and not self.answer_from_loss)
        if self.streaming and behind and now - self.last_send > STREAM_GAP_S:
            self.streaming = False
            self.keeper.fault(now)
            log.warning("agent %d: no valid step since step %d (vehicle at step %d): "
                        "setpoint stream stopped, the vehicle's failsafe will act",
                        self.id, self.answer_step, self.vehicle_step)


class EstimateOutbox:
    """Our published estimates: the last two, re-sent when none came for a while."""

    def __init__(self, swarm: SwarmPort) -> None:
        self.swarm = swarm
        self.last: wire.Estimate | None = None
        self.prev: wire.Estimate | None = None
        self.last_pub = 0.0
        self.republish_after = REPUBLISH_S  # s without a new estimate before re-sending

    def publish(self, est: wire.Estimate) -> None:
        if self.last is not None and self.last.step != est.step:
            self.prev = self.last
        self.last = est
        self.last_pub = time.monotonic()
        self.republish_after = REPUBLISH_S
        self.swarm.publish_estimate(est)

    def republish_due(self, now: float) -> bool:
        return self.last is not None and now - self.last_pub > self.republish_after

    def republish(self) -> None:
        """Re-send the last two estimates: a neighbour still at step k needs ours of k-1
        (the next re-send backs off, :data:`REPUBLISH_MAX_S`)."""
        for est in (self.prev, self.last):
            if est is not None:
                self.swarm.publish_estimate(est)
        self.last_pub = time.monotonic()
        self.republish_after = min(2.0 * self.republish_after, REPUBLISH_MAX_S)
