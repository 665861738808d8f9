"""offboard.daemon.mavlink.frame_peek: the unread frames of a datagram, from headers only, against
frames packed by pymavlink (v1, v2, signed) and what its parser makes of them."""

import os

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.mavlink.frame_peek import unread_frames  # noqa: E402
from offboard.daemon.mavlink.stream_trim import READ_KINDS  # noqa: E402
from swarm_common.signing import setup_signing  # noqa: E402

M = mavutil.mavlink
KEY = bytes(range(32))


def packer(sysid: int = 3, compid: int = 1, v1: bool = False, signed: bool = False):
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    if v1:
        mav.WIRE_PROTOCOL_VERSION = "1.0"
    if signed:
        setup_signing(mav, KEY, link_id=3)
    return mav


def frames(mav) -> dict[str, bytes]:
    """One packed frame of several messages, read and unread ones."""
    msgs = {
        "ATTITUDE": M.MAVLink_attitude_message(1, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0),
        "VFR_HUD": M.MAVLink_vfr_hud_message(1.0, 2.0, 90, 50, 3.0, 0.5),
        "SYS_STATUS": M.MAVLink_sys_status_message(*([0] * 13)),
        "HEARTBEAT": M.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3),
        "STATUSTEXT": M.MAVLink_statustext_message(6, b"hello"),
        "ODOMETRY": M.MAVLink_odometry_message(
            1, 1, 12, 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            [float("nan")] * 21, [float("nan")] * 21),
    }
    return {k: m.pack(mav) for k, m in msgs.items()}


def parsed(data: bytes) -> list[tuple[int, int, str]]:
    """What pymavlink's parser (unsigned-tolerant, no key) finds in ``data``."""
    mav = M.MAVLink(None)
    mav.robust_parsing = True
    out = mav.parse_buffer(data) or []
    return [(m.get_srcSystem(), m.get_srcComponent(), m.get_type()) for m in out]


@pytest.mark.parametrize("v1,signed", [(False, False), (False, True), (True, False)],
                         ids=["v2", "v2-signed", "v1"])
def test_unread_frames_match_the_parser(v1: bool, signed: bool) -> None:
    f = frames(packer(7, 1, v1=v1, signed=signed))
    unread = [k for k in f if k not in READ_KINDS]
    for k in unread:
        assert unread_frames(f[k]) == [(7, 1, k)]
        if not signed:  # (an unsigned parser drops signed frames it cannot check)
            assert parsed(f[k]) == [(7, 1, k)]
    several = b"".join(f[k] for k in unread)
    assert unread_frames(several) == [(7, 1, k) for k in unread]
    for k in READ_KINDS & f.keys():  # a message the daemon reads: the parser's turn
        assert unread_frames(f[k]) is None
        assert unread_frames(several + f[k]) is None
        assert unread_frames(f[k] + several) is None


def test_anything_unclear_goes_to_the_parser() -> None:
    f = frames(packer())
    att = f["ATTITUDE"]
    assert unread_frames(att[:-1]) is None  # truncated
    assert unread_frames(att[:5]) is None  # a header cut short
    assert unread_frames(att + b"\x00") is None  # a stray byte after the frame
    assert unread_frames(b"\x00" + att) is None  # no magic at the start
    flagged = bytearray(att)
    flagged[2] |= 0x02  # an incompatibility flag nobody knows
    assert unread_frames(bytes(flagged)) is None
    unknown = bytearray(att)
    unknown[7:10] = (0xFFFFF0).to_bytes(3, "little")  # no such message id
    assert unread_frames(bytes(unknown)) is None
    assert unread_frames(b"") == []


def test_foreign_systems_are_reported_as_sent() -> None:
    f = frames(packer(sysid=42, compid=190))
    assert unread_frames(f["VFR_HUD"]) == [(42, 190, "VFR_HUD")]
