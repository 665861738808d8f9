"""The COMMAND_LONG -> COMMAND_ACK retry policy, written once for blocking and async callers.

:func:`command_exchange` is a sans-I/O generator: it yields what to do next
(:class:`SendAttempt` - send COMMAND_LONG with this ``confirmation``; :class:`AwaitAck` -
wait up to ``timeout_s`` for the ACK) and is sent back whether that worked. Its return
value is the :class:`CommandResult`. :func:`drive_blocking` and :func:`drive_async` run
it with a blocking send/wait pair or an ``async`` wait, so the policy (attempt count,
``confirmation`` = retry number, NO-LINK on a failed send, TIMEOUT when every attempt
goes unanswered) is the same on both paths. The async path is plain coroutines, so
``asyncio.gather`` over all vehicles runs every command at once (no thread pool).

:class:`PendingAck` is the slot the receive side fills when the COMMAND_ACK arrives.
"""

from __future__ import annotations

import threading
from collections.abc import Awaitable, Callable, Generator
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mavlink

from .px4modes import MAV_RESULT_NAMES, CommandSpec


@dataclass(frozen=True)
class CommandResult:
    """Outcome of one COMMAND_LONG: ``result`` is MAV_RESULT or None (no ACK / no link)."""

    sysid: int
    command: int
    label: str
    result: int | None
    attempts: int
    elapsed_s: float
    note: str = ""

    @property
    def ok(self) -> bool:
        return self.result == mavlink.MAV_RESULT_ACCEPTED

    @property
    def result_name(self) -> str:
        if self.result is None:
            return self.note or "TIMEOUT"
        return MAV_RESULT_NAMES.get(self.result, str(self.result))

    def describe(self) -> str:
        tries = "1 try" if self.attempts == 1 else f"{self.attempts} tries"
        return f"#{self.sysid} {self.label}: {self.result_name} ({tries})"


@dataclass
class PendingAck:
    """Where the reader thread leaves the final MAV_RESULT of an awaited COMMAND_ACK."""

    event: threading.Event = field(default_factory=threading.Event)
    result: int | None = None
    progress: float = 0.0  # clock() time of the last MAV_RESULT_IN_PROGRESS


@dataclass(frozen=True)
class SendAttempt:
    """Send the COMMAND_LONG with this ``confirmation``; reply True when it went out."""

    confirmation: int


@dataclass(frozen=True)
class AwaitAck:
    """Wait up to ``timeout_s`` for the COMMAND_ACK; reply True when it arrived."""

    timeout_s: float


Step = SendAttempt | AwaitAck
Exchange = Generator[Step, bool, CommandResult]


def command_exchange(
    sysid: int,
    spec: CommandSpec,
    pend: PendingAck,
    clock: Callable[[], float],
    timeout_s: float = 1.0,
    retries: int = 2,
) -> Exchange:
    """One command, up to ``retries + 1`` attempts of ``timeout_s`` each (seconds)."""
    t0 = clock()
    attempts = 0
    for attempt in range(retries + 1):
        if not (yield SendAttempt(attempt)):
            return CommandResult(sysid, spec.command, spec.label, None, attempt, 0.0, "NO-LINK")
        attempts += 1
        if (yield AwaitAck(timeout_s)):
            break
    return CommandResult(sysid, spec.command, spec.label, pend.result, attempts, clock() - t0)


def drive_blocking(
    exchange: Exchange,
    send: Callable[[int], bool],
    wait: Callable[[float], bool],
) -> CommandResult:
    """Run ``exchange`` with a blocking ``send(confirmation)`` and ``wait(timeout_s)``."""
    try:
        step = next(exchange)
        while True:
            if isinstance(step, SendAttempt):
                step = exchange.send(send(step.confirmation))
            else:
                step = exchange.send(wait(step.timeout_s))
    except StopIteration as done:
        result: CommandResult = done.value
        return result


async def drive_async(
    exchange: Exchange,
    send: Callable[[int], bool],
    wait: Callable[[float], Awaitable[bool]],
) -> CommandResult:
    """Run ``exchange`` with a non-blocking ``send`` and an ``async`` ``wait(timeout_s)``."""
    try:
        step = next(exchange)
        while True:
            if isinstance(step, SendAttempt):
                step = exchange.send(send(step.confirmation))
            else:
                step = exchange.send(await wait(step.timeout_s))
    except StopIteration as done:
        result: CommandResult = done.value
        return result
