"""The OFFBOARD keeper: the daemon's start-up and failsafe-recovery policy for its
vehicle's mode (docs/security.md, "Commands never block; OFFBOARD after a failsafe"), and
the :class:`Backoff` re-request schedule it uses. Pure: no sockets, no clock of its own
(every time argument is in seconds of the caller's monotonic clock).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

log = logging.getLogger(__name__)


@dataclass
class Backoff:
    """Exponential re-request schedule: first try at once, then ``first_s``, doubling up
    to ``max_s``; :meth:`reset` after success."""

    first_s: float = 0.5
    max_s: float = 4.0
    next_at: float = 0.0
    delay: float = 0.0
    tries: int = 0

    def ready(self, now: float) -> bool:
        return now >= self.next_at

    def failed(self, now: float) -> None:
        self.tries += 1
        self.delay = self.first_s if self.delay == 0.0 else min(self.max_s, 2 * self.delay)
        self.next_at = now + self.delay

    def reset(self) -> None:
        self.next_at = 0.0
        self.delay = 0.0
        self.tries = 0


FAULT_WINDOW_S = 1.5  # s: an own fault this long before leaving OFFBOARD explains it
# what the keeper logs when it leaves the vehicle out of OFFBOARD for good (a run's logs are
# read for them: tests/integration/mission/test_faults_realtime.py)
LEFT_TO_OPERATOR = "vehicle out of OFFBOARD and not in HOLD: left to its operator"
HOLD_RESPECTED = "vehicle put in HOLD by a third party: respected"


@dataclass
class VehicleView:
    """What :class:`OffboardKeeper` needs to know each loop (times: monotonic s)."""

    in_offboard: bool
    hold: bool  # AUTO.LOITER, PX4's hold and its offboard-loss failsafe mode
    armed: bool
    failsafe_texts: int  # STATUSTEXTs from the vehicle that say "failsafe", so far
    streaming_s: float  # how long fresh setpoints have streamed without a gap
    critical: bool = False  # its HEARTBEAT says MAV_STATE_CRITICAL (a failsafe is active)
    reported_offboard: bool = False  # a HEARTBEAT since the daemon's start said OFFBOARD
    offboard_lost_texts: int = 0  # STATUSTEXTs so far that say "failsafe" and "offboard"


class OffboardKeeper:
    """Start-up (OFFBOARD, then arm) and OFFBOARD recovery after a failsafe.

    Recovery policy (docs/security.md): once the mission has had the vehicle in OFFBOARD,
    leaving it is a *failsafe* when the vehicle is armed and in HOLD and either it said
    so ("failsafe" in a STATUSTEXT since it was last in OFFBOARD, or MAV_STATE_CRITICAL in
    its HEARTBEAT, which survives a lost STATUSTEXT), or the daemon itself had a fault
    (:meth:`fault`: a stalled loop, a stopped stream, lost truth) within FAULT_WINDOW_S
    before it left. Then, as soon as setpoints have streamed for ``stream_s`` again,
    OFFBOARD is asked for with exponential backoff (0.5 s doubling to 4 s). Anything else
    (a third party's LAND, HOLD or other mode without such evidence, or any mode other
    than HOLD later on) is respected until the vehicle is back in OFFBOARD."""

    def __init__(self, stream_s: float, manual_start: bool) -> None:
        self.stream_s = stream_s
        self.manual_start = manual_start
        self.startup_done = manual_start
        self.offboard_acked = False
        self.arm_acked = False
        self.seen_offboard = False
        self.left_at: float | None = None
        self.fault_at = -math.inf
        self.texts_ref = 0
        self.recovering = False
        self.respect = False  # a third party's mode change: do not take the vehicle back
        self.recoveries = 0
        self.backoff = Backoff()
        self.startup_backoff = Backoff(first_s=0.2, max_s=1.0)

    def fault(self, now: float) -> None:
        self.fault_at = now

    def decide(self, now: float, v: VehicleView) -> str | None:
        """"offboard", "arm" or None: what to ask the vehicle for now."""
        if not self.startup_done:
            want = self._startup(now, v)
            if not self.startup_done:
                return want
        if v.in_offboard:
            if self.recovering:
                self.recoveries += 1
                log.info("vehicle back in OFFBOARD after a failsafe (%d so far)", self.recoveries)
            self.seen_offboard, self.left_at = True, None
            self.recovering = self.respect = False
            self.texts_ref = v.failsafe_texts
            self.backoff.reset()
            return None
        if not self._was_offboard(v):
            return None  # not in OFFBOARD yet (the heartbeat lags the accepted request)
        if self.left_at is None:
            self.left_at = now
        if not (v.hold and v.armed):
            if self.recovering or not self.respect:
                log.warning(LEFT_TO_OPERATOR)
            self.recovering, self.respect = False, True
            return None
        if not self.recovering and not self.respect:
            # a lost STATUSTEXT (a lossy link) must not hide a failsafe: the HEARTBEAT,
            # repeated every second, says CRITICAL while the failsafe action is active
            evidence = (v.failsafe_texts > self.texts_ref or v.critical
                        or self.fault_at >= self.left_at - FAULT_WINDOW_S)
            if evidence:
                self.recovering = True
                log.warning("vehicle in failsafe HOLD: OFFBOARD will be asked for again")
            elif now - self.left_at > FAULT_WINDOW_S:
                self.respect = True
                log.warning(HOLD_RESPECTED)
        if self.recovering and v.streaming_s >= self.stream_s and self.backoff.ready(now):
            return "offboard"
        return None

    def _was_offboard(self, v: VehicleView) -> bool:
        """Whether the vehicle has been in OFFBOARD in this mission: this keeper saw it,
        or a HEARTBEAT said so (also one the loop never sampled), or the vehicle said it
        lost offboard (a failsafe can come before any HEARTBEAT showed OFFBOARD: a ground
        station's OFFBOARD, then this daemon stopped for longer than the failsafe's
        timeout), or OFFBOARD was accepted and the vehicle is now in HOLD."""
        return (self.seen_offboard or v.reported_offboard or v.offboard_lost_texts > 0
                or (self.offboard_acked and v.hold))

    def _startup(self, now: float, v: VehicleView) -> str | None:
        if v.in_offboard:  # a failsafe HOLD from here on is recovered (decide)
            self.seen_offboard, self.texts_ref = True, v.failsafe_texts
        if v.streaming_s < self.stream_s or not self.startup_backoff.ready(now):
            return None
        if not (v.in_offboard or self.offboard_acked):
            return "offboard"
        if not (v.armed or self.arm_acked):
            return "arm"
        self.startup_done = True  # a failsafe HOLD before the heartbeat showed OFFBOARD:
        return None  # decide() recovers it (offboard_acked and hold)

    def result(self, what: str, accepted: bool, now: float) -> None:
        """The outcome of an "offboard" / "arm" request (None result counts as refused)."""
        if not self.startup_done:
            if accepted:
                self.offboard_acked = self.offboard_acked or what == "offboard"
                self.arm_acked = self.arm_acked or what == "arm"
                self.startup_backoff.reset()
            else:
                self.startup_backoff.failed(now)
            return
        if accepted:
            self.backoff.reset()
            self.backoff.next_at = now + self.backoff.first_s  # let the heartbeat show it
        else:
            self.backoff.failed(now)
