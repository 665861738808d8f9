"""The ground station's Zenoh side: truth, every agent's status and estimate; commands.

Subscribes to ``key_truth(swarm)``, ``key_status(swarm, "*")`` and
``key_estimate(swarm, "*")`` (``swarm_common.wire``); keeps the latest payload of
each with its receive time, counts payloads that fail to decode, and turns status
transitions into operator events (method switch, QP fallback, communication loss,
estimator health, status gone stale / back). Publishes :class:`Command` payloads on
``key_cmd(swarm, kind)``.

By default it opens its own peer session that dials the simulator's listening
endpoint (``swarm_common.zenoh_session.default_endpoint(offset)``); a session can be
passed in instead (tests, or a process that already has one). No Textual here.

**No Python on Zenoh's threads.** Each subscriber delivers into a
:class:`zenoh.handlers.RingChannel` of :data:`RING_DEPTH` samples (it drops the oldest
when full and never blocks the pushing thread), and a thread of this feed per subscriber
decodes from it. ``gcs dashboard --launch`` passes the session of the swarm's router, and
a Python callback there runs on the router's receive thread: it waits for the GIL and for
this feed's lock, and while it waits the router forwards nothing to anyone. A busy
dashboard on a loaded host stalled the truth of every daemon for longer than the
runner-loss limit that way, and a FIFO channel would do the same once full. With the
ring, a stalled dashboard loses its own oldest samples and nothing else.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import zenoh
from pymavlink.dialects.v20 import common as mavlink

from offboard.safety.monitor import alarm_onsets
from swarm_common.enums import AgentAlarm, CommandKind, Method, VehicleMode
from swarm_common.wire import (
    COMMAND_KINDS,
    Command,
    Estimate,
    Status,
    Truth,
    WireError,
    agent_id_from_key,
    decode,
    encode,
    key_cmd,
    key_estimate,
    key_status,
    key_truth,
)
from swarm_common.zenoh_session import open_session

log = logging.getLogger(__name__)

METHODS = tuple(Method)
NOTICE = mavlink.MAV_SEVERITY_NOTICE
INFO = mavlink.MAV_SEVERITY_INFO
RING_DEPTH = 256  # samples per subscriber kept for the feed's reader (the oldest dropped)


def in_charge(s: Status) -> bool:
    """Whether the agent's setpoints fly its vehicle (its QP, estimator and links matter)."""
    return s.mode == VehicleMode.OFFBOARD


@dataclass(frozen=True)
class FeedEvent:
    t: float  # clock() time
    agent: int  # 0 = swarm-wide
    kind: str  # method | fallback | comm | estimator | status | mode | outage
    text: str
    severity: int = INFO  # MAV_SEVERITY scale: 0..7, lower is worse


@dataclass
class FeedSnapshot:
    """A consistent copy of what the feed holds, with receive times (clock() based)."""

    now: float
    truth: Truth | None
    truth_time: float | None
    status: dict[int, tuple[Status, float]]
    estimate: dict[int, tuple[Estimate, float]]
    bad_payloads: int
    missing: list[int]  # expected ids with no status yet, or a stale one
    connected: bool


class ZenohFeed:
    """Zenoh subscriber/publisher for the dashboard. ``start()`` opens and subscribes."""

    def __init__(
        self,
        swarm: str,
        ids: Sequence[int],
        session: Any = None,
        connect: Sequence[str] = (),
        listen: Sequence[str] = (),
        mode: str = "peer",
        stale_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        config_file: str | None = None,
    ) -> None:
        self.swarm = swarm
        self.config_file = config_file  # Zenoh credentials (default: $SWARM_ZENOH_CONFIG)
        self.ids = list(ids)
        self._session = session
        self._own_session = session is None
        self.connect = list(connect)
        self.listen = list(listen)
        self.mode = mode
        self.stale_s = stale_s
        self.clock = clock
        self._lock = threading.Lock()
        self._subs: list[Any] = []
        self._readers: list[threading.Thread] = []
        self.truth: Truth | None = None
        self.truth_time: float | None = None
        self.status: dict[int, tuple[Status, float]] = {}
        self.estimate: dict[int, tuple[Estimate, float]] = {}
        self.bad_payloads = 0
        self._events: deque[FeedEvent] = deque(maxlen=2000)
        self._stale_flag: dict[int, bool] = {}
        self.started_at = clock()
        # called with each truth taken in, on a reader thread (the live view, gcs.records.live)
        self.on_truth: Callable[[Truth], None] | None = None

    # -- lifecycle ---------------------------------------------------------------
    def start(self) -> ZenohFeed:
        if self._session is None:
            self._session = open_session(self.mode, listen=self.listen, connect=self.connect,
                                         config_file=self.config_file)
        s = self._session
        keys = (key_truth(self.swarm), key_status(self.swarm, "*"),
                key_estimate(self.swarm, "*"))
        self._subs = [s.declare_subscriber(k, zenoh.handlers.RingChannel(RING_DEPTH))
                      for k in keys]
        self._readers = [
            threading.Thread(target=self._read, args=(sub.handler,), daemon=True,
                             name=f"zenoh-feed-{i}")
            for i, sub in enumerate(self._subs)
        ]
        for th in self._readers:
            th.start()
        self.started_at = self.clock()
        return self

    def close(self) -> None:
        for sub in self._subs:  # closes its channel: its reader's recv() raises and it ends
            try:
                sub.undeclare()
            except zenoh.ZError as exc:  # the session is already gone
                log.debug("undeclare %s: %s", sub, exc)
        self._subs = []
        for th in self._readers:
            th.join(timeout=1.0)
        self._readers = []
        if self._own_session and self._session is not None:
            try:
                self._session.close()
            except zenoh.ZError as exc:
                log.warning("closing the Zenoh session: %s", exc)
            self._session = None

    # -- receive -----------------------------------------------------------------
    def _read(self, channel: Any) -> None:
        """A reader thread: every sample of one subscriber's ring, until it is closed."""
        while True:
            try:
                sample = channel.recv()
            except zenoh.ZError:  # undeclared (or the session closed): nothing more
                return
            try:
                self._on_sample(sample)
            except Exception:  # a payload that breaks a handler: counted, reading goes on
                log.warning("Zenoh sample not taken in", exc_info=True)
                with self._lock:
                    self.bad_payloads += 1

    def _on_sample(self, sample: Any) -> None:
        try:
            data = sample.payload.to_bytes()
            key = str(sample.key_expr)
        except (AttributeError, TypeError, ValueError, zenoh.ZError) as exc:
            with self._lock:
                self.bad_payloads += 1
            log.debug("unreadable Zenoh sample: %r", exc)
            return
        self.ingest(key, data)

    def ingest(self, key: str, data: bytes) -> None:
        """Decode one payload received on ``key`` (a reader thread, or tests)."""
        now = self.clock()
        try:
            obj = decode(data)
            if isinstance(obj, Status | Estimate) and agent_id_from_key(key) != obj.id:
                raise WireError(f"id {obj.id} on key {key}")
        except WireError:
            with self._lock:
                self.bad_payloads += 1
            log.debug("undecodable payload on %s", key)
            return
        with self._lock:
            if isinstance(obj, Truth):
                self.truth, self.truth_time = obj, now
            elif isinstance(obj, Status):
                prev = self.status.get(obj.id)
                self._status_events(prev[0] if prev else None, obj, now)
                self.status[obj.id] = (obj, now)
                if self._stale_flag.get(obj.id):
                    self._stale_flag[obj.id] = False
                    self._events.append(FeedEvent(now, obj.id, "status", "status back", NOTICE))
            elif isinstance(obj, Estimate):
                self.estimate[obj.id] = (obj, now)
            else:
                self.bad_payloads += 1  # a Command on a data key
        if isinstance(obj, Truth) and self.on_truth is not None:
            self.on_truth(obj)

    def _status_events(self, prev: Status | None, s: Status, now: float) -> None:
        """Operator events from one agent's status change. Before its setpoints fly its
        vehicle (mode not OFFBOARD: on the pads, holding, landed) the agent's QP, estimator
        and links cannot hurt anyone: their changes are states (INFO), QP fallbacks are
        not reported, and what is still wrong when it enters OFFBOARD is reported then."""
        ev = self._events
        if prev is None:
            ev.append(FeedEvent(now, s.id, "status", f"status up ({s.mode}, {s.method})", INFO))
            return
        flying = in_charge(s)
        if s.method != prev.method:
            text = f"method {prev.method} -> {s.method}"
            ev.append(FeedEvent(now, s.id, "method", text, NOTICE))
        if s.mode != prev.mode:
            ev.append(FeedEvent(now, s.id, "mode", f"offboard {prev.mode} -> {s.mode}", NOTICE))
        entered = flying and not in_charge(prev)
        if flying and s.fallbacks > prev.fallbacks:
            text = f"QP fallback ({s.qp_status}), total {s.fallbacks}"
            ev.append(FeedEvent(now, s.id, "fallback", text, mavlink.MAV_SEVERITY_WARNING))
        if s.comm_ok != prev.comm_ok or (entered and not s.comm_ok):
            text, sev = (
                ("comm restored", NOTICE)
                if s.comm_ok
                else ("comm outage", mavlink.MAV_SEVERITY_ERROR if flying else INFO)
            )
            ev.append(FeedEvent(now, s.id, "comm", text, sev))
        if s.est_health != prev.est_health or (entered and s.est_health != "ok"):
            bad = mavlink.MAV_SEVERITY_ERROR if flying else INFO
            sev = INFO if s.est_health == "ok" else bad
            ev.append(FeedEvent(now, s.id, "estimator", f"estimator {s.est_health}", sev))
        new = alarm_onsets(prev.alarms, s.alarms) if flying else AgentAlarm(0)
        if entered:
            new |= alarm_onsets(0, s.alarms)
        if new:  # docs/safety.md, in-flight alarms
            sev = (mavlink.MAV_SEVERITY_CRITICAL if new & AgentAlarm.FALLBACK
                   else mavlink.MAV_SEVERITY_WARNING if new == AgentAlarm.DEADLOCK
                   else mavlink.MAV_SEVERITY_ERROR)
            text = "safety alarm " + "+".join(str(b.name) for b in new)
            ev.append(FeedEvent(now, s.id, "safety", text, sev))

    # -- snapshots ---------------------------------------------------------------
    def missing(self, now: float | None = None) -> list[int]:
        """Expected ids with no status yet, or one older than ``stale_s``."""
        now = self.clock() if now is None else now
        with self._lock:
            return self._missing(now)

    def _missing(self, now: float) -> list[int]:
        out = []
        for i in self.ids:
            rec = self.status.get(i)
            if rec is None or now - rec[1] > self.stale_s:
                out.append(i)
        return out

    def check(self, now: float | None = None) -> None:
        """Raise "status stale" events once per silence (call periodically)."""
        now = self.clock() if now is None else now
        with self._lock:
            for i in self.ids:
                rec = self.status.get(i)
                if rec is not None and now - rec[1] > self.stale_s and not self._stale_flag.get(i):
                    self._stale_flag[i] = True
                    self._events.append(
                        FeedEvent(
                            now,
                            i,
                            "status",
                            f"status stale ({now - rec[1]:.1f}s)",
                            mavlink.MAV_SEVERITY_ERROR,
                        )
                    )

    def snapshot(self) -> FeedSnapshot:
        now = self.clock()
        with self._lock:
            return FeedSnapshot(
                now=now,
                truth=self.truth,
                truth_time=self.truth_time,
                status=dict(self.status),
                estimate=dict(self.estimate),
                bad_payloads=self.bad_payloads,
                missing=self._missing(now),
                connected=self._session is not None,
            )

    def drain_events(self) -> list[FeedEvent]:
        with self._lock:
            out = list(self._events)
            self._events.clear()
        return out

    # -- commands ----------------------------------------------------------------
    def publish(self, cmd: Command) -> str:
        """Publish ``cmd`` on ``key_cmd(swarm, cmd.kind)``; returns the key."""
        if cmd.kind == "method" and cmd.method not in METHODS:
            raise ValueError(f"method {cmd.method!r}: must be one of {', '.join(METHODS)}")
        if cmd.kind not in COMMAND_KINDS:
            kinds = ", ".join(COMMAND_KINDS)
            raise ValueError(f"command kind {cmd.kind!r}: must be one of {kinds}")
        if self._session is None:
            raise RuntimeError("zenoh feed is not started")
        key = key_cmd(self.swarm, cmd.kind)
        self._session.put(key, encode(cmd))
        return key

    @property
    def started(self) -> bool:
        """The Zenoh session is open (commands can be published)."""
        return self._session is not None

    def mission_time(self) -> float | None:
        """Latest mission time (s) any agent reported in its status, None before any."""
        with self._lock:
            return max((st.t for st, _ in self.status.values()), default=None)

    def switch_method(self, method: str, agent: int = 0) -> str:
        return self.publish(Command(kind=CommandKind.METHOD, agent=agent, method=method))

    def inject_outage(self, duration_s: float, agent: int = 0) -> str:
        return self.publish(Command(kind=CommandKind.OUTAGE, agent=agent,
                                    duration_s=float(duration_s)))
