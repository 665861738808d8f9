"""CDR bodies of the record's ROS 2 messages (:mod:`gcs.records.topics` field lists), built
for every step at once from the series arrays (no I/O): a packed numpy record array per
message kind whose rows are the messages, so a 60 s run's tens of thousands of messages
cost milliseconds.

Layout (OMG CDR, little endian, as ROS 2 writes it): the 4-byte encapsulation header
``00 01 00 00`` then the fields in order; fixed-size arrays have no length prefix. The
fields are ordered so that none needs padding (the float64s first; checked:
:func:`layout`). Floats are the series' doubles bit for bit (NaN/inf included).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping, Sequence

import numpy as np

CDR_LE = b"\x00\x01\x00\x00"  # encapsulation: plain CDR, little endian
_TYPES = {"float64": "<f8", "bool": "u1", "uint8": "u1", "uint16": "<u2"}
_ARRAY = re.compile(r"^(\w+)(?:\[(\d+)\])?$")


@functools.lru_cache(maxsize=64)  # a few field lists, each asked for at every step live
def layout(fields: Sequence[tuple[str, str, str]]) -> np.dtype:
    """The packed numpy dtype of a message of ``fields`` (name, ROS type, comment), header
    first; ``ValueError`` when a field would need padding (CDR aligns each to its own size
    from the end of the header: a float64 after a 1-byte field, say) or a type is not one
    of float64, bool, uint8, uint16 (fixed arrays allowed)."""
    parts: list[tuple[str, str, tuple[int, ...]]] = [("_cdr", "u1", (4,))]
    offset = 0
    for name, typ, _ in fields:
        m = _ARRAY.match(typ)
        if m is None or m.group(1) not in _TYPES:
            raise ValueError(f"field {name}: type {typ!r} not supported")
        base = _TYPES[m.group(1)]
        size = np.dtype(base).itemsize
        if offset % size:
            raise ValueError(f"field {name}: a {m.group(1)} at offset {offset} needs padding")
        count = int(m.group(2)) if m.group(2) else 1
        offset += size * count
        parts.append((name, base, (int(m.group(2)),) if m.group(2) else ()))
    return np.dtype(parts)


def cdr_rows(fields: Sequence[tuple[str, str, str]], values: Mapping[str, np.ndarray],
             k: int) -> list[bytes]:
    """The ``k`` messages of ``fields``: ``values[name]`` (k,) or (k, n) per field."""
    dt = layout(fields)
    arr = np.zeros(k, dt)
    arr["_cdr"] = np.frombuffer(CDR_LE, np.uint8)
    for name, _, _ in fields:
        arr[name] = values[name]
    buf = arr.tobytes()
    size = dt.itemsize
    return [buf[r * size:(r + 1) * size] for r in range(k)]
