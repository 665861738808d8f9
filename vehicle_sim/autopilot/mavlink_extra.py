"""MAVLink messages that pymavlink's ``common`` dialect (2.4.x) does not generate.

PROTOCOL_VERSION (id 300, defined in MAVLink's ``standard``/``minimal`` set) is the
answer to MAV_CMD_REQUEST_PROTOCOL_VERSION that MAVSDK and QGroundControl send on
connect. The class below packs and decodes it exactly like a generated pymavlink class;
:func:`register` adds it to pymavlink's decoder table so a pymavlink client can read it.
The CRC extra byte is computed from the field list the way ``mavgen`` does
(:func:`crc_extra`), not copied as a literal.
"""

from __future__ import annotations

import struct
from typing import Any

from pymavlink.dialects.v20 import common as M
from pymavlink.generator.mavcrc import x25crc

MAVLINK_MSG_ID_PROTOCOL_VERSION = 300
HASH_LEN = 8  # spec_version_hash and library_version_hash: uint8_t[8]
# (C type, name, array length or 0) in wire order (largest type first, stable)
_WIRE_FIELDS = (
    ("uint16_t", "version", 0),
    ("uint16_t", "min_version", 0),
    ("uint16_t", "max_version", 0),
    ("uint8_t", "spec_version_hash", HASH_LEN),
    ("uint8_t", "library_version_hash", HASH_LEN),
)


def crc_extra(name: str, wire_fields: tuple[tuple[str, str, int], ...]) -> int:
    """The MAVLink CRC_EXTRA seed of a message: X.25 CRC over its name and wire-ordered
    fields (``type name `` and, for an array, one byte of its length), folded to 8 bits."""
    text = bytearray(f"{name} ".encode())
    for ctype, fname, n in wire_fields:
        text += f"{ctype} {fname} ".encode()
        if n:
            text.append(n)
    crc = x25crc(bytes(text)).crc
    return (crc & 0xFF) ^ (crc >> 8)


class MAVLink_protocol_version_message(M.MAVLink_message):  # noqa: N801 - pymavlink naming
    """PROTOCOL_VERSION: MAVLink versions × 100 (v2 = 200) and two 8-byte git hashes."""

    id = MAVLINK_MSG_ID_PROTOCOL_VERSION
    msgname = "PROTOCOL_VERSION"
    fieldnames = [f for _, f, _ in _WIRE_FIELDS]
    ordered_fieldnames = list(fieldnames)
    fieldtypes = [t for t, _, _ in _WIRE_FIELDS]
    fielddisplays_by_name: dict[str, str] = {}
    fieldenums_by_name: dict[str, str] = {}
    fieldunits_by_name: dict[str, str] = {}
    native_format = bytearray(b"<HHHBB")
    orders = [0, 1, 2, 3, 4]
    lengths = [1, 1, 1, HASH_LEN, HASH_LEN]
    array_lengths = [0, 0, 0, HASH_LEN, HASH_LEN]
    crc_extra = crc_extra("PROTOCOL_VERSION", _WIRE_FIELDS)
    unpacker = struct.Struct(f"<HHH{HASH_LEN}B{HASH_LEN}B")
    instance_field = None
    instance_offset = -1

    def __init__(
        self,
        version: int,
        min_version: int,
        max_version: int,
        spec_version_hash: Any,
        library_version_hash: Any,
    ) -> None:
        M.MAVLink_message.__init__(self, self.id, self.msgname)
        self._fieldnames = self.fieldnames
        self._instance_field = self.instance_field
        self._instance_offset = self.instance_offset
        self.version = version
        self.min_version = min_version
        self.max_version = max_version
        self.spec_version_hash = spec_version_hash
        self.library_version_hash = library_version_hash

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(
            self.version, self.min_version, self.max_version,
            *self.spec_version_hash[:HASH_LEN], *self.library_version_hash[:HASH_LEN],
        )  # fmt: skip
        return bytes(self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1))


def register(dialect: Any = M) -> None:
    """Let a pymavlink dialect module's decoder (every ``MAVLink`` object of this process
    built from it; ``mavutil`` connections use ``mavutil.mavlink``) read this module's
    messages."""
    dialect.mavlink_map[MAVLINK_MSG_ID_PROTOCOL_VERSION] = MAVLink_protocol_version_message
