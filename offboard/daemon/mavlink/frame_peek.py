"""Frames the daemon does not read, told from their headers alone (docs/performance.md).

A vehicle streams telemetry the daemon never reads: PX4's default streams (PX4 ignores
the stop request of :mod:`offboard.daemon.mavlink.stream_trim`), every stream until that request
takes
effect, and the backlog that fills a daemon's socket before its link locks (a process
packing 32 agents opens 32 sockets, then waits for each link in turn). pymavlink decoded
and signature-checked each such frame before the daemon dropped it: about 30 µs a
frame, and most of a packed process's start-up in a profile.

:func:`unread_frames` walks the MAVLink frames of one UDP datagram by their headers
(v2: magic 0xFD, payload length, incompatibility flags, sequence, system, component,
24-bit message id; v1: magic 0xFE, length, sequence, system, component, 8-bit id).
When the datagram is made of whole frames of known messages, none of which the daemon
reads, it returns each frame's (system, component, message name) and the caller drops
them without decoding. Anything else (a message it reads, an unknown id, unknown
incompatibility flags, a truncated or stray byte) returns None, and pymavlink judges the
datagram as before. Frames dropped here are not checked: a corrupted or badly signed
frame of an unread kind is counted as unread, where the full parse counted it as bad
data or a bad signature. It is dropped either way, and signing still guards every frame
the daemon acts on.
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.mavlink.stream_trim import READ_KINDS  # noqa: E402

M = mavutil.mavlink
MAGIC_V2 = 0xFD  # MAVLink 2 start byte
MAGIC_V1 = 0xFE  # MAVLink 1 start byte
HEADER_V2, HEADER_V1 = 10, 6  # bytes before the payload
CRC_LEN, SIGNATURE_LEN = 2, 13
# message id -> name, for the messages of the dialect the daemon does not read
UNREAD_NAMES: dict[int, str] = {
    msgid: cls.msgname for msgid, cls in M.mavlink_map.items() if cls.msgname not in READ_KINDS
}


def unread_frames(data: bytes) -> list[tuple[int, int, str]] | None:
    """[(system id, component id, message name)] of every frame of ``data`` if it holds
    whole frames only, all of known messages the daemon does not read; else None."""
    out: list[tuple[int, int, str]] = []
    i, n = 0, len(data)
    while i < n:
        magic = data[i]
        if magic == MAGIC_V2:
            if i + HEADER_V2 > n:
                return None
            flags = data[i + 2]
            if flags & ~M.MAVLINK_IFLAG_SIGNED:
                return None
            length = HEADER_V2 + data[i + 1] + CRC_LEN
            if flags & M.MAVLINK_IFLAG_SIGNED:
                length += SIGNATURE_LEN
            sysid, compid = data[i + 5], data[i + 6]
            msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
        elif magic == MAGIC_V1:
            if i + HEADER_V1 > n:
                return None
            length = HEADER_V1 + data[i + 1] + CRC_LEN
            sysid, compid, msgid = data[i + 3], data[i + 4], data[i + 5]
        else:
            return None
        name = UNREAD_NAMES.get(msgid)
        if name is None or i + length > n:
            return None
        out.append((sysid, compid, name))
        i += length
    return out
