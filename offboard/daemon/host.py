"""Several agents' daemons in one process (``offboard --agents 3-8``).

Each agent keeps everything that is its own: its :class:`offboard.daemon.core.OffboardDaemon`
(agent, guards, mode requests, runner-loss policy), its MAVLink link to its own vehicle
(own UDP socket, sequence numbers, signing state and ``.tlog``). What they share is the
process: one Zenoh session (each daemon its own publishers on it; one subscriber per key
for all of them, :mod:`offboard.daemon.zenoh.shared_subs`, each daemon judging what it is handed;
decoded payloads shared, :class:`offboard.daemon.zenoh.link.DecodeCache`), one formation object
and one event loop.

The loop: wait (``select``) until any vehicle socket is readable or ``WAIT_CAP_S`` passes,
hand out what the shared Zenoh channels hold, then give every daemon one pass
(:meth:`OffboardDaemon.iterate`) in agent order. A daemon that waits for data in its step
(its truth, its peers' estimates) pumps the shared channels itself. In
lockstep a daemon's step k waits only for data of step k (its vehicle's ODOMETRY, the
truth) and of step k−1 (its peers' estimates, published when their step k−1 ended), so
stepping the packed agents one after the other cannot deadlock, and each agent computes
exactly what it computes alone: a packed lockstep run equals the one-process-per-agent
and in-process runs. One process per agent stays the default and the realistic layout
(one companion computer per vehicle); packing is for simulation on few cores.

An agent whose daemon ends (vehicle heartbeat lost) leaves the loop; the others fly on,
and the process exits with the worst status once all have ended or on SIGTERM/SIGINT.
"""

from __future__ import annotations

import logging
import select
import signal
import time
from typing import Any

from offboard.daemon.core import WAIT_CAP_S, OffboardDaemon
from offboard.daemon.output_burst import OutputBurst
from offboard.daemon.packing import format_agents, parse_agents

__all__ = ["DaemonHost", "format_agents", "parse_agents"]

log = logging.getLogger(__name__)

class DaemonHost:
    """The event loop of the daemons packed in one process (module docstring)."""

    def __init__(self, daemons: list[OffboardDaemon]) -> None:
        if not daemons:
            raise ValueError("no daemon to host")
        self.daemons = daemons
        self.stop = False

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.stop = True
        for d in self.daemons:
            d.stop = True

    def run(self) -> int:
        """Start every daemon (the vehicles' heartbeats), then loop until all have ended
        or a signal; the worst exit status of the daemons."""
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)
        worst = 0
        try:
            live: list[OffboardDaemon] = []
            for d in self.daemons:
                rc = d.start()
                if rc is not None:  # no vehicle: the packed process fails as one daemon would
                    return rc
                live.append(d)
            worst = self._loop(live)
            for d in self.daemons:
                d.say_stopped()
            return worst
        finally:
            for d in self.daemons:
                d.close()

    def _loop(self, live: list[OffboardDaemon]) -> int:
        worst = 0
        fds = [fd for d in live if (fd := d.link.fileno()) is not None]
        whole = len(fds) == len(live)  # every link a socket: one select waits for them all
        mark = time.monotonic()
        shared = live[0].bus.shared  # the packed daemons' Zenoh subscriptions (or None)
        burst = self._burst(live)
        while live and not self.stop:
            if whole:
                select.select(fds, [], [], WAIT_CAP_S)
            if shared is not None:  # once a pass, not once per daemon (each would drain
                shared.pump()  # every key); a daemon waiting for data pumps it itself
            for d in list(live):
                rc = d.iterate(mark, 0.0 if whole else WAIT_CAP_S / len(live))
                mark = time.monotonic()
                if rc is not None:
                    log.error("agent %d: daemon ended (status %d); %d agent(s) fly on",
                              d.id, rc, len(live) - 1)
                    worst = max(worst, rc)
                    live.remove(d)
                    fds = [fd for x in live if (fd := x.link.fileno()) is not None]
            if burst is not None:
                burst.flush()
        if burst is not None:
            burst.flush()
        return worst

    @staticmethod
    def _burst(live: list[OffboardDaemon]) -> OutputBurst | None:
        """One burst for the pass's sends (:mod:`offboard.daemon.output_burst`): lockstep and
        more than one agent only."""
        if len(live) < 2 or not all(d.cfg.lockstep for d in live):
            return None
        burst = OutputBurst()
        for d in live:
            d.link.burst = d.bus.burst = burst
        return burst
