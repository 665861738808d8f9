"""The setpoint stream of the offboard daemon (docs/security.md, "Offboard daemon: link
hygiene and failsafes"): a setpoint goes out only while it answers the vehicle's current
step (lockstep) or for one control period (real time); when the vehicle's clock has moved
on without a new one, the stream stops and says so, and the vehicle's offboard-loss
failsafe acts. A mixin of :class:`offboard.daemon.core.OffboardDaemon` (the attributes below
are the daemon's)."""

from __future__ import annotations

import logging
import time

import numpy as np

from offboard.daemon.config import DaemonConfig
from offboard.daemon.mavlink.link import VehicleLink
from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper
from offboard.daemon.runner_loss import RunnerLoss

log = logging.getLogger("offboard.daemon.core")


class SetpointStream:
    """Answer freshness and the setpoint stream of one daemon."""

    id: int
    cfg: DaemonConfig
    link: VehicleLink
    keeper: OffboardKeeper
    control_hz: int
    answer: tuple[int, np.ndarray, np.float32] | None
    answer_from_loss: bool
    answer_step: int
    answer_at: float
    vehicle_step: int
    last_send: float
    stream_since: float
    streaming: bool

    loss: RunnerLoss

    @property
    def truth_lost(self) -> bool:
        """Real time: the runner or router is lost (offboard.daemon.runner_loss)."""
        return self.loss.lost

    def _answer_fresh(self, now: float) -> bool:
        """A setpoint may go out while it answers the vehicle's current step (lockstep:
        the vehicle's clock waits for it) or for one control period (real time)."""
        if self.answer is None or (self.truth_lost and not self.answer_from_loss):
            return False
        if self.cfg.lockstep:
            return self.vehicle_step <= self.answer_step
        return now - self.answer_at <= 1.0 / self.control_hz

    def _send_answer(self) -> None:
        now = time.monotonic()
        if self.answer is None or not self._answer_fresh(now):
            return
        ms, q, thrust = self.answer
        self.link.send_attitude_target(ms, q, thrust)
        if not self.streaming:
            self.streaming, self.stream_since = True, now
        self.last_send = now

    def _check_stream(self, now: float) -> None:
        """Say so when the vehicle's clock has moved on for 0.1 s without a new setpoint
        (the stale one is no longer sent): the vehicle's failsafe acts."""
        behind = self.vehicle_step > self.answer_step or (
            self.truth_lost and not self.answer_from_loss)
        if self.streaming and behind and now - self.last_send > 0.1:
            self.streaming = False
            self.keeper.fault(now)
            log.warning("agent %d: no valid step since step %d (vehicle at step %d): "
                        "setpoint stream stopped, the vehicle's failsafe will act",
                        self.id, self.answer_step, self.vehicle_step)
