"""MAVLink 2 message signing: the key file and the signing setup of one pymavlink link.

The key file holds one 32-byte secret key written as 64 hexadecimal digits and a newline.
It must be a regular file readable by its owner only (mode 0600); :func:`load_key`
refuses anything else with one :class:`SigningKeyError` line. Keys never appear in log
records or error messages.

:func:`setup_signing` turns signing on for one ``pymavlink`` ``MAVLink`` object: every
outgoing frame is signed, every incoming frame must carry a valid signature (HMAC
SHA-256 truncated to 48 bits over key + frame, MAVLink 2 signing) or pass the optional
``allow_unsigned_cb(mav, msg_id)``. A rejected frame comes out of the parser as
``BAD_DATA`` whose reason is ``"Invalid signature: <why>"``, ``<why>`` one of
``REJECT_*`` (unsigned, bad signature, replayed timestamp).

Departure from pymavlink's own check: pymavlink records a stream's timestamp *before* it
checks the signature, so one forged frame with a far-future timestamp and a victim's
(link id, system id, component id) locks that victim out. Here the signature is checked
first and a stream's timestamp only advances on a frame that verified.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
import struct
import sys
import time
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

KEY_BYTES = 32
KEY_FILE_MODE = 0o600
KEY_DIR_MODE = 0o700
KEY_FILE_MAX_BYTES = 4096  # a key file is 65 bytes; anything much larger is not one
SIGNATURE_EPOCH_UNIX_S = 1420070400  # MAVLink signing timestamps count from 2015-01-01
TIMESTAMP_UNITS_PER_S = 100_000  # 10 µs units
NEW_STREAM_MAX_BEHIND = 60 * TIMESTAMP_UNITS_PER_S  # a new stream may lag us by 1 minute
REJECT_UNSIGNED = "unsigned"
REJECT_BAD_SIGNATURE = "bad_signature"
REJECT_REPLAY = "replay"  # a valid signature with an old timestamp (replayed frame)
REJECT_REASONS = (REJECT_UNSIGNED, REJECT_BAD_SIGNATURE, REJECT_REPLAY)
INVALID_SIGNATURE_REASON = "Invalid signature"  # BAD_DATA.reason prefix of a rejected frame
V2_MARKER = 0xFD
IFLAG_SIGNED = 0x01

AllowUnsignedCallback = Callable[[Any, int], bool]


class SigningKeyError(ValueError):
    """A key file or key that cannot be used (one line, never containing the key)."""


def _timestamp_now() -> int:
    """The current MAVLink signing timestamp (10 µs units since 2015-01-01 UTC)."""
    return int(max(0.0, time.time() - SIGNATURE_EPOCH_UNIX_S) * TIMESTAMP_UNITS_PER_S)


def generate_key(path: str | os.PathLike[str], overwrite: bool = False) -> bytes:
    """Write a fresh random key to ``path`` (mode 0600) and return it.

    The parent directory is created with mode 0700 if missing. An existing file is
    refused unless ``overwrite``; then the new key replaces it atomically.
    """
    p = Path(path)
    if p.exists() and not overwrite:
        raise SigningKeyError(f"key file {p} already exists (refusing to overwrite)")
    if p.exists() and not p.is_file():
        raise SigningKeyError(f"key path {p} exists and is not a regular file")
    parent = p.parent
    try:
        if not parent.exists():
            parent.mkdir(mode=KEY_DIR_MODE, parents=True)
            os.chmod(parent, KEY_DIR_MODE)  # mkdir's mode is masked by the umask
        elif not parent.is_dir():
            raise SigningKeyError(f"key directory {parent} is not a directory")
        key = secrets.token_bytes(KEY_BYTES)
        tmp = parent / f".{p.name}.{os.getpid()}.tmp"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, KEY_FILE_MODE)
        try:
            os.fchmod(fd, KEY_FILE_MODE)
            os.write(fd, (key.hex() + "\n").encode("ascii"))
            os.fsync(fd)
        finally:
            os.close(fd)
        if overwrite:
            os.replace(tmp, p)
        else:
            try:
                os.link(tmp, p)  # fails if p appeared meanwhile: never clobber
            finally:
                os.unlink(tmp)
    except FileExistsError:
        raise SigningKeyError(f"key file {p} already exists (refusing to overwrite)") from None
    except OSError as exc:
        raise SigningKeyError(f"cannot write key file {p}: {exc.strerror}") from None
    return key


def load_key(path: str | os.PathLike[str]) -> bytes:
    """Read and validate a key file: a regular file, mode without group/other bits,
    64 hexadecimal digits (a trailing newline allowed). Returns the 32 key bytes."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise SigningKeyError(f"cannot open key file {p}: {exc.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise SigningKeyError(f"key file {p} is not a regular file")
        if st.st_mode & 0o077:
            raise SigningKeyError(
                f"key file {p} has mode {stat.S_IMODE(st.st_mode):04o}: it must not be "
                f"readable by group or others (chmod 600 {p})"
            )
        if st.st_size > KEY_FILE_MAX_BYTES:
            raise SigningKeyError(f"key file {p} is too large to be a key file")
        raw = os.read(fd, KEY_FILE_MAX_BYTES + 1)
    except OSError as exc:
        raise SigningKeyError(f"cannot read key file {p}: {exc.strerror}") from None
    finally:
        os.close(fd)
    text = raw.rstrip(b"\r\n")
    want = 2 * KEY_BYTES
    if len(text) != want or any(c not in b"0123456789abcdefABCDEF" for c in text):
        raise SigningKeyError(f"key file {p} does not hold a key ({want} hexadecimal digits)")
    return bytes.fromhex(text.decode("ascii"))


def _check_signature(mav: Any, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
    """Signature first, then the replay window; only a verified frame advances state."""
    signing = mav.signing
    key = signing.secret_key
    expect = hashlib.sha256(bytes(key) + bytes(msgbuf[:-6])).digest()[:6]
    if not hmac.compare_digest(expect, bytes(msgbuf[-6:])):
        signing.last_reject = REJECT_BAD_SIGNATURE
        return False
    link_id = msgbuf[-13]
    tlow, thigh = struct.unpack("<IH", bytes(msgbuf[-12:-6]))
    timestamp = tlow + (thigh << 32)
    stream_key = (link_id, src_system, src_component)
    last = signing.stream_timestamps.get(stream_key)
    if last is not None and timestamp <= last:
        signing.last_reject = REJECT_REPLAY
        return False
    if last is None and timestamp + NEW_STREAM_MAX_BEHIND < signing.timestamp:
        signing.last_reject = REJECT_REPLAY
        return False
    signing.stream_timestamps[stream_key] = timestamp
    signing.timestamp = max(signing.timestamp, timestamp)
    signing.last_reject = ""
    return True


def _wrap_decode(mav: Any) -> None:
    """Make a signature rejection say why: the parser's ``BAD_DATA.reason`` becomes
    ``"Invalid signature: <REJECT_*>"``."""
    if getattr(mav, "_signing_decode_wrapped", False):
        return
    plain_decode = mav.decode
    mav_error = sys.modules[type(mav).__module__].MAVError

    def decode(msgbuf: bytearray) -> Any:
        signed = len(msgbuf) > 2 and msgbuf[0] == V2_MARKER and bool(msgbuf[2] & IFLAG_SIGNED)
        mav.signing.last_reject = "" if signed else REJECT_UNSIGNED
        try:
            return plain_decode(msgbuf)
        except mav_error as exc:
            if exc.message == INVALID_SIGNATURE_REASON:
                raise mav_error(f"{INVALID_SIGNATURE_REASON}: {mav.signing.last_reject}") from None
            raise

    mav.decode = decode
    mav._signing_decode_wrapped = True


def setup_signing(
    mav: Any,
    key: bytes,
    link_id: int,
    allow_unsigned_cb: AllowUnsignedCallback | None = None,
) -> None:
    """Sign every outgoing frame of ``mav`` and verify every incoming one with ``key``.

    ``link_id`` (0–255) tells this link's streams apart for receivers; the outgoing
    timestamp starts at the current time. ``allow_unsigned_cb(mav, msg_id)`` may accept a
    frame that is unsigned or fails verification (``None``: reject all such frames).
    """
    if not isinstance(key, bytes | bytearray) or len(key) != KEY_BYTES:
        raise SigningKeyError(f"a signing key must be {KEY_BYTES} bytes")
    if not 0 <= int(link_id) <= 255:
        raise SigningKeyError(f"signing link id {link_id} is not in [0, 255]")
    s = mav.signing
    s.secret_key = bytes(key)
    s.sign_outgoing = True
    s.link_id = int(link_id)
    s.timestamp = max(int(s.timestamp or 0), _timestamp_now())
    s.allow_unsigned_callback = allow_unsigned_cb
    s.last_reject = ""
    mav.check_signature = types.MethodType(_check_signature, mav)
    _wrap_decode(mav)
