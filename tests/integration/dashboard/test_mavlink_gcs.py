"""The MAVLink GCS link against tiny pymavlink vehicles on loopback UDP."""

from __future__ import annotations

import asyncio
import time

import pytest
from conftest import wait_for  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink2

from gcs.dashboard.command_retry import (
    AwaitAck,
    PendingAck,
    SendAttempt,
    command_exchange,
    drive_blocking,
)
from gcs.dashboard.mavlink_gcs import MavlinkGcs
from gcs.dashboard.px4modes import COMMANDS, custom_mode, decode_px4_mode

from .fake_vehicle import FakeVehicle


def test_decode_px4_modes():
    assert decode_px4_mode(6 << 16) == "OFFBOARD"
    assert decode_px4_mode(4 << 16 | 3 << 24) == "AUTO.LOITER"
    assert decode_px4_mode(4 << 16 | 6 << 24) == "AUTO.LAND"
    assert decode_px4_mode(3 << 16) == "POSCTL"
    assert decode_px4_mode(custom_mode(4, 3)) == "AUTO.LOITER"
    assert decode_px4_mode(77 << 16).startswith("MODE:")
    assert decode_px4_mode(6 << 16, base_mode=0).startswith("BASE")


@pytest.fixture
def gcs(port_offset):
    link = MavlinkGcs(port_offset=port_offset, heartbeat_timeout_s=0.5).start()
    yield link
    link.close()


def test_busy_port_names_the_port(gcs):
    with pytest.raises(OSError, match=str(gcs.port)):
        MavlinkGcs(port=gcs.port).start()


def test_tracks_vehicles_and_events(gcs):
    vs = [FakeVehicle(i, gcs.port).start() for i in (1, 2)]
    try:
        assert wait_for(lambda: set(gcs.vehicles()) == {1, 2})
        assert wait_for(lambda: gcs.vehicles()[1].pos_enu is not None)
        v = gcs.vehicles()[1]
        assert v.mode == "POSCTL" and not v.armed
        assert v.pos_enu == pytest.approx((2.0, 1.0, 3.0))  # NED (1,2,-3) -> ENU
        assert v.vel_enu == pytest.approx((0.0, 0.5, 0.1))
        assert v.heartbeat_age(time.monotonic()) < 1.0
        vs[0].statustext("Failsafe: offboard lost", severity=2)
        vs[0].armed = True
        assert wait_for(lambda: gcs.vehicles()[1].armed)
        assert wait_for(lambda: gcs.vehicles()[1].rate_hz > 0)
        assert wait_for(lambda: gcs.vehicles()[1].statustexts == 1)
        # the GCS heartbeats the vehicles it knows
        assert wait_for(lambda: vs[0].heartbeats_from_gcs > 0)
        ev = gcs.drain_events()
        kinds = {(e.sysid, e.kind) for e in ev}
        assert (1, "statustext") in kinds and (1, "armed") in kinds
        st = [e for e in ev if e.kind == "statustext"][0]
        assert st.text == "Failsafe: offboard lost" and st.severity == 2
        # a silent vehicle is reported lost, then regained
        vs[1].stop()
        assert wait_for(lambda: gcs.vehicles()[2].lost)
        assert any(e.kind == "link" and e.sysid == 2 for e in gcs.drain_events())
        assert gcs.vehicles()[2].heartbeat_age(time.monotonic()) > 0.5
    finally:
        for v in vs:
            if not v._stop.is_set():
                v.stop()


def test_bad_packets_counted_never_fatal(gcs):
    v = FakeVehicle(3, gcs.port).start()
    try:
        assert wait_for(lambda: 3 in gcs.vehicles())
        v.send_raw(b"\xfd\x09garbage-garbage")
        good = v.mav.heartbeat_encode(2, 12, 1, 6 << 16, 4).pack(v.mav)
        bad = bytearray(good)
        bad[-1] ^= 0xFF  # CRC error
        v.send_raw(bytes(bad))
        v.send_raw(good[:7])  # truncated
        assert wait_for(lambda: gcs.bad_packets >= 3)
        n = gcs.vehicles()[3].msg_count
        assert wait_for(lambda: gcs.vehicles()[3].msg_count > n)  # still parsing
    finally:
        v.stop()


def test_command_ack_sync_and_retry(gcs):
    v = FakeVehicle(4, gcs.port, drop_first_acks=1).start()
    try:
        assert wait_for(lambda: 4 in gcs.vehicles())
        res = gcs.send_command(4, COMMANDS["arm"], timeout_s=0.3, retries=3)
        assert res.ok and res.result_name == "ACCEPTED"
        assert res.attempts == 2
        assert [c[1] for c in v.commands] == [0, 1]  # confirmation counts retries
        assert v.commands[0][0] == 400 and v.commands[0][2][0] == 1.0
        assert wait_for(lambda: gcs.vehicles()[4].armed)
        res = gcs.send_command(4, COMMANDS["offboard"], timeout_s=1.0)
        assert res.ok
        assert v.commands[-1][2][:3] == [129.0, 6.0, 0.0]
        assert wait_for(lambda: gcs.vehicles()[4].mode == "OFFBOARD")
    finally:
        v.stop()


def test_command_denied_timeout_and_no_link(gcs):
    v = FakeVehicle(5, gcs.port, ack_result=2).start()
    try:
        assert wait_for(lambda: 5 in gcs.vehicles())
        res = gcs.send_command(5, COMMANDS["offboard"], timeout_s=1.0)
        assert not res.ok and res.result_name == "DENIED"
        v.drop_first_acks = 99
        res = gcs.send_command(5, COMMANDS["land"], timeout_s=0.1, retries=1)
        assert res.result is None and res.result_name == "TIMEOUT" and res.attempts == 2
        res = gcs.send_command(42, COMMANDS["arm"], timeout_s=0.1)
        assert res.result_name == "NO-LINK"
    finally:
        v.stop()


def test_command_async(gcs):
    vs = [FakeVehicle(i, gcs.port).start() for i in (6, 7)]
    try:
        assert wait_for(lambda: {6, 7} <= set(gcs.vehicles()))

        async def both():
            return await asyncio.gather(
                gcs.command(6, COMMANDS["hold"], timeout_s=1.0),
                gcs.command(7, COMMANDS["terminate"], timeout_s=1.0),
            )

        r6, r7 = asyncio.run(both())
        assert r6.ok and r7.ok
        assert vs[0].commands[-1][0] == 176 and vs[0].commands[-1][2][1:3] == [4.0, 3.0]
        assert vs[1].commands[-1][0] == 185
    finally:
        for v in vs:
            v.stop()


def test_retry_policy_steps():
    """The one policy both paths drive: send, wait, retry with confirmation = retry number."""
    pend = PendingAck()
    ex = command_exchange(3, COMMANDS["arm"], pend, time.monotonic, timeout_s=0.25, retries=2)
    assert next(ex) == SendAttempt(0)
    assert ex.send(True) == AwaitAck(0.25)
    assert ex.send(False) == SendAttempt(1)
    assert ex.send(True) == AwaitAck(0.25)
    pend.result = mavlink2.MAV_RESULT_ACCEPTED
    with pytest.raises(StopIteration) as done:
        ex.send(True)
    res = done.value.value
    assert res.ok and res.attempts == 2 and res.sysid == 3
    # every wait unanswered: TIMEOUT after retries + 1 sends; a failed send: NO-LINK
    sent: list[int] = []
    ex = command_exchange(3, COMMANDS["land"], PendingAck(), time.monotonic, 0.0, retries=1)
    res = drive_blocking(ex, lambda conf: sent.append(conf) is None, lambda _t: False)
    assert sent == [0, 1] and res.result_name == "TIMEOUT" and res.attempts == 2
    ex = command_exchange(3, COMMANDS["land"], PendingAck(), time.monotonic, 0.0, retries=3)
    res = drive_blocking(ex, lambda conf: conf < 1, lambda _t: False)
    assert res.result_name == "NO-LINK" and res.attempts == 1


def test_command_async_all_vehicles_at_once(gcs):
    """An "all vehicles" gather waits for every ACK at once, not one vehicle after another."""
    ids = list(range(20, 32))
    vs = [FakeVehicle(i, gcs.port, drop_first_acks=99).start() for i in ids]
    try:
        assert wait_for(lambda: set(ids) <= set(gcs.vehicles()))

        async def everyone():
            return await asyncio.gather(
                *(gcs.command(i, COMMANDS["hold"], timeout_s=0.4, retries=1) for i in ids)
            )

        t0 = time.monotonic()
        results = asyncio.run(everyone())
        elapsed = time.monotonic() - t0
        assert [r.result_name for r in results] == ["TIMEOUT"] * len(ids)
        assert all(r.attempts == 2 for r in results)
        assert elapsed < 0.4 * 2 * len(ids) / 3  # serial would take 9.6 s
    finally:
        for v in vs:
            v.stop()


def test_feed_without_socket():
    link = MavlinkGcs(port=1, send_heartbeat=False)
    mav = mavlink2.MAVLink(None, srcSystem=9, srcComponent=1)
    hb = mav.heartbeat_encode(2, 12, 129, 4 << 16 | 6 << 24, 4).pack(mav)
    odo = mav.odometry_encode(
        0, 1, 12, 1.0, 0.0, -2.0, [1, 0, 0, 0], 1.0, 0.0, 0.0, 0, 0, 0, [0] * 21, [0] * 21
    ).pack(mav)
    link.feed(hb + odo, ("127.0.0.1", 5))
    v = link.vehicles()[9]
    assert v.mode == "AUTO.LAND" and v.armed
    assert v.pos_enu == pytest.approx((0.0, 1.0, 2.0))
    assert v.vel_enu == pytest.approx((0.0, 1.0, 0.0))  # body FRD, identity attitude
    assert v.addr == ("127.0.0.1", 5)
    assert link.bad_packets == 0
    link.feed(b"\x00" * 3, ("127.0.0.1", 5))
    assert link.bad_packets >= 1
