"""One burst of output per pass of a packed lockstep process (``offboard --agents``).

A packed process steps its agents one after the other (:mod:`offboard.daemon.host`).
Sent as they are made, each agent's setpoint datagram and Zenoh puts wake the receiver
(the simulator's select, the Zenoh transmit thread, then the router) between two agents'
steps, and a wake-up of a thread asleep on the other core costs the sender several times
the send itself (a 60-byte loopback ``sendto``: 11 µs of CPU when the receiver sleeps
between sends, 3.5 µs in a burst, on the 2-core machine). Held here and sent together
at the end of the pass, they wake each receiver once, and the transmit thread batches
the puts.

Held in lockstep only, where no agent of the pass waits for what another of the same
pass sends: a step k waits for data of step k from the simulator (sent after every
setpoint of step k−1 arrived, so after an earlier pass's burst) and for the estimates of
step k−1 (published by an earlier pass). The one output of step k that a step k waits
for, an agent's own odometry on Zenoh (``--sensing odometry``), is never held. The order
of the held outputs is kept. In real time nothing is held: a setpoint's latency is the
vehicle's.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


class OutputBurst:
    """Sends held until :meth:`flush` (module docstring)."""

    def __init__(self) -> None:
        self._held: list[tuple[Callable[[Any], Any], Any]] = []

    def hold(self, send: Callable[[Any], Any], item: Any) -> None:
        """``send(item)`` at the next :meth:`flush`, after everything held before it."""
        self._held.append((send, item))

    def flush(self) -> int:
        """Send everything held, in order; how many."""
        held, self._held = self._held, []
        for send, item in held:
            send(item)
        return len(held)

    def __len__(self) -> int:
        return len(self._held)
