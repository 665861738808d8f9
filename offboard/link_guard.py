"""Pure guards of the offboard daemon's links (no sockets, no clocks of their own).

* :class:`DropLog` counts what a receiver drops, by reason, and logs it rate-limited;
* :class:`StampGuard` accepts the vehicle's ODOMETRY stamps only when they move forward
  by a plausible amount (docs/security.md, "Offboard daemon: link hygiene and failsafes");
* :func:`odometry_fields_ok` checks an ODOMETRY's numbers;
* :class:`PayloadGuard` checks every Zenoh payload against the scenario and the
  daemon's own step;
* :class:`CommandRetry` is the non-blocking COMMAND_LONG -> COMMAND_ACK retry state
  machine (the policy of the ground station's retry generator, redone sans-I/O so that
  the daemon's loop keeps streaming setpoints while a command waits);
* :class:`Backoff` is a re-request schedule, :class:`OffboardKeeper` the start-up and
  failsafe-recovery policy of the vehicle's mode.

Every time argument is in seconds of the caller's monotonic clock.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from swarm_common import wire

log = logging.getLogger(__name__)

MAX_JUMP_PERIODS = 5  # an ODOMETRY stamp may skip this many control periods at once
REALTIME_AHEAD_S = 0.5  # real time: a stamp may lead the wall-clock prediction this much
REANCHOR_COUNT = 3  # consecutive, mutually consistent too-far stamps that re-anchor
MAX_FIRST_STAMP_S = 1.0e7  # s (~115 days): a first stamp beyond this is implausible
MAX_ABS_POSITION_M = 1.0e5  # m: |ODOMETRY position| beyond this is not a vehicle here
MAX_ABS_SPEED_MS = 1.0e3  # m/s
QUAT_NORM_TOL = 0.1
STEP_BEHIND = 64  # Zenoh payloads may lag the daemon's own step by this many steps
STEP_AHEAD = 50  # ... and lead it by this many (one second at 50 Hz)
MAX_STEP_BEFORE_FIRST = 1 << 31  # before the first ODOMETRY: any sane step
MAX_OUTAGE_S = 3600.0  # an injected outage longer than an hour is not a test
LOG_EVERY_S = 5.0  # DropLog: at most one line per reason per this many seconds


@dataclass
class DropLog:
    """Counts of dropped input by reason; logs the first drop of a reason at once and
    then at most one summary line per ``every_s`` (WARNING)."""

    what: str
    every_s: float = LOG_EVERY_S
    counts: dict[str, int] = field(default_factory=dict)
    _last_log: dict[str, float] = field(default_factory=dict)
    _since_log: dict[str, int] = field(default_factory=dict)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def drop(self, reason: str, detail: str, now: float) -> None:
        self.counts[reason] = self.counts.get(reason, 0) + 1
        self._since_log[reason] = self._since_log.get(reason, 0) + 1
        last = self._last_log.get(reason)
        if last is None or now - last >= self.every_s:
            n = self._since_log.pop(reason)
            log.warning("%s: dropped %d (%s, %d in all): %s",
                        self.what, n, reason, self.counts[reason], detail)
            self._last_log[reason] = now


def _finite(values: Iterable[float]) -> bool:
    return all(math.isfinite(float(x)) for x in values)


def odometry_fields_ok(
    pos: Iterable[float], q: Iterable[float], vel: Iterable[float]
) -> str | None:
    """None when the position (m), quaternion and velocity (m/s) are usable; else why."""
    p, qq, v = list(pos), list(q), list(vel)
    if not (_finite(p) and _finite(qq) and _finite(v)):
        return "non-finite field"
    if max(abs(float(x)) for x in p) > MAX_ABS_POSITION_M:
        return "position out of range"
    if max(abs(float(x)) for x in v) > MAX_ABS_SPEED_MS:
        return "velocity out of range"
    if abs(math.sqrt(sum(float(x) ** 2 for x in qq)) - 1.0) > QUAT_NORM_TOL:
        return "quaternion not unit"
    return None


class StampGuard:
    """Accepts an ODOMETRY stamp (µs) when it is later than the last accepted one by at
    most ``MAX_JUMP_PERIODS`` control periods (lockstep: the simulator waits for the
    daemon, so its clock cannot run away); in real time when it leads the wall clock by
    at most ``REALTIME_AHEAD_S`` more than any accepted stamp did (the vehicle's clock
    runs at wall-clock rate; delays only make stamps lag, so the largest lead seen is
    its offset). An equal stamp is a duplicate, an earlier one non-monotonic.
    ``REANCHOR_COUNT`` consecutive too-far stamps that follow each other within the jump
    bound re-anchor the clock (a restart or a long stall of the simulator; one forged
    datagram never does)."""

    def __init__(self, control_hz: float, lockstep: bool) -> None:
        self.dt_us = 1e6 / float(control_hz)
        self.lockstep = lockstep
        self.last_us: int | None = None
        self.last_at = 0.0
        self.lead_s = -math.inf  # real time: the largest (stamp - wall clock) accepted
        self._candidates: list[int] = []
        self.reanchors = 0

    def _plausible(self, stamp_us: int, now: float) -> bool:
        if self.lockstep:
            return stamp_us - (self.last_us or 0) <= MAX_JUMP_PERIODS * self.dt_us
        lead = stamp_us * 1e-6 - now
        return lead <= self.lead_s + MAX_JUMP_PERIODS * self.dt_us * 1e-6 + REALTIME_AHEAD_S

    def check(self, stamp_us: int, now: float) -> str | None:
        """None (accepted, becomes the last stamp) or the reason it is dropped."""
        if stamp_us < 0:
            return "negative stamp"
        if self.last_us is None:
            if stamp_us > MAX_FIRST_STAMP_S * 1e6:
                return "first stamp implausible"
            self._accept(stamp_us, now)
            return None
        if stamp_us == self.last_us:
            return "duplicate stamp"
        if stamp_us < self.last_us:
            return "non-monotonic stamp"
        if self._plausible(stamp_us, now):
            self._accept(stamp_us, now)
            return None
        return self._candidate(stamp_us, now)

    def _candidate(self, stamp_us: int, now: float) -> str | None:
        cands = self._candidates
        if cands and not 0 < stamp_us - cands[-1] <= MAX_JUMP_PERIODS * self.dt_us:
            cands.clear()
        cands.append(stamp_us)
        if len(cands) >= REANCHOR_COUNT:
            log.warning("vehicle clock re-anchored: %.3f s -> %.3f s",
                        (self.last_us or 0) * 1e-6, stamp_us * 1e-6)
            self.reanchors += 1
            self._accept(stamp_us, now)
            return None
        return "implausible stamp jump"

    def _accept(self, stamp_us: int, now: float) -> None:
        self.last_us = stamp_us
        self.last_at = now
        self.lead_s = max(self.lead_s, stamp_us * 1e-6 - now)
        self._candidates.clear()


class PayloadGuard:
    """Receiver-side validation of Zenoh payloads for one daemon: ids of the scenario,
    steps within [ref - STEP_BEHIND, ref + STEP_AHEAD] of the daemon's own step ``ref``
    (the vehicle's latest ODOMETRY step; before the first one only a sane range), time
    consistent with the step, finite numbers. :meth:`check` returns None or why."""

    def __init__(
        self, ids: list[int], leader_ids: list[int], control_hz: float, own_id: int
    ) -> None:
        self.ids = list(ids)
        self.leaders = set(leader_ids)
        self.dt = 1.0 / float(control_hz)
        self.own_id = own_id
        self.ref: int | None = None

    def step_ok(self, step: int) -> bool:
        if self.ref is None:
            return -1 <= step <= MAX_STEP_BEFORE_FIRST
        return self.ref - STEP_BEHIND <= step <= self.ref + STEP_AHEAD

    def _time_ok(self, step: int, t: float, offset_steps: int) -> bool:
        """``t`` finite and within two periods of ``(step + offset_steps) * dt``."""
        return math.isfinite(t) and abs(t - (step + offset_steps) * self.dt) <= 2 * self.dt

    def check(self, msg: wire.Payload) -> str | None:
        if isinstance(msg, wire.Truth):
            return self._truth(msg)
        if isinstance(msg, wire.Estimate):
            return self._estimate(msg)
        if isinstance(msg, wire.Status):
            return self._status(msg)
        if isinstance(msg, wire.Odometry):
            return self._odometry(msg)
        return self._command(msg)

    def _truth(self, m: wire.Truth) -> str | None:
        if m.ids != self.ids:
            return "truth ids are not the scenario's"
        if not self.step_ok(m.step) or m.step < 0:
            return f"truth step {m.step} implausible (own step {self.ref})"
        if not self._time_ok(m.step, m.t, 0):
            return f"truth t {m.t!r} does not match step {m.step}"
        arrays = (m.p, m.v, m.att, m.thrust, m.lumped)
        if not all(np.all(np.isfinite(a)) for a in arrays) or math.isnan(m.min_dist):
            return "truth has non-finite values"
        if len(m.armed) != len(self.ids) or len(m.mode) != len(self.ids) or m.collisions < 0:
            return "truth fields inconsistent"
        return None

    def _estimate(self, m: wire.Estimate) -> str | None:
        if m.id not in self.ids:
            return f"estimate id {m.id} not in the scenario"
        if m.step != -1 and not self.step_ok(m.step):  # -1: the initial estimate, any time
            return f"estimate step {m.step} implausible (own step {self.ref})"
        # the estimate of step k is valid at t_k+1 (the initial one, step -1, at t_0)
        if not self._time_ok(m.step, m.t, 1):
            return f"estimate t {m.t!r} does not match step {m.step}"
        if (m.role == "leader") != (m.id in self.leaders):
            return f"estimate role {m.role!r} is not agent {m.id}'s"
        vecs = (m.z1, m.z2, m.z3, m.xi, m.zeta)
        if not all(np.all(np.isfinite(a)) for a in vecs):
            return "estimate has non-finite values"
        return None

    def _status(self, m: wire.Status) -> str | None:
        if m.id not in self.ids:
            return f"status id {m.id} not in the scenario"
        if not self.step_ok(m.step) or not self._time_ok(m.step, m.t, 0):
            return f"status step {m.step} / t {m.t!r} implausible"
        return None

    def _odometry(self, m: wire.Odometry) -> str | None:
        if m.id not in self.ids:
            return f"odometry id {m.id} not in the scenario"
        if m.step < 0 or not self.step_ok(m.step) or not self._time_ok(m.step, m.t, 0):
            return f"odometry step {m.step} / t {m.t!r} implausible"
        if not (np.all(np.isfinite(m.p)) and np.all(np.isfinite(m.v))):
            return "odometry has non-finite values"
        return None

    def _command(self, m: wire.Command) -> str | None:
        if m.agent != 0 and m.agent not in self.ids:
            return f"command for agent {m.agent} not in the scenario"
        if not (math.isfinite(m.duration_s) and 0.0 <= m.duration_s <= MAX_OUTAGE_S):
            return f"command duration {m.duration_s!r} out of range"
        if not math.isfinite(m.at_s):
            return f"command at_s {m.at_s!r} not finite"
        return None


@dataclass
class CommandRetry:
    """One COMMAND_LONG in flight, retried without blocking: :meth:`due` says when to
    (re)send (``attempt`` is then the COMMAND_LONG ``confirmation``), :meth:`on_ack`
    takes the COMMAND_ACK's MAV_RESULT, :meth:`expired` says every attempt went
    unanswered. MAV_RESULT_IN_PROGRESS restarts the wait of the current attempt."""

    command: int
    params: list[float]
    attempts: int = 3
    timeout_s: float = 1.0
    attempt: int = -1
    sent_at: float = -math.inf
    result: int | None = None
    done: bool = False

    def due(self, now: float) -> bool:
        """True when the next attempt should go out now (the caller sends it)."""
        if self.done or now - self.sent_at < self.timeout_s:
            return False
        if self.attempt + 1 >= self.attempts:
            self.done = True  # expired: no ACK for any attempt
            return False
        self.attempt += 1
        self.sent_at = now
        return True

    def on_ack(self, result: int, now: float, in_progress: int) -> None:
        if self.done:
            return
        if result == in_progress:
            self.sent_at = now
            return
        self.result = int(result)
        self.done = True

    @property
    def expired(self) -> bool:
        return self.done and self.result is None


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


@dataclass
class VehicleView:
    """What :class:`OffboardKeeper` needs to know each loop (times: monotonic s)."""

    in_offboard: bool
    hold: bool  # AUTO.LOITER, PX4's hold and its offboard-loss failsafe mode
    armed: bool
    failsafe_texts: int  # STATUSTEXTs from the vehicle that say "failsafe", so far
    streaming_s: float  # how long fresh setpoints have streamed without a gap
    critical: bool = False  # its HEARTBEAT says MAV_STATE_CRITICAL (a failsafe is active)


class OffboardKeeper:
    """Start-up (OFFBOARD, then arm) and OFFBOARD recovery after a failsafe.

    Recovery policy (docs/security.md): once the mission has had the vehicle in OFFBOARD,
    leaving it is a *failsafe* when the vehicle is armed and in HOLD and either it said
    "failsafe" (STATUSTEXT) since it was last in OFFBOARD, or the daemon itself had a fault
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
        if not (self.seen_offboard or (self.offboard_acked and v.hold)):
            return None  # not in OFFBOARD yet (the heartbeat lags the accepted request)
        if self.left_at is None:
            self.left_at = now
        if not (v.hold and v.armed):
            if self.recovering or not self.respect:
                log.warning("vehicle out of OFFBOARD and not in HOLD: left to its operator")
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
                log.warning("vehicle put in HOLD by a third party: respected")
        if self.recovering and v.streaming_s >= self.stream_s and self.backoff.ready(now):
            return "offboard"
        return None

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
