"""MISSION_CURRENT with its plan ids, which pymavlink's ``common`` dialect (2.4.x) lacks.

PX4 tells every peer that a plan changed with MISSION_CURRENT's extension fields
``mission_id``, ``fence_id`` and ``rally_points_id`` (MAVLink common, id 42: a checksum of
the stored plan, 0 when none is stored or ids are not supported). The offboard daemon
downloads its vehicle's fence when ``fence_id`` changes (docs/world.md, "A fence uploaded
over MAVLink"). pymavlink 2.4.50 generates only ``seq``, ``total``, ``mission_state`` and
``mission_mode``, so:

* :class:`MissionCurrent` packs the whole message (the simulator sends it). Extensions
  do not enter CRC_EXTRA, so a decoder that knows fewer fields reads the same frame and
  drops the rest (pymavlink truncates a longer payload);
* :func:`fence_id_of` reads ``fence_id`` back from a decoded frame's bytes (the daemon),
  without replacing pymavlink's class for every decoder of the process.
"""

from __future__ import annotations

import struct
from typing import Any

from pymavlink.dialects.v20 import common as M

# wire order: seq (the only base field), then the extensions in their XML order
PAYLOAD = struct.Struct("<HHBBIII")
FENCE_ID_OFFSET = 10  # bytes into the payload
MAGIC_V2 = 0xFD
HEADER_V2 = 10  # bytes before a MAVLink 2 frame's payload


class MissionCurrent(M.MAVLink_mission_current_message):
    """MISSION_CURRENT with ``mission_id``, ``fence_id`` and ``rally_points_id``."""

    fieldnames = [*M.MAVLink_mission_current_message.fieldnames, "mission_id", "fence_id",
                  "rally_points_id"]

    def __init__(self, seq: int, total: int, mission_state: int, mission_mode: int,
                 mission_id: int = 0, fence_id: int = 0, rally_points_id: int = 0) -> None:
        super().__init__(seq, total, mission_state, mission_mode)
        self._fieldnames = self.fieldnames
        self.mission_id = mission_id
        self.fence_id = fence_id
        self.rally_points_id = rally_points_id

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = PAYLOAD.pack(self.seq, self.total, self.mission_state, self.mission_mode,
                               self.mission_id, self.fence_id, self.rally_points_id)
        return bytes(self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1))


def fence_id_of(msg: Any) -> int:
    """The ``fence_id`` of a decoded MISSION_CURRENT: its field when the decoder knows it,
    else from the frame's payload (MAVLink 2 trims trailing zero bytes: what is missing is
    0). A MAVLink 1 frame carries no extensions: 0."""
    known = getattr(msg, "fence_id", None)
    if known is not None:
        return int(known)
    buf = bytes(msg.get_msgbuf())
    if len(buf) < HEADER_V2 or buf[0] != MAGIC_V2:
        return 0
    payload = buf[HEADER_V2 : HEADER_V2 + buf[1]].ljust(PAYLOAD.size, b"\0")
    return int(struct.unpack_from("<I", payload, FENCE_ID_OFFSET)[0])
