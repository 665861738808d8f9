"""swarm_common.signing replay rules (MAVLink 2 signing, docs/security.md "Replayed and
reflected frames"): per-stream timestamps strictly increasing, a 60 s window for a new
stream measured against the receiver's wall clock, frames of the receiver's own identity
(or of streams its process emits, :class:`StreamLedger`) rejected as reflected. The
clock is a controlled variable (``signing._timestamp_now`` patched); no sockets."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common import signing
from swarm_common.signing import StreamLedger, frame_stream, setup_signing

KEY = bytes(range(32))
T0 = 100_000_000_000_000  # about 31.7 years after the 2015 epoch, 10 µs units (< 2^48)
UNITS = signing.TIMESTAMP_UNITS_PER_S


class Clock:
    """The signing wall clock (10 µs units), set by the test."""

    def __init__(self, now: int) -> None:
        self.now = now

    def __call__(self) -> int:
        return self.now


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Clock:
    c = Clock(T0)
    monkeypatch.setattr(signing, "_timestamp_now", c)
    return c


def _mav(sysid: int, compid: int, link_id: int, ledger: StreamLedger | None = None) -> M.MAVLink:
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.robust_parsing = True
    setup_signing(mav, KEY, link_id, ledger=ledger)
    return mav


def _hb(mav: M.MAVLink) -> bytes:
    return bytes(mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav))


def _verdict(rx: M.MAVLink, frame: bytes) -> str:
    """"ok" or the REJECT_* reason of one frame."""
    (m,) = rx.parse_buffer(frame)
    if m.get_msgId() >= 0:
        return "ok"
    prefix = signing.INVALID_SIGNATURE_REASON + ": "
    assert m.reason.startswith(prefix), m.reason
    return str(m.reason[len(prefix) :])


def _stamp(frame: bytes) -> int:
    got = frame_stream(frame)
    assert got is not None
    return got[1]


def test_outgoing_timestamps_follow_the_clock_and_strictly_increase(clock: Clock) -> None:
    tx = _mav(255, 190, 3)
    a, b = _hb(tx), _hb(tx)  # the clock stands still: one unit apart
    assert _stamp(a) == T0 and _stamp(b) == T0 + 1
    clock.now = T0 + 120 * UNITS  # two minutes later, without a frame in between
    c = _hb(tx)
    assert _stamp(c) == T0 + 120 * UNITS  # not T0 + 2, pymavlink's own count
    clock.now = T0  # the wall clock steps back: stamps still increase
    assert _stamp(_hb(tx)) == T0 + 120 * UNITS + 1


def test_stream_timestamps_strictly_increase(clock: Clock) -> None:
    tx, rx = _mav(255, 190, 3), _mav(1, 1, 0)
    f1, f2 = _hb(tx), _hb(tx)
    assert _verdict(rx, f1) == "ok" and _verdict(rx, f2) == "ok"
    assert _verdict(rx, f2) == signing.REJECT_REPLAY  # the same frame again
    assert _verdict(rx, f1) == signing.REJECT_REPLAY  # an older one
    tx.signing.timestamp = _stamp(f2)  # another frame with the last accepted timestamp
    tx.seq = 7  # (another sequence number: other bytes)
    same = _hb(tx)
    assert same != f2 and _stamp(same) == _stamp(f2)
    assert _verdict(rx, same) == signing.REJECT_REPLAY  # equal is not greater
    assert _verdict(rx, _hb(tx)) == "ok"  # one unit later
    # the same timestamps on another link id (another stream) are a stream of their own
    other = _mav(255, 190, 4)
    other.signing.timestamp = T0
    assert _verdict(rx, _hb(other)) == "ok"


@pytest.mark.parametrize(
    ("behind_units", "want"),
    [
        (0, "ok"),
        (signing.NEW_STREAM_MAX_BEHIND, "ok"),  # exactly 60 s old: still inside
        (signing.NEW_STREAM_MAX_BEHIND + 1, signing.REJECT_REPLAY),  # 60 s + 10 µs
        (3600 * UNITS, signing.REJECT_REPLAY),
    ],
)
def test_new_stream_window(clock: Clock, behind_units: int, want: str) -> None:
    assert signing.NEW_STREAM_MAX_BEHIND == 60 * UNITS
    rx = _mav(1, 1, 0)
    clock.now = T0 - behind_units  # the frame is stamped this long before ...
    frame = _hb(_mav(255, 190, 3))
    clock.now = T0  # ... the receiver reads it
    assert _verdict(rx, frame) == want


def test_window_is_measured_against_the_receivers_wall_clock(clock: Clock) -> None:
    """A receiver that has heard nothing for two minutes: a frame stamped 1 s after the
    receiver started is 119 s old now and refused (a clock frozen at set-up, as
    pymavlink's, would have let it in)."""
    rx = _mav(1, 1, 0)
    clock.now = T0 + 1 * UNITS
    old = _hb(_mav(255, 190, 3))
    clock.now = T0 + 120 * UNITS
    assert _verdict(rx, old) == signing.REJECT_REPLAY
    assert _verdict(rx, _hb(_mav(255, 190, 5))) == "ok"  # a fresh stream is welcome


def test_own_identity_is_reflected_other_components_are_not(clock: Clock) -> None:
    rx = _mav(1, 1, 0)
    mine = _hb(_mav(1, 1, 0))  # what the receiver itself sends, come back
    assert _verdict(rx, mine) == signing.REJECT_REFLECTED
    mine_other_link = _hb(_mav(1, 1, 9))  # on any link id, with any fresh timestamp
    assert _verdict(rx, mine_other_link) == signing.REJECT_REFLECTED
    # the same system's onboard computer (the offboard daemon: component 191) is not us
    assert _verdict(rx, _hb(_mav(1, 191, 1))) == "ok"
    assert signing.REJECT_REFLECTED in signing.REPLAY_REASONS


def test_ledger_identities_and_forwarded_streams(clock: Clock) -> None:
    ledger = StreamLedger()
    ledger.add_identity(2, 1)
    ledger.add_identity(2, 1)  # two links of vehicle 2
    rx = _mav(1, 1, 0, ledger=ledger)
    v2 = _mav(2, 1, 1)
    assert _verdict(rx, _hb(v2)) == signing.REJECT_REFLECTED  # another vehicle of ours
    daemon = _mav(2, 191, 2)
    forwarded = _hb(daemon)
    ledger.note_forwarded(forwarded)
    assert _verdict(rx, forwarded) == signing.REJECT_REFLECTED  # came back after forwarding
    assert _verdict(rx, _hb(daemon)) == "ok"  # the stream's next frame is new
    ledger.remove_identity(2, 1)
    assert _verdict(rx, _hb(v2)) == signing.REJECT_REFLECTED  # one link still open
    ledger.remove_identity(2, 1)
    assert _verdict(rx, _hb(v2)) == "ok"
    ledger.note_forwarded(b"\xfe\x09" + bytes(15))  # MAVLink 1: ignored
    ledger.note_forwarded(_hb(M.MAVLink(None, 3, 191)))  # unsigned: ignored
    assert _verdict(rx, _hb(_mav(3, 191, 3))) == "ok"


def test_frame_stream_reads_what_pymavlink_wrote(clock: Clock) -> None:
    clock.now = T0 + 12345
    frame = _hb(_mav(42, 191, 7))
    assert frame_stream(frame) == ((7, 42, 191), T0 + 12345)
    assert frame_stream(frame[:-1]) is None  # truncated
    assert frame_stream(_hb(M.MAVLink(None, 42, 191))) is None  # unsigned


def test_a_rejected_frame_does_not_advance_its_stream(clock: Clock) -> None:
    """A replayed first frame leaves the stream unknown: the stream's genuine next frame
    is judged as a new stream, and accepted."""
    rx = _mav(1, 1, 0)
    clock.now = T0 - 2 * signing.NEW_STREAM_MAX_BEHIND
    tx = _mav(255, 190, 3)
    stale = _hb(tx)
    clock.now = T0
    assert _verdict(rx, stale) == signing.REJECT_REPLAY
    assert (3, 255, 190) not in rx.signing.stream_timestamps
    assert _verdict(rx, _hb(tx)) == "ok"
