"""Results computed once per object in a process: every agent of one scenario or formation
(the in-process runner, a packed daemon) shares what depends on that object alone.

Keyed by the object's identity plus the parameters of the computation. An entry holds the
object itself, so its id cannot be reused by another object while the entry lives; the
objects memoised here (``Scenario``, ``Formation``) are not changed after they are built.
The memo keeps at most ``size`` entries (a process builds the agents of one or two).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

R = TypeVar("R")


class IdentityMemo(Generic[R]):
    """``get(obj, params, compute)``: ``compute()`` once per (obj, params)."""

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self._got: dict[tuple[int, Hashable], tuple[object, R]] = {}

    def get(self, obj: object, params: Hashable, compute: Callable[[], R]) -> R:
        key = (id(obj), params)
        hit = self._got.get(key)
        if hit is not None and hit[0] is obj:
            return hit[1]
        value = compute()
        if len(self._got) >= self.size:
            del self._got[next(iter(self._got))]
        self._got[key] = (obj, value)
        return value


class ContentMemo(Generic[R]):
    """``get(key, compute)``: ``compute()`` once per hashable ``key`` that names the
    computation's whole input by content (a digest and parameters), so equal inputs built
    as different objects share one result (the runs of a sweep). Bounded like
    :class:`IdentityMemo`: at most ``size`` entries, the oldest dropped first."""

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self._got: dict[Hashable, R] = {}

    def get(self, key: Hashable, compute: Callable[[], R]) -> R:
        if key in self._got:
            return self._got[key]
        value = compute()
        if len(self._got) >= self.size:
            del self._got[next(iter(self._got))]
        self._got[key] = value
        return value
