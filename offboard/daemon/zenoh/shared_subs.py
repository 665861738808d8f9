"""Zenoh subscriptions shared by the daemons packed in one process (``offboard --agents``).

With one set of subscribers per daemon, a payload that n co-located daemons subscribe to
is queued by Zenoh into n channels, and each daemon takes it out and copies its bytes. In
a packed grid64 process that is about 14 deliveries of every estimate per step, and 64 of
the truth. Shared, each key expression has one subscriber in the process: Zenoh queues a
payload once, and :meth:`SharedSubscriptions.pump` takes it out and copies its bytes once.
Then it hands the same bytes to every daemon that subscribed to the key, in the order they
subscribed.

A daemon alone in its process holds a private instance: the same code hands its payloads
to it alone, as its own subscribers did.

Each daemon still judges what it is handed on its own, exactly as it judges what its own
subscriber delivers (:class:`offboard.daemon.zenoh.link.SwarmBus`): its inbound faults, its
decode, its guard and its drop counts. So a forged or malformed payload is counted and
dropped by every daemon that subscribed to its key, as before. Only the queueing and the
copy are shared.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import zenoh

# (payload bytes, key expression) -> None; the key is only read to say what was dropped
Handler = Callable[[bytes, Any], None]
# what a channel read or an undeclare raises once the subscriber or session is gone
ZENOH_ERRORS: tuple[type[Exception], ...] = (zenoh.ZError, RuntimeError)


class InboundFaults(Protocol):
    def drop_inbound(self) -> bool: ...


class Subscriber(Protocol):
    """Who subscribes: its injected inbound faults, None without a fault plan."""

    @property
    def faults(self) -> InboundFaults | None: ...


class SharedSubscriptions:
    """One Zenoh subscriber (a FIFO channel of ``depth``) per key expression, for every
    daemon of a process; each payload is handed to the key's subscribers in turn."""

    def __init__(self, session: Any, depth: int) -> None:
        self.session = session
        self.depth = depth
        self._keys: dict[str, tuple[Any, list[tuple[Subscriber, Handler]]]] = {}

    def keys(self) -> list[str]:
        """The key expressions the process subscribes to (one Zenoh subscriber each)."""
        return list(self._keys)

    def add(self, key: str, owner: Subscriber, handler: Handler) -> None:
        """Hand ``owner``'s ``handler`` every payload on ``key`` from now on (the first
        subscriber to a key declares its Zenoh subscriber)."""
        got = self._keys.get(key)
        if got is None:
            sub = self.session.declare_subscriber(key, zenoh.handlers.FifoChannel(self.depth))
            got = self._keys[key] = (sub, [])
        got[1].append((owner, handler))

    def remove(self, owner: Subscriber, keys: list[str] | None = None) -> list[Any]:
        """Stop handing ``owner`` the payloads of ``keys`` (None: of every key). Returns
        the Zenoh subscribers nobody uses any more, for the caller to undeclare."""
        unused = []
        for key in list(self._keys) if keys is None else keys:
            got = self._keys.get(key)
            if got is None:
                continue
            sub, entries = got
            entries[:] = [(o, h) for o, h in entries if o is not owner]
            if not entries:
                del self._keys[key]
                unused.append(sub)
        return unused

    def pump(self) -> int:
        """Hand out every payload waiting in the channels; returns how many payloads."""
        n = 0
        for sub, entries in list(self._keys.values()):
            while True:
                try:
                    sample = sub.try_recv()
                except ZENOH_ERRORS:  # undeclared / session closed: nothing more to read
                    break
                if sample is None:
                    break
                data = sample.payload.to_bytes()
                for owner, handler in entries:
                    if owner.faults is not None and owner.faults.drop_inbound():
                        continue
                    handler(data, sample.key_expr)
                n += 1
        return n
