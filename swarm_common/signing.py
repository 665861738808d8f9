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

Replay rules (MAVLink 2 signing, docs/security.md "Replayed and reflected frames"), in this
order after the signature verified:

* **reflected** (:data:`REJECT_REFLECTED`): a frame that claims the receiver's own
  (system id, component id), or whose stream a :class:`StreamLedger` given to
  :func:`setup_signing` says this process emits itself (an identity it signs as, or a
  stream it forwarded, up to the highest timestamp forwarded). A frame the receiver (or
  its process) sent never comes back in.
* **replay** (:data:`REJECT_REPLAY`): a (link id, system id, component id) stream's
  timestamp must be strictly greater than the last one accepted on that stream; the first
  frame of a new stream must be at most :data:`REPLAY_WINDOW_S` (60 s) older than the
  receiver's own timestamp.

The receiver's (and sender's) own timestamp follows the wall clock: after
:func:`setup_signing` ``mav.signing.timestamp`` reads as the larger of the last value
stored and the current time (pymavlink only counts it up by one per signed frame, so a
long-running sender's timestamps would fall behind the clock and a stale receiver clock
would widen the replay window).
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
REPLAY_WINDOW_S = 60  # s: a new stream may lag the receiver's clock by this much (spec)
NEW_STREAM_MAX_BEHIND = REPLAY_WINDOW_S * TIMESTAMP_UNITS_PER_S  # the same, 10 µs units
REJECT_UNSIGNED = "unsigned"
REJECT_BAD_SIGNATURE = "bad_signature"
REJECT_REPLAY = "replay"  # a valid signature with an old timestamp (replayed frame)
REJECT_REFLECTED = "reflected"  # a valid signature on a frame the receiver's side sent
REJECT_REASONS = (REJECT_UNSIGNED, REJECT_BAD_SIGNATURE, REJECT_REPLAY, REJECT_REFLECTED)
REPLAY_REASONS = (REJECT_REPLAY, REJECT_REFLECTED)  # both are counted as replays
INVALID_SIGNATURE_REASON = "Invalid signature"  # BAD_DATA.reason prefix of a rejected frame
V2_MARKER = 0xFD
IFLAG_SIGNED = 0x01
SIGNATURE_LEN = 13  # link id (1) + timestamp (6) + signature (6) bytes

AllowUnsignedCallback = Callable[[Any, int], bool]
StreamKey = tuple[int, int, int]  # (link id, system id, component id)


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


def key_file(text: str) -> str:
    """argparse ``type=`` of a ``--signing-key`` option: the path, once :func:`load_key`
    takes it, so a bad key file is refused (one line, exit 2) as the flags are parsed,
    before the command loads anything heavy. The command loads the key again later."""
    import argparse

    try:
        load_key(text)
    except SigningKeyError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


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


class StreamLedger:
    """The signed streams one process emits, for its receivers to refuse them coming back.

    ``identities``: the (system id, component id) pairs the process signs as (reference
    counted: several links may share one); ``forwarded``: per (link id, system id,
    component id) stream, the highest timestamp (10 µs units) of a frame the process
    forwarded on. A frame of an identity, or of a forwarded stream up to that timestamp,
    arriving at a receiver that uses the ledger is a reflection.
    """

    def __init__(self) -> None:
        self._identities: dict[tuple[int, int], int] = {}
        self._forwarded: dict[StreamKey, int] = {}

    def add_identity(self, sysid: int, compid: int) -> None:
        key = (int(sysid), int(compid))
        self._identities[key] = self._identities.get(key, 0) + 1

    def remove_identity(self, sysid: int, compid: int) -> None:
        key = (int(sysid), int(compid))
        n = self._identities.get(key, 0) - 1
        if n > 0:
            self._identities[key] = n
        else:
            self._identities.pop(key, None)

    def note_forwarded(self, frame: bytes | bytearray) -> None:
        """Record a signed MAVLink 2 frame this process forwards (anything else: ignored)."""
        got = frame_stream(frame)
        if got is not None:
            key, ts = got
            self._forwarded[key] = max(ts, self._forwarded.get(key, -1))

    def reflected(self, key: StreamKey, timestamp: int) -> bool:
        """Whether a verified frame of stream ``key`` at ``timestamp`` is one this process
        emitted."""
        if (key[1], key[2]) in self._identities:
            return True
        return timestamp <= self._forwarded.get(key, -1)


def frame_stream(frame: bytes | bytearray) -> tuple[StreamKey, int] | None:
    """((link id, system id, component id), timestamp) of one whole signed MAVLink 2 frame;
    None for anything else (MAVLink 1, unsigned, too short)."""
    if len(frame) < 10 + 2 + SIGNATURE_LEN or frame[0] != V2_MARKER:
        return None
    if not frame[2] & IFLAG_SIGNED or len(frame) != 10 + frame[1] + 2 + SIGNATURE_LEN:
        return None
    tlow, thigh = struct.unpack("<IH", bytes(frame[-12:-6]))
    return (frame[-13], frame[5], frame[6]), tlow + (thigh << 32)


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
    ledger: StreamLedger | None = getattr(signing, "ledger", None)
    if (src_system, src_component) == (mav.srcSystem, mav.srcComponent) or (
        ledger is not None and ledger.reflected(stream_key, timestamp)
    ):
        signing.last_reject = REJECT_REFLECTED
        return False
    last = signing.stream_timestamps.get(stream_key)
    if last is not None and timestamp <= last:
        signing.last_reject = REJECT_REPLAY
        return False
    now = signing.timestamp  # the wall clock at least (_clock_timestamps)
    if last is None and timestamp + NEW_STREAM_MAX_BEHIND < now:
        signing.last_reject = REJECT_REPLAY
        return False
    signing.stream_timestamps[stream_key] = timestamp
    signing.timestamp = max(now, timestamp)
    signing.last_reject = ""
    return True


_CLOCKED_CLASSES: dict[type, type] = {}


def _get_timestamp(self: Any) -> int:
    return max(int(self.__dict__.get("_stored_timestamp", 0)), _timestamp_now())


def _set_timestamp(self: Any, value: int) -> None:
    self.__dict__["_stored_timestamp"] = int(value)


def _clock_timestamps(signing_state: Any) -> None:
    """Make ``signing_state.timestamp`` read as max(stored value, wall clock now) (10 µs
    units); pymavlink's ``timestamp += 1`` per signed frame then keeps it strictly
    increasing. The object's class becomes a subclass of its own with that property."""
    base = type(signing_state)
    if getattr(base, "_wall_clock_timestamps", False):
        return
    cls = _CLOCKED_CLASSES.get(base)
    if cls is None:
        cls = type(
            f"WallClock{base.__name__}",
            (base,),
            {"timestamp": property(_get_timestamp, _set_timestamp), "_wall_clock_timestamps": True},
        )
        _CLOCKED_CLASSES[base] = cls
    stored = int(signing_state.__dict__.pop("timestamp", 0) or 0)
    signing_state.__class__ = cls
    signing_state.timestamp = stored


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
    ledger: StreamLedger | None = None,
) -> None:
    """Sign every outgoing frame of ``mav`` and verify every incoming one with ``key``.

    ``link_id`` (0–255) tells this link's streams apart for receivers; the outgoing
    timestamp follows the wall clock (never below it, strictly increasing per frame).
    ``allow_unsigned_cb(mav, msg_id)`` may accept a frame that is unsigned or fails
    verification (``None``: reject all such frames). Incoming frames claiming ``mav``'s own
    (system id, component id) are rejected as reflected, and so are the streams
    ``ledger`` (the receiver's process) emits.
    """
    if not isinstance(key, bytes | bytearray) or len(key) != KEY_BYTES:
        raise SigningKeyError(f"a signing key must be {KEY_BYTES} bytes")
    if not 0 <= int(link_id) <= 255:
        raise SigningKeyError(f"signing link id {link_id} is not in [0, 255]")
    s = mav.signing
    s.secret_key = bytes(key)
    s.sign_outgoing = True
    s.link_id = int(link_id)
    _clock_timestamps(s)
    s.timestamp = max(int(s.timestamp or 0), _timestamp_now())
    s.allow_unsigned_callback = allow_unsigned_cb
    s.ledger = ledger
    s.last_reject = ""
    mav.check_signature = types.MethodType(_check_signature, mav)
    _wrap_decode(mav)
