"""A stranger without the key cannot take a signed daemon link's lock (issue 42;
docs/security.md "Link lock on a signed link"). Real ``vehicle-sim`` (one signed vehicle)
and the daemon's :class:`VehicleLink` on real UDP over 127.0.0.1:

* a stranger records the vehicle's signed frames at the daemon's port (nothing bound
  there yet), and the simulator stops;
* while it ran, a second stranger relayed the vehicle's live ground-station stream (fresh
  frames, signed after that link started) to a signed link: it was challenged, never
  answered, and the link did not lock (``unproven address``);
* a signed link started more than LOCK_CLOCK_TOLERANCE_S after the recording is sent the
  recording before any vehicle is there: it does not lock, sends nothing back, counts
  ``replay before lock`` and says so once at WARNING;
* the simulator starts again: the link locks to it.
"""

from __future__ import annotations

import logging
import time

import pytest
from pymavlink.dialects.v20 import common as M
from udp_capture import LOCALHOST, drain, udp_socket

from offboard.daemon.mavlink.link import VehicleLink
from offboard.daemon.mavlink.lock_gate import (
    LOCK_CLOCK_TOLERANCE_S,
    REPLAY_BEFORE_LOCK,
    UNPROVEN_ADDRESS,
)
from swarm_common.ports import vehicle_ports
from swarm_common.signing import generate_key

pytestmark = pytest.mark.timeout(120)

WAIT_S = 10.0  # a deadline for what the simulator streams at 1 Hz, never a timing claim


def _kinds(datagrams: list[bytes]) -> list[tuple[int, int, str]]:
    parser = M.MAVLink(None)  # no key: reads the frames' contents, checks nothing
    parser.robust_parsing = True
    return [(m.get_srcSystem(), m.get_srcComponent(), m.get_type())
            for d in datagrams for m in parser.parse_buffer(d) or []]


def test_a_replayed_capture_does_not_take_the_lock_and_the_vehicle_does(
    sim_factory, tmp_path, caplog
) -> None:
    caplog.set_level(logging.WARNING, logger="offboard.daemon.mavlink.lock_gate")
    path = tmp_path / "swarm.key"
    key = generate_key(path)
    args = ["--no-zenoh", "--vehicles", "1", "--signing-key", str(path)]
    sim = sim_factory(args)
    p1 = vehicle_ports(1, sim.offset)
    capture, gcs = udp_socket(p1.api_remote), udp_socket(p1.gcs_remote)
    relay = udp_socket()
    # a signed link for vehicle 1 where the simulator does not stream (vehicle 2's port)
    raced = VehicleLink(f"udpin:{LOCALHOST}:{vehicle_ports(2, sim.offset).api_remote}", 1,
                        50.0, lockstep=False, signing_key=key)  # fmt: skip
    recorded: list[bytes] = []
    recorded_by = None  # every recorded frame was signed before this (wall clock)
    challenges: list[M.MAVLink_message] = []
    try:
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline and not (
            recorded_by and raced.drops.counts.get(UNPROVEN_ADDRESS, 0) >= 1 and challenges
        ):
            if recorded_by is None:  # record until a HEARTBEAT is in
                recorded += drain(capture)
                if (1, 1, "HEARTBEAT") in _kinds(recorded):
                    recorded_by = time.time()
            for d in drain(gcs):  # the live stream, relayed one way at once
                relay.sendto(d, (LOCALHOST, raced.sock.getsockname()[1]))  # type: ignore[union-attr]
            raced.poll(0.02)
            challenges += [m for m in M.MAVLink(None).parse_buffer(b"".join(drain(relay))) or []
                           if m.get_type() == "TIMESYNC"]
        assert recorded_by is not None
        # fresh signed HEARTBEATs from an address that never echoes the challenge's nonce
        assert not raced.locked and raced.drops.counts.get(UNPROVEN_ADDRESS, 0) >= 1
        assert challenges and challenges[0].tc1 == 0 and challenges[0].ts1 != 0
        assert raced.drops.counts.get(REPLAY_BEFORE_LOCK, 0) == 0  # fresh, not stale
    finally:
        raced.close()
        for s in (capture, gcs, relay):
            s.close()
    assert sim.stop() == 0

    # the recording is now older than a link started now, by more than the tolerance
    time.sleep(max(0.0, recorded_by + LOCK_CLOCK_TOLERANCE_S + 0.2 - time.time()))
    link = VehicleLink(f"udpin:{LOCALHOST}:{p1.api_remote}", 1, 50.0, lockstep=False,
                       signing_key=key)
    stranger = udp_socket()
    try:
        for d in recorded:
            stranger.sendto(d, (LOCALHOST, p1.api_remote))
            link.poll(0.0)
        unsigned = M.MAVLink(None, 9, 1)  # last in the queue: its drop says all were read
        stranger.sendto(bytes(M.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(unsigned)),
                        (LOCALHOST, p1.api_remote))
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline and not link.drops.counts.get("bad signature"):
            link.poll(0.05)
        assert link.drops.counts.get("bad signature") == 1
        assert not link.locked and link.peer is None
        heartbeats = _kinds(recorded).count((1, 1, "HEARTBEAT"))
        assert link.drops.counts.get(REPLAY_BEFORE_LOCK, 0) >= heartbeats >= 1
        assert link.drops.counts.get(UNPROVEN_ADDRESS, 0) == 0  # refused before that
        assert drain(stranger) == [] and link.sent == 0  # nothing went back
        said = [r for r in caplog.records if REPLAY_BEFORE_LOCK in r.getMessage()]
        assert len(said) == 1 and said[0].levelno == logging.WARNING

        # the real vehicle: challenged, it answers, and the link locks to it
        sim_factory(args, offset=sim.offset)
        assert link.wait_lock(WAIT_S * 3, lambda: False, 5.0)
        assert link.peer == (LOCALHOST, p1.api_local)
        assert link.gate.proven == {(LOCALHOST, p1.api_local)}
        assert drain(stranger) == []
    finally:
        link.close()
        stranger.close()
