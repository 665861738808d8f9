"""swarm_common.signing: key files and pymavlink signing setup (no sockets)."""

from __future__ import annotations

import os
import stat

import pytest
from pymavlink.dialects.v20 import common as M

from gcs.cli import main as gcs_main
from swarm_common import signing
from swarm_common.signing import SigningKeyError, generate_key, load_key, setup_signing


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_generate_then_load(tmp_path):
    path = tmp_path / "keys" / "swarm.key"
    key = generate_key(path)
    assert len(key) == signing.KEY_BYTES
    assert _mode(path) == 0o600 and _mode(path.parent) == 0o700
    assert load_key(path) == key
    assert key.hex() not in str(sorted(os.listdir(path.parent)))  # no temp file left


def test_generate_refuses_existing_unless_asked(tmp_path):
    path = tmp_path / "swarm.key"
    first = generate_key(path)
    with pytest.raises(SigningKeyError, match="already exists"):
        generate_key(path)
    assert load_key(path) == first
    second = generate_key(path, overwrite=True)
    assert second != first and load_key(path) == second and _mode(path) == 0o600


@pytest.mark.parametrize("mode", [0o644, 0o640, 0o604, 0o660])
def test_load_refuses_group_or_world_readable(tmp_path, mode):
    path = tmp_path / "swarm.key"
    key = generate_key(path)
    os.chmod(path, mode)
    with pytest.raises(SigningKeyError, match="chmod 600") as exc:
        load_key(path)
    assert key.hex() not in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("content", [b"", b"00" * 31 + b"\n", b"zz" * 32 + b"\n", b"\x00" * 32])
def test_load_refuses_bad_content(tmp_path, content):
    path = tmp_path / "bad.key"
    path.write_bytes(content)
    os.chmod(path, 0o600)
    with pytest.raises(SigningKeyError, match="does not hold a key"):
        load_key(path)


def test_load_refuses_missing_dir_and_fifo(tmp_path):
    with pytest.raises(SigningKeyError, match="cannot open"):
        load_key(tmp_path / "missing.key")
    with pytest.raises(SigningKeyError, match="not a regular file"):
        load_key(tmp_path)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo, 0o600)
    with pytest.raises(SigningKeyError, match="not a regular file"):
        load_key(fifo)


def _pair(key_a: bytes, key_b: bytes) -> tuple[M.MAVLink, M.MAVLink]:
    a = M.MAVLink(None, srcSystem=255, srcComponent=190)
    b = M.MAVLink(None, srcSystem=1, srcComponent=1)
    b.robust_parsing = True
    setup_signing(a, key_a, 1)
    setup_signing(b, key_b, 2)
    return a, b


def _hb(mav: M.MAVLink) -> bytes:
    return mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav)


def test_signed_frames_pass_and_rejections_say_why():
    key = bytes(range(32))
    a, b = _pair(key, key)
    frame = _hb(a)
    (m,) = b.parse_buffer(frame)
    assert m.get_type() == "HEARTBEAT" and m.get_signed()
    (rep,) = b.parse_buffer(frame)  # the same frame again: replay
    assert rep.get_msgId() < 0 and rep.reason.endswith(signing.REJECT_REPLAY)
    plain = M.MAVLink(None, srcSystem=77, srcComponent=1)
    (uns,) = b.parse_buffer(_hb(plain))
    assert uns.get_msgId() < 0 and uns.reason.endswith(signing.REJECT_UNSIGNED)
    wrong, _ = _pair(bytes(32), key)
    (bad,) = b.parse_buffer(_hb(wrong))
    assert bad.get_msgId() < 0 and bad.reason.endswith(signing.REJECT_BAD_SIGNATURE)


def test_forged_future_timestamp_does_not_lock_out_a_stream():
    key = bytes(range(32))
    a, b = _pair(key, key)
    forged = bytearray(_hb(a))
    forged[-12:-6] = b"\xff" * 6  # far-future timestamp, signature now wrong
    (m,) = b.parse_buffer(bytes(forged))
    assert m.get_msgId() < 0 and m.reason.endswith(signing.REJECT_BAD_SIGNATURE)
    (ok,) = b.parse_buffer(_hb(a))
    assert ok.get_type() == "HEARTBEAT"


def test_allow_unsigned_callback_and_outgoing_signature():
    key = bytes(range(32))
    b = M.MAVLink(None, srcSystem=1, srcComponent=1)
    b.robust_parsing = True
    setup_signing(b, key, 0, lambda _mav, mid: mid == M.MAVLINK_MSG_ID_HEARTBEAT)
    plain = M.MAVLink(None, srcSystem=77, srcComponent=1)
    (hb,) = b.parse_buffer(_hb(plain))
    assert hb.get_type() == "HEARTBEAT" and not hb.get_signed()
    cmd = plain.command_long_encode(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    (rej,) = b.parse_buffer(cmd.pack(plain))
    assert rej.get_msgId() < 0
    out = _hb(b)
    assert out[2] & signing.IFLAG_SIGNED  # outgoing frames carry a signature


@pytest.mark.parametrize("key,link_id", [(b"short", 0), (bytes(32), 256), (bytes(32), -1)])
def test_setup_refuses_bad_key_or_link_id(key, link_id):
    with pytest.raises(SigningKeyError):
        setup_signing(M.MAVLink(None, 1, 1), key, link_id)


def test_gcs_keys_generate(tmp_path, capsys):
    path = tmp_path / "k" / "swarm.key"
    assert gcs_main(["keys", "generate", "--out", str(path)]) == 0
    key = load_key(path)
    assert gcs_main(["keys", "generate", "--out", str(path)]) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and key.hex() not in err
    assert gcs_main(["keys", "generate", "--out", str(tmp_path)]) == 2
    assert load_key(path) == key
