"""Checks of hand-written TOML tables that are not schema sections (``[mission]``,
``[[obstacle]]``, ``[geofence]``): each refusal is one line naming the key and what is
allowed, raised as the caller's error class, e.g.::

    obstacle[2].radius_m = nan: must be a number in (0, 1000]

Kept apart from :mod:`swarm_common.scenario.schema` so that the scenario loader may import
the rooms that use it without a cycle.
"""

from __future__ import annotations

import math
from typing import Any

Range = tuple[float, float, bool, bool]  # lo, hi, lo_open, hi_open


def show(value: object, limit: int = 40) -> str:
    """``repr`` of a value, cut to ``limit`` characters (always one line)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


MAX_PLAIN_KEY = 64  # characters: a longer plain key is cut like any other (one short line)


def key_text(key: object) -> str:
    """A table key as it may appear in a message: plain names of at most
    :data:`MAX_PLAIN_KEY` characters as they are, others (a newline, 20 000 characters)
    quoted and cut by :func:`show`, so that the error line stays short."""
    if (isinstance(key, str) and key.replace("_", "a").isalnum() and key.isascii()
            and len(key) <= MAX_PLAIN_KEY):
        return key
    return show(str(key) if not isinstance(key, str) else key, 30)


def describe(rng: Range) -> str:
    lo, hi, lo_open, hi_open = rng
    return f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def as_float(value: object) -> float | None:
    """``value`` as a finite float, or None (bools, non-numbers, NaN, inf, huge ints)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        out = float(value)
    except OverflowError:
        return None
    return out if math.isfinite(out) else None


def in_range(x: float, rng: Range) -> bool:
    lo, hi, lo_open, hi_open = rng
    return (x > lo if lo_open else x >= lo) and (x < hi if hi_open else x <= hi)


def number(value: object, where: str, rng: Range, err: type[ValueError]) -> float:
    """``value`` as a float in ``rng``, else ``err`` naming ``where``."""
    x = as_float(value)
    if x is None or not in_range(x, rng):
        raise err(f"{where} = {show(value)}: must be {describe(rng)}")
    return x


def vector(value: object, where: str, n: int, rng: Range,
           err: type[ValueError]) -> tuple[float, ...]:
    """``value`` as ``n`` floats in ``rng``, else ``err`` naming ``where``."""
    lo, hi, _, _ = rng
    rule = f"a list of {n} numbers in [{lo:g}, {hi:g}]"
    if not isinstance(value, list | tuple) or len(value) != n:
        raise err(f"{where} = {show(value)}: must be {rule}")
    xs = [as_float(v) for v in value]
    if any(x is None or not in_range(x, rng) for x in xs):
        raise err(f"{where} = {show(value)}: must be {rule}")
    return tuple(float(x) for x in xs if x is not None)


def check_keys(table: dict[Any, Any], where: str, allowed: tuple[str, ...],
               err: type[ValueError]) -> None:
    """``err`` for the first key of ``table`` not in ``allowed``."""
    for key in table:
        if key not in allowed:
            raise err(f"unknown key {where}.{key_text(key)}; allowed: {', '.join(allowed)}")
