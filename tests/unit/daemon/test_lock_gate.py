"""offboard.daemon.mavlink.lock_gate: with signing, the vehicle link's lock takes a frame
signed after the daemon's start (minus LOCK_CLOCK_TOLERANCE_S, against an injected wall
clock) and an address that echoed one of the daemon's TIMESYNC nonces. Frames packed by
pymavlink with chosen signing timestamps and verified by a receiver set up like the
daemon's link."""

import logging
import os
import time
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.link_guard import DropLog  # noqa: E402
from offboard.daemon.mavlink.lock_gate import (  # noqa: E402
    LOCK_CLOCK_TOLERANCE_S,
    NONCES_PER_ADDRESS,
    REPLAY_BEFORE_LOCK,
    UNPROVEN_ADDRESS,
    LockGate,
)
from swarm_common.signing import (  # noqa: E402
    SIGNATURE_EPOCH_UNIX_S,
    TIMESTAMP_UNITS_PER_S,
    setup_signing,
)

M = mavutil.mavlink
KEY = bytes(range(32))
AGENT = 3
VEHICLE = ("127.0.0.1", 14582)
STRANGER = ("127.0.0.1", 40000)
# the daemon's start on the fake clock, 10 s before each test (so that every frame stays
# inside the receiver's 60 s window for a new stream, however late the test runs after
# this module's import: set by the autouse fixture below)
START = 0.0


@pytest.fixture(autouse=True)
def _start_now() -> None:
    global START
    START = time.time() - 10.0


def stamp(wall_s: float) -> int:
    """The MAVLink signing timestamp of a wall-clock time (10 µs units since 2015)."""
    return int((wall_s - SIGNATURE_EPOCH_UNIX_S) * TIMESTAMP_UNITS_PER_S)


def signer(timestamp: int, link_id: int = 0, compid: int = 1) -> Any:
    """A vehicle-side packer whose next frame carries ``timestamp`` (pymavlink's own
    signing: it counts up by one per frame, from any value)."""
    mav = M.MAVLink(None, srcSystem=AGENT, srcComponent=compid)
    mav.signing.secret_key = KEY
    mav.signing.sign_outgoing = True
    mav.signing.link_id = link_id
    mav.signing.timestamp = timestamp
    return mav


def receiver() -> Any:
    mav = M.MAVLink(None, srcSystem=AGENT, srcComponent=M.MAV_COMP_ID_ONBOARD_COMPUTER)
    mav.robust_parsing = True  # a rejected frame comes out as BAD_DATA, as in the link
    setup_signing(mav, KEY, link_id=AGENT)
    return mav


def decoded(rx: Any, msg: Any, mav: Any) -> Any:
    """``msg`` packed by ``mav``, verified and decoded by ``rx`` (the daemon's side)."""
    out = rx.parse_buffer(bytes(msg.pack(mav))) or []
    assert len(out) == 1 and out[0].get_type() != "BAD_DATA", out
    return out[0]


def heartbeat() -> Any:
    return M.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)


def gate(signed: bool = True, challenge: bool = True) -> LockGate:
    return LockGate(AGENT, DropLog(f"agent {AGENT}: MAVLink"), signed, challenge,
                    wall=lambda: START)


def test_a_frame_signed_before_the_start_minus_the_tolerance_is_refused(caplog) -> None:
    caplog.set_level(logging.WARNING, logger="offboard.daemon.mavlink.lock_gate")
    g, rx = gate(), receiver()
    floor = stamp(START - LOCK_CLOCK_TOLERANCE_S)
    # one stream, increasing stamps (the signing layer's own rule): 10 units, then
    # 1 unit, below the floor, then exactly at it and after the start
    stale1 = decoded(rx, heartbeat(), signer(floor - 10))
    stale2 = decoded(rx, M.MAVLink_timesync_message(1, 2), signer(floor - 1))
    at_floor = decoded(rx, heartbeat(), signer(floor))
    after = decoded(rx, heartbeat(), signer(stamp(START + 1.0)))
    assert not g.fresh(stale1, STRANGER)
    assert not g.fresh(stale2, STRANGER)
    assert g.fresh(at_floor, VEHICLE) and g.fresh(after, VEHICLE)
    assert g.drops.counts == {REPLAY_BEFORE_LOCK: 2}
    warnings = [r for r in caplog.records if REPLAY_BEFORE_LOCK in r.getMessage()]
    assert len(warnings) == 1  # logged once, counted every time
    assert "127.0.0.1:40000" in warnings[0].getMessage()


def test_the_start_follows_the_clock_given() -> None:
    rx = receiver()
    msg = decoded(rx, heartbeat(), signer(stamp(START - 2.0)))
    assert gate().fresh(msg, VEHICLE)  # within the tolerance of START
    later = LockGate(AGENT, DropLog("x"), True, wall=lambda: START + LOCK_CLOCK_TOLERANCE_S)
    assert not later.fresh(msg, VEHICLE)  # the same frame, a daemon started later


def test_only_an_address_that_echoed_a_nonce_may_lock() -> None:
    g, rx = gate(), receiver()
    ts = stamp(START + 1.0)
    vehicle = signer(ts, link_id=0)
    assert not g.may_lock(VEHICLE)  # nobody challenged yet
    ask = g.challenge(VEHICLE)
    assert ask.get_type() == "TIMESYNC" and ask.tc1 == 0 and ask.ts1 > 0
    nonce = ask.ts1
    for _ in range(NONCES_PER_ADDRESS - 1):
        assert g.challenge(VEHICLE).ts1 != nonce  # a new nonce per challenge
    g.challenge(STRANGER)

    def echo(ts1: int, mav: Any = vehicle) -> Any:
        return decoded(rx, M.MAVLink_timesync_message(5, ts1), mav)

    # a wrong nonce; the right one from another address; the right one signed as another
    # component (the daemon's own request reflected): none proves anything
    assert not g.answered(echo(nonce + 2), VEHICLE)
    assert not g.answered(echo(nonce), STRANGER)
    own = signer(ts, link_id=AGENT, compid=M.MAV_COMP_ID_ONBOARD_COMPUTER)
    reflected = M.MAVLink_timesync_message(0, nonce)
    assert rx.parse_buffer(bytes(reflected.pack(own)))[0].get_type() == "BAD_DATA"
    assert not g.answered(reflected, VEHICLE)  # (the signing layer refuses it first)
    assert not g.answered(decoded(receiver(), M.MAVLink_heartbeat_message(
        2, 12, 0, 0, 3, 3), vehicle), VEHICLE)  # not a TIMESYNC
    assert not g.may_lock(VEHICLE) and not g.may_lock(STRANGER)
    assert g.drops.counts == {UNPROVEN_ADDRESS: 3}
    # the first (oldest kept) nonce, answered late: the vehicle's address is proven
    assert g.answered(echo(nonce), VEHICLE)
    assert g.may_lock(VEHICLE) and not g.may_lock(STRANGER)
    assert g.challenge(VEHICLE) is None  # proven: no more challenges
    assert g.drops.counts == {UNPROVEN_ADDRESS: 4}


def test_no_rule_without_signing_and_no_challenge_without_an_address() -> None:
    plain = M.MAVLink(None, srcSystem=AGENT, srcComponent=1)
    msg = M.MAVLink(None).parse_buffer(bytes(heartbeat().pack(plain)))[0]
    g = gate(signed=False)
    assert g.fresh(msg, STRANGER) and g.may_lock(STRANGER) and g.challenge(STRANGER) is None
    assert g.drops.counts == {}
    # a pymavlink transport (udpout, tcp): locked by system id, so no challenge, but a
    # frame signed before the start is still refused
    g = gate(challenge=False)
    rx = receiver()
    stale = decoded(rx, heartbeat(), signer(stamp(START - 2 * LOCK_CLOCK_TOLERANCE_S)))
    assert g.challenge(None) is None and g.may_lock(None)
    assert not g.fresh(stale, None)
    assert g.drops.counts == {REPLAY_BEFORE_LOCK: 1}
