"""The live view (docs/records.md, "Live view"): a run's record channels served by
foxglove-sdk's WebSocket server while the run goes, for the Foxglove app to draw the swarm
in 3-D as it flies. The topics, schemas and messages are the record's own
(:class:`~gcs.records.channels.RecordChannels`, the one implementation the MCAP writer
uses), with two differences: each vehicle frame of ``/world/tf`` turns with the vehicle's
true attitude (the live feeds have it, a run's series does not), and ``/events`` holds the
start, the onsets the rows show (QP fallbacks and recoveries, alarm bits, input clipping)
and, when the run ends, the events of its ``metrics.json`` (:meth:`LiveView.finish`).

A :class:`LiveView` is fed rows of a :class:`~gcs.report.metrics.Series` and each row's
attitudes (:mod:`gcs.mission.live_feed` builds them from each runner's data). While no
client subscribes, :meth:`LiveView.watched` is False (a counter kept by the server's
subscribe callbacks) and the feeds build nothing; with one, a message is built only for
the topics some client subscribes to (``has_sinks``). Logging never waits for a client:
the server queues what each client is sent and drops the oldest when that one lags.

The server binds ``127.0.0.1`` by default: anyone who can reach the port sees the swarm,
and the protocol has no authentication, so another address is the user's choice
(``--foxglove-host``).
"""

from __future__ import annotations

import argparse
import atexit
import logging
import math
import threading
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import foxglove
import numpy as np
from foxglove import Context
from foxglove.messages import Quaternion
from foxglove.websocket import ChannelView, Client, ServerListener

from gcs.records import topics as tp
from gcs.records.channels import RecordChannels, RecordContext, cdr_messages
from gcs.records.events import (
    Event,
    document_events,
    run_failed_event,
    series_events,
    start_event,
)
from gcs.records.live_flags import DEFAULT_HOST, DEFAULT_PORT, live_endpoint, ws_url
from gcs.records.scene import BEARING_PERIOD_S, IDENTITY
from gcs.report.metrics import Series
from swarm_common.frames import quat_from_rotm, rotm_from_euler

if TYPE_CHECKING:
    from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

LINES_NS = int(round(BEARING_PERIOD_S * 1e9))  # the bearings and desired poses: 10 Hz


def attitude_rotations(att: np.ndarray) -> list[Quaternion]:
    """Each vehicle's rotation world -> body of (N, 3) ENU/FLU roll, pitch, yaw (rad); the
    identity where an attitude is not finite."""
    out = []
    for r, p, y in np.asarray(att, float).tolist():
        if not all(map(math.isfinite, (r, p, y))):
            out.append(IDENTITY)
            continue
        w, x, qy, z = quat_from_rotm(rotm_from_euler(r, p, y)).tolist()
        out.append(Quaternion(x=x, y=qy, z=z, w=w))
    return out


class _Listener(ServerListener):
    """Counts the subscriptions (the server's threads call it)."""

    def __init__(self, view: LiveView) -> None:
        self.view = view

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.view._subscribed(channel.topic, +1)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        self.view._subscribed(channel.topic, -1)


class LiveView:
    """A Foxglove WebSocket server on ``host:port`` (0: any free port) serving the record
    channels of ``c``; ``run``: the run's ``scenario``, ``method`` and ``seed`` (the start
    event). ``OSError`` (one line) when the port cannot be bound. Feed it from one thread."""

    def __init__(self, c: RecordContext, run: Mapping[str, Any], host: str = DEFAULT_HOST,
                 port: int = DEFAULT_PORT) -> None:
        self.c, self.run = c, dict(run)
        self._lock = threading.Lock()
        self._subs = 0  # subscriptions held by clients, every channel counted
        self._setup_due = True  # a client subscribed to /scene: send the vehicles again
        self._started = False  # the start event was logged
        self._prev: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._last_lines = -LINES_NS
        self._first_ns: int | None = None
        self._last_ns = 0
        self._ctx = Context()
        self.channels = RecordChannels(self._ctx, c, skip_unwatched=True)
        sdk = logging.getLogger("foxglove")  # its server's INFO lines: each client, shutdown
        if sdk.level == logging.NOTSET:
            sdk.setLevel(logging.WARNING)
        try:
            self._server = foxglove.start_server(
                name=f"bearing-swarm {run.get('scenario')}", host=host, port=port,
                context=self._ctx, server_listener=_Listener(self))
        except RuntimeError as exc:  # FoxgloveError: Failed to bind port: ...
            why = str(exc).rsplit(": ", 1)[-1]
            raise OSError(f"live view on {host}:{port}: cannot listen: {why}") from None
        self.host, self.port = host, int(self._server.port)
        self._closed = False
        atexit.register(self.close)
        log.info("live view: open %s in Foxglove (Open connection, Foxglove WebSocket)",
                 self.url)

    @property
    def url(self) -> str:
        return ws_url(self.host, self.port)

    def _subscribed(self, topic: str, step: int) -> None:
        with self._lock:
            self._subs = max(0, self._subs + step)
            if step > 0 and topic == tp.SCENE:
                self._setup_due = True

    def watched(self) -> bool:
        """Whether some client subscribes to some topic (else :meth:`publish` is free)."""
        return self._subs > 0

    def publish(self, s: Series, att: np.ndarray | None = None) -> None:
        """Log the rows of ``s`` in order (``att`` (K, N, 3): each row's attitudes, for
        ``/world/tf``); rows whose positions are not finite are skipped. Nothing while
        no client watches (the onsets then start again from the next row watched)."""
        if not self.watched() or self._closed:
            self._prev = None
            return
        ns = np.round(np.asarray(s.t, float) * 1e9).astype(np.int64)
        rows = np.flatnonzero(np.isfinite(s.p).all(axis=(1, 2)))
        if len(rows) == 0:
            return
        if self._first_ns is None:
            self._first_ns = int(ns[rows[0]])
        ch = self.channels
        events = self._events(s, ns, rows)
        cdr = cdr_messages(s, self.c) if ch.wants_cdr() else None
        with self._lock:
            setup, self._setup_due = self._setup_due, False
        e = 0
        for k in rows.tolist():
            t_ns = int(ns[k])
            if setup:
                ch.log_setup(t_ns)
                setup = False
            # every LINES_NS of sim time (again from a clock that went back: a new run)
            lines = not 0 <= t_ns - self._last_lines < LINES_NS
            if lines:
                self._last_lines = t_ns
            rot = None if att is None else attitude_rotations(att[k])
            ch.log_step(s, k, t_ns, cdr, lines, rot)
            while e < len(events) and events[e].ns <= t_ns:
                ch.log_event(events[e], t_ns)
                e += 1
            self._last_ns = t_ns

    def _events(self, s: Series, ns: np.ndarray, rows: np.ndarray) -> list[Event]:
        """The start (once, while ``/events`` is watched) and the onsets of ``rows``
        against the last row published."""
        out: list[Event] = []
        if not self._started and self.channels.events.has_sinks():
            self._started = True
            out.append(start_event(self.run, int(ns[rows[0]])))
        n = s.p.shape[1]
        prev = self._prev or (-1, np.zeros(n, bool), np.zeros(n, np.uint8), np.zeros(n, bool))
        t = np.concatenate([[prev[0]], ns[rows]])
        fb = np.concatenate([prev[1][None], np.asarray(s.fallback[rows], bool)])
        al = np.concatenate([prev[2][None], np.asarray(s.alarms[rows], np.uint8)])
        cl = np.concatenate([prev[3][None], np.asarray(s.input_clipped[rows], bool)])
        self._prev = (int(t[-1]), fb[-1], al[-1], cl[-1])
        out += [ev for ev in series_events(t, self.c.ids, fb, al, cl) if ev.ns > t[0]]
        out.sort(key=lambda ev: ev.ns)
        return out

    def finish(self, doc: Mapping[str, Any]) -> None:
        """The end of the run: the events of its ``metrics.json`` document ``doc`` (safety
        alarms, failed agents, the verdict), while ``/events`` is watched."""
        if self._closed or self._first_ns is None or not self.channels.events.has_sinks():
            return
        for ev in document_events(doc, self._first_ns, self._last_ns)[1:]:  # not the start
            self.channels.log_event(ev, self._last_ns)

    def fail(self, why: str) -> None:
        """The run failed before its end (``why``: its one-line error, e.g. a dead agent
        worker): an ERROR ``run`` event at the last time published, in place of
        :meth:`finish`'s verdict, while ``/events`` is watched."""
        if self._closed or not self.channels.events.has_sinks():
            return
        self.channels.log_event(run_failed_event(why, self._last_ns), self._last_ns)

    def close(self) -> None:
        """Stop the server (its clients are disconnected); idempotent."""
        if self._closed:
            return
        self._closed = True
        self._server.stop()
        atexit.unregister(self.close)


def start_live(args: argparse.Namespace, sc: Scenario, method: str,
               seed: int | None) -> LiveView | None:
    """The :class:`LiveView` of ``--foxglove`` for a run of ``sc`` (None without it);
    ``ValueError`` or ``OSError`` (one line) for bad flags or a port that cannot be bound."""
    where = live_endpoint(args)
    if where is None:
        return None
    run = {"scenario": sc.name, "method": method, "seed": sc.seed if seed is None else seed}
    return LiveView(RecordContext.from_scenario(sc), run, *where)
