"""The offboard daemon's Zenoh side: truth, neighbours' estimates, commands in; own out.

Receives (callbacks run on Zenoh threads; everything is stored under one condition):

* ``Truth`` per control step (from ``vehicle-sim``), kept by step;
* every agent's post-update ``Estimate`` (kept by sender and step);
* ground-station ``Command`` payloads (method switch, outage injection).

A payload that fails to decode is counted (``bad_payloads``) and dropped. Key
expressions and payloads come from :mod:`swarm_common.wire` only.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import zenoh

from swarm_common import wire

KEEP_STEPS = 64
FIFO_DEPTH = 1024


def _drain(sub: Any, handler: Callable[[Any], None]) -> None:
    """Feed every sample of a channel subscriber to ``handler`` until it is undeclared."""
    try:
        for sample in sub:
            handler(sample)
    except Exception:  # noqa: BLE001 - session closed under us: stop quietly
        return


class SwarmBus:
    """Typed publish/subscribe of one agent over an open Zenoh session."""

    def __init__(
        self, session: Any, swarm: str, agent_id: int, threaded: bool = False
    ) -> None:
        self.session = session
        self.swarm = swarm
        self.agent_id = agent_id
        self.cond = threading.Condition()
        self.truth: dict[int, wire.Truth] = {}
        self.latest_truth: wire.Truth | None = None
        self.estimates: dict[int, dict[int, wire.Estimate]] = {}  # step -> id -> est
        self.latest_estimate: dict[int, wire.Estimate] = {}
        self.commands: deque[wire.Command] = deque()
        self.bad_payloads = 0
        # Subscriptions deliver into Rust FIFO channels drained by Python threads, so
        # Zenoh's own threads never wait for the GIL (with Python callbacks they do, and
        # every put() of this process then stalls behind them: 1.9 ms median, measured).
        self.threaded = threaded
        self._subs = []
        self._polled: list[tuple[Any, Callable[[Any], None]]] = []
        for key, handler in (
            (wire.key_truth(swarm), self._on_truth),
            (wire.key_estimate(swarm, "*"), self._on_estimate),
            (wire.key_cmd(swarm, "*"), self._on_command),
        ):
            sub = session.declare_subscriber(key, zenoh.handlers.FifoChannel(FIFO_DEPTH))
            if threaded:
                th = threading.Thread(target=_drain, args=(sub, handler), daemon=True)
                th.start()
            else:  # drained by the main thread in pump(): no GIL hand-offs at all
                self._polled.append((sub, handler))
            self._subs.append(sub)
        self._pub_est = session.declare_publisher(wire.key_estimate(swarm, agent_id))
        self._pub_status = session.declare_publisher(wire.key_status(swarm, agent_id))

    # -- callbacks (Zenoh threads) -----------------------------------------------------
    def _decode(self, sample: Any) -> wire.Payload | None:
        try:
            return wire.decode(sample.payload.to_bytes())
        except wire.WireError:
            with self.cond:
                self.bad_payloads += 1
            return None

    def _on_truth(self, sample: Any) -> None:
        msg = self._decode(sample)
        if not isinstance(msg, wire.Truth):
            return
        with self.cond:
            self.truth[msg.step] = msg
            if self.latest_truth is None or msg.step >= self.latest_truth.step:
                self.latest_truth = msg
            for old in [s for s in self.truth if s < msg.step - KEEP_STEPS]:
                del self.truth[old]
            self.cond.notify_all()

    def _on_estimate(self, sample: Any) -> None:
        msg = self._decode(sample)
        if not isinstance(msg, wire.Estimate) or msg.id == self.agent_id:
            return
        with self.cond:
            self.estimates.setdefault(msg.step, {})[msg.id] = msg
            prev = self.latest_estimate.get(msg.id)
            if prev is None or msg.step >= prev.step:
                self.latest_estimate[msg.id] = msg
            for old in [s for s in self.estimates if s < msg.step - KEEP_STEPS]:
                del self.estimates[old]
            self.cond.notify_all()

    def _on_command(self, sample: Any) -> None:
        msg = self._decode(sample)
        if not isinstance(msg, wire.Command):
            return
        if msg.agent not in (0, self.agent_id):
            return
        with self.cond:
            self.commands.append(msg)
            self.cond.notify_all()

    # -- main-thread API ---------------------------------------------------------------
    def pump(self) -> int:
        """Handle every sample waiting in the channels (polled mode); returns how many."""
        n = 0
        for sub, handler in self._polled:
            while True:
                try:
                    sample = sub.try_recv()
                except Exception:  # noqa: BLE001 - undeclared / session closed
                    break
                if sample is None:
                    break
                handler(sample)
                n += 1
        return n

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Wait until ``predicate()`` or ``timeout`` seconds (polls the channels every
        0.2 ms in polled mode, waits on the condition in threaded mode)."""
        deadline = time.monotonic() + timeout
        if not self.threaded:
            while True:
                self.pump()
                if predicate():
                    return True
                if time.monotonic() >= deadline:
                    return False
                time.sleep(0.0002)
        with self.cond:
            while not predicate():
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self.cond.wait(remaining)
            return True

    def estimates_at(self, step: int) -> dict[int, wire.Estimate]:
        with self.cond:
            return dict(self.estimates.get(step, {}))

    def pop_commands(self) -> list[wire.Command]:
        with self.cond:
            out = list(self.commands)
            self.commands.clear()
            return out

    def publish_estimate(self, est: wire.Estimate) -> None:
        self._pub_est.put(wire.encode(est))

    def publish_status(self, status: wire.Status) -> None:
        self._pub_status.put(wire.encode(status))

    def close(self) -> None:
        for s in self._subs:
            try:
                s.undeclare()
            except Exception:  # noqa: BLE001 - closing best effort
                pass
