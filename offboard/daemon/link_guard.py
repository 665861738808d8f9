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
* :class:`~offboard.daemon.mavlink.offboard_keeper.Backoff` and
:class:`~offboard.daemon.mavlink.offboard_keeper.
  OffboardKeeper` (the start-up and failsafe-recovery policy of the vehicle's mode) live
  in :mod:`offboard.daemon.mavlink.offboard_keeper` .

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


def odometry_fields_ok(
    pos: Iterable[float], q: Iterable[float], vel: Iterable[float]
) -> str | None:
    """None when the position (m), quaternion and velocity (m/s) are usable; else why."""
    p, qq, v = [float(x) for x in pos], [float(x) for x in q], [float(x) for x in vel]
    if not all(map(math.isfinite, p + qq + v)):
        return "non-finite field"
    if max(map(abs, p)) > MAX_ABS_POSITION_M:
        return "position out of range"
    if max(map(abs, v)) > MAX_ABS_SPEED_MS:
        return "velocity out of range"
    if abs(math.sqrt(sum([x * x for x in qq])) - 1.0) > QUAT_NORM_TOL:
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


def all_finite(arrays: tuple[np.ndarray, ...]) -> bool:
    """True when every element of ``arrays`` is finite, with one reduction per array
    instead of an ``isfinite`` + ``all`` pair: NaN and ±inf propagate through a sum. A sum
    of finite elements overflows only beyond 1e307 per element, far outside anything the
    float32 wire carries (3.4e38 at most); such a payload would be refused, never
    accepted."""
    total = 0.0
    for a in arrays:
        total += float(a.sum())
    return math.isfinite(total)


def payload_finite(msg: wire.Payload) -> bool:
    """Every float array of ``msg`` finite (truth, estimate, odometry; True for the rest).
    A property of the payload alone: a packed process computes it once per payload
    (``offboard.daemon.zenoh.link.DecodeCache``), not once per daemon."""
    if isinstance(msg, wire.Estimate):
        if msg.block is not None:  # decoded: every vector is a view of this block
            return all_finite((msg.block,))
        return all_finite((msg.z1, msg.z2, msg.z3, msg.xi, msg.zeta))
    if isinstance(msg, wire.Truth):
        return all_finite((msg.p, msg.v, msg.att, msg.thrust, msg.lumped))
    if isinstance(msg, wire.Odometry):
        return all_finite((msg.p, msg.v))
    return True


class PayloadGuard:
    """Receiver-side validation of Zenoh payloads for one daemon: ids of the scenario,
    steps within [ref - STEP_BEHIND, ref + STEP_AHEAD] of the daemon's own step ``ref``
    (the vehicle's latest ODOMETRY step; before the first one only a sane range), time
    consistent with the step, finite numbers. :meth:`check` returns None or why."""

    def __init__(
        self, ids: list[int], leader_ids: list[int], control_hz: float, own_id: int
    ) -> None:
        self.ids = list(ids)
        self.id_set = frozenset(self.ids)  # membership per payload without a list scan
        self.leaders = set(leader_ids)
        self.dt = 1.0 / float(control_hz)
        self.own_id = own_id
        self.ref: int | None = None

    def step_ok(self, step: int) -> bool:
        if self.ref is None:
            return -1 <= step <= MAX_STEP_BEFORE_FIRST
        return self.ref - STEP_BEHIND <= step <= self.ref + STEP_AHEAD

    def window(self) -> tuple[int, int]:
        """The steps :meth:`step_ok` accepts, as (lowest, highest)."""
        if self.ref is None:
            return -1, MAX_STEP_BEFORE_FIRST
        return self.ref - STEP_BEHIND, self.ref + STEP_AHEAD

    def _time_ok(self, step: int, t: float, offset_steps: int) -> bool:
        """``t`` finite and within two periods of ``(step + offset_steps) * dt``."""
        return math.isfinite(t) and abs(t - (step + offset_steps) * self.dt) <= 2 * self.dt

    def check(self, msg: wire.Payload, finite: bool | None = None) -> str | None:
        """None if ``msg`` is acceptable now, else why not. ``finite``: the payload's
        :func:`payload_finite`, when the caller already knows it."""
        if finite is None:
            finite = payload_finite(msg)
        if isinstance(msg, wire.Truth):
            return self._truth(msg, finite)
        if isinstance(msg, wire.Estimate):
            return self._estimate(msg, finite)
        if isinstance(msg, wire.Status):
            return self._status(msg)
        if isinstance(msg, wire.Odometry):
            return self._odometry(msg, finite)
        return self._command(msg)

    def _truth(self, m: wire.Truth, finite: bool) -> str | None:
        if m.ids != self.ids:
            return "truth ids are not the scenario's"
        if not self.step_ok(m.step) or m.step < 0:
            return f"truth step {m.step} implausible (own step {self.ref})"
        if not self._time_ok(m.step, m.t, 0):
            return f"truth t {m.t!r} does not match step {m.step}"
        if not finite or math.isnan(m.min_dist):
            return "truth has non-finite values"
        if len(m.armed) != len(self.ids) or len(m.mode) != len(self.ids) or m.collisions < 0:
            return "truth fields inconsistent"
        return None

    def _estimate(self, m: wire.Estimate, finite: bool) -> str | None:
        if m.id not in self.id_set:
            return f"estimate id {m.id} not in the scenario"
        if m.step != -1 and not self.step_ok(m.step):  # -1: the initial estimate, any time
            return f"estimate step {m.step} implausible (own step {self.ref})"
        # the estimate of step k is valid at t_k+1 (the initial one, step -1, at t_0)
        if not self._time_ok(m.step, m.t, 1):
            return f"estimate t {m.t!r} does not match step {m.step}"
        if (m.role == "leader") != (m.id in self.leaders):
            return f"estimate role {m.role!r} is not agent {m.id}'s"
        if not finite:
            return "estimate has non-finite values"
        return None

    def _status(self, m: wire.Status) -> str | None:
        if m.id not in self.id_set:
            return f"status id {m.id} not in the scenario"
        if not self.step_ok(m.step) or not self._time_ok(m.step, m.t, 0):
            return f"status step {m.step} / t {m.t!r} implausible"
        return None

    def _odometry(self, m: wire.Odometry, finite: bool) -> str | None:
        if m.id not in self.id_set:
            return f"odometry id {m.id} not in the scenario"
        if m.step < 0 or not self.step_ok(m.step) or not self._time_ok(m.step, m.t, 0):
            return f"odometry step {m.step} / t {m.t!r} implausible"
        if not finite:
            return "odometry has non-finite values"
        return None

    def _command(self, m: wire.Command) -> str | None:
        if m.agent != 0 and m.agent not in self.id_set:
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
