"""The offboard daemon's Zenoh side: truth, neighbours' estimates, commands in; own out.

Receives into Zenoh FIFO channels that the daemon's main thread drains (:meth:`pump`):

* ``Truth`` per control step (from ``vehicle-sim``), kept by step;
* its peers' post-update ``Estimate`` (kept by sender and step): one subscriber per peer
  key (:mod:`offboard.agent.peers`), never a wildcard over the swarm;
* ground-station ``Command`` payloads (method switch, outage injection);
* with ``odometry=True`` (``--sensing odometry``), every other agent's ``Odometry`` (its
  vehicle's measured state at t_k), kept by step and latest per sender.

It publishes its agent's estimate, status and its own vehicle's odometry.

Draining from the main thread means no Python thread and no GIL hand-off per message:
with Python callbacks every put() stalled behind Zenoh's threads (1.9 ms median), and
with drain threads plus a condition variable the lockstep run was 1.39× against
1.55–1.69× polled (docs/performance.md). A payload that fails to decode, or that the
daemon's :class:`offboard.daemon.link_guard.PayloadGuard` refuses (id not in the scenario, step
outside a window around the daemon's own step, time not matching the step, non-finite
values), is counted by reason in ``drops`` and dropped (docs/security.md). Keys and
payloads come from :mod:`swarm_common.wire`. Several daemons packed in one process
(``offboard --agents``) share one session; a payload they all receive (the truth, a
common peer's estimate) is decoded once (:class:`DecodeCache`) and guarded by each.

Fault injection (docs/faults.md): with a ``[faults]`` plan for this agent's ``zenoh`` link,
the estimates and statuses it publishes go through a seeded
:class:`swarm_common.faults.FaultInjector` (drop, delay, duplicate, reorder) and every
sample it receives (truth, estimates, commands) may be discarded (``drop_in``); without
one nothing changes.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from offboard.daemon.link_guard import DropLog, PayloadGuard, payload_finite
from offboard.daemon.output_burst import OutputBurst
from offboard.daemon.zenoh.shared_subs import ZENOH_ERRORS, Handler, SharedSubscriptions
from offboard.daemon.zenoh.step_store import StepStore
from swarm_common import faults as fault_plan
from swarm_common import wire
from swarm_common.faults import FaultInjector

log = logging.getLogger(__name__)

KEEP_STEPS = 64
FIFO_DEPTH = 1024
POLL_S = 0.0002  # channel polling period while waiting for data
CACHE_ENTRIES = 256  # decoded payloads kept per process (a few steps of a packed swarm)


class DecodeCache:
    """Decoded payloads by their bytes, shared by the daemons of one process: a packed
    process receives the same truth and estimate bytes once per daemon. Decoded records
    hold read-only arrays, so sharing them is safe. Forgets everything when full."""

    def __init__(self, entries: int = CACHE_ENTRIES) -> None:
        self.entries = entries
        self._got: dict[bytes, tuple[wire.Payload, bool]] = {}

    def decode(self, data: bytes) -> wire.Payload:
        """``wire.decode(data)`` (raises ``wire.WireError`` like it), remembered."""
        return self.decode_checked(data)[0]

    def decode_checked(self, data: bytes) -> tuple[wire.Payload, bool]:
        """(payload, every float finite) of ``data``, both computed once per payload."""
        got = self._got.get(data)
        if got is None:
            msg = wire.decode(data)
            got = (msg, payload_finite(msg))
            if len(self._got) >= self.entries:
                self._got.clear()
            self._got[data] = got
        return got


PROCESS_CACHE = DecodeCache()


class SwarmBus:
    """Typed publish/subscribe of one agent over an open Zenoh session."""

    def __init__(
        self, session: Any, swarm: str, agent_id: int, guard: PayloadGuard | None = None,
        faults: FaultInjector | None = None, odometry: bool = False,
        peers: list[int] | None = None, cache: DecodeCache | None = None,
        ready: list[int] | None = None, shared: SharedSubscriptions | None = None,
    ) -> None:
        """``faults``: injected faults (docs/faults.md); None: the plan of the scenario this
        process loaded (:func:`swarm_common.faults.injector_for`). ``odometry``: subscribe
        to the other agents' odometry (``--sensing odometry``, which senses every agent).
        ``peers``: the agents whose estimates to receive (None: every agent, one wildcard
        subscriber). ``cache``: decoded payloads shared with the process's other daemons
        (default :data:`PROCESS_CACHE`). ``ready``: agents to hear from before flying
        (offboard.agent.peers.ready_ids); those not among ``peers`` are listened to only
        until :meth:`end_readiness` (a valid estimate marks them heard, nothing more).
        ``shared``: the subscriptions of the process's daemons (a packed process,
        :mod:`offboard.daemon.zenoh.shared_subs`); None: subscriptions of its own (a private
        :class:`~offboard.daemon.zenoh.shared_subs.SharedSubscriptions`, handing it alone its
        payloads)."""
        self.shared = shared
        self.subs = SharedSubscriptions(session, FIFO_DEPTH) if shared is None else shared
        self.cache = PROCESS_CACHE if cache is None else cache
        self.session = session
        self.faults = faults or fault_plan.injector_for(fault_plan.ZENOH, agent_id, "offboard")
        # a packed lockstep process's burst: puts held until the end of its pass
        self.burst: OutputBurst | None = None
        self.guard = guard
        self.drops = DropLog(f"agent {agent_id}: Zenoh")
        self.truth_time = 0.0  # monotonic time of the last accepted truth
        self.swarm = swarm
        self.agent_id = agent_id
        self.truth: StepStore[wire.Truth] = StepStore()
        self.latest_truth: wire.Truth | None = None
        self.estimates: StepStore[dict[int, wire.Estimate]] = StepStore()  # step -> id -> est
        self.latest_estimate: dict[int, wire.Estimate] = {}
        self.commands: deque[wire.Command] = deque()
        self.heard: set[int] = set()  # agents whose estimate was ever accepted (readiness)
        self.odometry: StepStore[dict[int, wire.Odometry]] = StepStore()  # step -> id -> odo
        self.latest_odometry: dict[int, wire.Odometry] = {}
        keys: list[tuple[str, Handler]] = [
            (wire.key_truth(swarm), self._on_truth),
            (wire.key_cmd(swarm, "*"), self._on_command),
        ]
        est_keys = ["*"] if peers is None else [str(j) for j in peers if j != agent_id]
        keys += [(wire.key_estimate(swarm, j), self._on_estimate) for j in est_keys]
        if odometry:
            keys.append((wire.key_odometry(swarm, "*"), self._on_odometry))
        # readiness only: undeclared by end_readiness
        self._ready_keys = [] if peers is None else [
            wire.key_estimate(swarm, j) for j in sorted(set(ready or ()) - set(peers) - {agent_id})]
        keys += [(key, self._on_announce) for key in self._ready_keys]
        for key, handler in keys:
            self.subs.add(key, self, handler)
        self._pub_est = session.declare_publisher(wire.key_estimate(swarm, agent_id))
        self._pub_status = session.declare_publisher(wire.key_status(swarm, agent_id))
        self._pub_odo = session.declare_publisher(wire.key_odometry(swarm, agent_id))
        # whether anyone subscribes to our odometry, kept by Zenoh's matching listener (a
        # matching_status query per step cost as much as the put it saves, more with 64
        # agents in the network)
        self._odo_listener = self._pub_odo.declare_matching_listener(self._on_odo_matching)
        self.odometry_matched = bool(self._pub_odo.matching_status.matching)

    # -- handlers (called from pump) ---------------------------------------------------
    @property
    def bad_payloads(self) -> int:
        return self.drops.total

    def _decode(self, data: bytes, key: Any, kind: type) -> Any:
        """The payload ``data`` (received on ``key``) if it decodes to ``kind`` and passes
        the guard; else None (counted)."""
        try:
            msg, finite = self.cache.decode_checked(data)
        except wire.WireError as exc:
            self.drops.drop("undecodable", str(exc), time.monotonic())
            return None
        if not isinstance(msg, kind):
            self.drops.drop("wrong kind", f"{type(msg).__name__} on {key}",
                            time.monotonic())
            return None
        why = None if self.guard is None else self.guard.check(msg, finite)
        if why is not None:
            self.drops.drop(type(msg).__name__.lower(), why, time.monotonic())
            return None
        return msg

    def set_reference(self, step: int) -> None:
        """The daemon's own step (the vehicle's latest ODOMETRY): payloads are judged
        against it from now on, and anything held beyond its window is forgotten."""
        if self.guard is None:
            return
        self.guard.ref = step
        lo, hi = self.guard.window()
        if self.latest_truth is not None and not lo <= self.latest_truth.step <= hi:
            self.latest_truth = None
        for latest in (self.latest_estimate, self.latest_odometry):
            for j in [j for j, m in latest.items() if not lo <= m.step <= hi]:
                del latest[j]
        self.truth.keep_within(lo, hi)
        self.estimates.keep_within(lo, hi)
        self.odometry.keep_within(lo, hi)

    def _on_truth(self, data: bytes, key: Any) -> None:
        msg = self._decode(data, key, wire.Truth)
        if msg is None:
            return
        self.truth[msg.step] = msg
        self.truth_time = time.monotonic()
        if self.latest_truth is None or msg.step >= self.latest_truth.step:
            self.latest_truth = msg
        if self.truth.lo < msg.step - KEEP_STEPS:  # (the common case costs no call)
            self.truth.keep_from(msg.step - KEEP_STEPS)

    def _on_estimate(self, data: bytes, key: Any) -> None:
        msg = self._decode(data, key, wire.Estimate)
        if msg is None or msg.id == self.agent_id:
            return
        self.heard.add(msg.id)
        _slot(self.estimates, msg.step)[msg.id] = msg
        prev = self.latest_estimate.get(msg.id)
        if prev is None or msg.step >= prev.step:
            self.latest_estimate[msg.id] = msg
        if self.estimates.lo < msg.step - KEEP_STEPS:  # (the common case costs no call)
            self.estimates.keep_from(msg.step - KEEP_STEPS)

    def _on_announce(self, data: bytes, key: Any) -> None:
        """An estimate listened to for readiness only: heard, not kept."""
        msg = self._decode(data, key, wire.Estimate)
        if msg is not None and msg.id != self.agent_id:
            self.heard.add(msg.id)

    def end_readiness(self) -> None:
        """Stop listening to the agents heard for readiness only (idempotent)."""
        if not self._ready_keys:
            return
        _undeclare(self.subs.remove(self, self._ready_keys), "after readiness")
        self._ready_keys = []

    def _on_odometry(self, data: bytes, key: Any) -> None:
        msg = self._decode(data, key, wire.Odometry)
        if msg is None or msg.id == self.agent_id:
            return
        _slot(self.odometry, msg.step)[msg.id] = msg
        prev = self.latest_odometry.get(msg.id)
        if prev is None or msg.step >= prev.step:
            self.latest_odometry[msg.id] = msg
        if self.odometry.lo < msg.step - KEEP_STEPS:  # (the common case costs no call)
            self.odometry.keep_from(msg.step - KEEP_STEPS)

    def _on_command(self, data: bytes, key: Any) -> None:
        msg = self._decode(data, key, wire.Command)
        if msg is not None and msg.agent in (0, self.agent_id):
            self.commands.append(msg)

    # -- main-thread API ---------------------------------------------------------------
    def pump(self, with_shared: bool = True) -> int:
        """Handle every sample waiting in the channels; returns how many were taken out
        (shared: every sample the process's shared channels held, whoever it was for).
        ``with_shared`` False: leave a packed process's shared channels to whoever pumps
        them for the whole process (:class:`offboard.daemon.host.DaemonHost`, once per
        pass over its daemons); a bus with subscriptions of its own pumps them anyway."""
        if self.shared is not None and not with_shared:
            return 0
        return self.subs.pump()

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Pump until ``predicate()`` holds or ``timeout`` seconds pass. The predicate is
        asked first: what the main loop pumped already usually satisfies it (in a packed
        process a pump drains every shared key, about 66 channels in grid64)."""
        if predicate():
            return True
        deadline = time.monotonic() + timeout
        while True:
            self.pump()
            if predicate():
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(POLL_S)

    def estimates_at(self, step: int) -> dict[int, wire.Estimate]:
        return dict(self.estimates.get(step, {}))

    def pop_commands(self) -> list[wire.Command]:
        out = list(self.commands)
        self.commands.clear()
        return out

    def publish_estimate(self, est: wire.Estimate) -> None:
        self._put(self._pub_est, wire.encode(est))

    def publish_status(self, status: wire.Status) -> None:
        self._put(self._pub_status, wire.encode(status))

    def _on_odo_matching(self, status: Any) -> None:
        """Zenoh's callback (its own thread): subscribers to our odometry came or went."""
        self.odometry_matched = bool(status.matching)

    def publish_odometry(self, odo: wire.Odometry) -> None:
        """Our vehicle's odometry, when anyone subscribes to it (Zenoh's matching status:
        a swarm flying on truth has no subscriber, and an unmatched put would still cost
        the encoding and the router's work every step)."""
        if not self.odometry_matched:
            return
        # never held in a burst: a peer's step k waits for our odometry of step k, which
        # a peer of this very process may do within the same pass
        self._put(self._pub_odo, wire.encode(odo), hold=False)

    def _put(self, pub: Any, payload: bytes, hold: bool = True) -> None:
        if self.faults is None:
            if self.burst is None or not hold:
                pub.put(payload)
            else:
                self.burst.hold(self._held_put, (pub, payload))
        else:
            self.faults.send(payload, lambda data: self._late_put(pub, data))

    def _held_put(self, item: tuple[Any, bytes]) -> None:
        """A put of the burst (:mod:`offboard.daemon.output_burst`): the publisher may be
        undeclared by the time the burst goes."""
        self._late_put(*item)

    def _late_put(self, pub: Any, payload: bytes) -> None:
        """A delayed put (the fault timer, a burst): the publisher may be gone by then."""
        try:
            pub.put(payload)
        except ZENOH_ERRORS as exc:
            log.debug("agent %d: delayed publish lost: %s", self.agent_id, exc)

    def close(self) -> None:
        if self.faults is not None:
            self.faults.close()
        _undeclare([self._odo_listener, *self.subs.remove(self)], "on close")


def _slot(store: StepStore[dict[int, Any]], step: int) -> dict[int, Any]:
    """The payloads of ``step`` in ``store`` (by sender), made empty on first use."""
    got = store.get(step)
    if got is None:
        got = store[step] = {}
    return got


def _undeclare(entities: list[Any], when: str) -> None:
    """Undeclare each of ``entities`` (subscribers, listeners), best effort: one that is
    already gone, or whose session closed, is logged at debug level and skipped."""
    for ent in entities:
        try:
            ent.undeclare()
        except ZENOH_ERRORS as exc:
            log.debug("undeclare %s: %s", when, exc)
