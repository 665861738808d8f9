"""Which sender may take the vehicle link's lock on a signed link (issue 42, docs/security.md
"Link lock on a signed link").

Before its lock the daemon's link (:class:`offboard.daemon.mavlink.link.VehicleLink`) has
no vehicle address yet, and a signature alone does not say a frame is fresh: a captured
vehicle frame still verifies while its signing timestamp is under 60 s old. With signing
on, :class:`LockGate` adds two rules before a sender of the vehicle's system id and
component 1 may lock the link:

* **not older than the daemon's start** (:meth:`LockGate.fresh`): a frame whose signing
  timestamp (10 µs units since 2015-01-01 UTC) lies more than
  :data:`LOCK_CLOCK_TOLERANCE_S` before the wall clock at the link's start is a replay
  of a capture made before the daemon ran. It is dropped, counted
  (:data:`REPLAY_BEFORE_LOCK`) and nothing is sent to its sender; the first one is
  logged at WARNING. The tolerance covers a vehicle clock behind the companion
  computer's.
* **the address answered a challenge** (:meth:`LockGate.challenge`,
  :meth:`LockGate.answered`, :meth:`LockGate.may_lock`): a candidate address is sent a
  signed TIMESYNC request whose ``ts1`` is a fresh random nonce; a vehicle echoes
  ``ts1`` in its signed answer (MAVLink's time-sync protocol, which PX4, ArduPilot and
  our simulator answer). Only a HEARTBEAT from an address that returned one of its
  nonces, in a frame signed as the vehicle, locks the link; one from any other address
  is dropped and counted (:data:`UNPROVEN_ADDRESS`). A capture made after the daemon
  started, or the vehicle's live stream relayed one way, cannot carry a nonce the
  daemon picked after it was signed.

Without signing every rule is off (the link is unauthenticated anyway). Pure: no
sockets; the wall clock is injectable.
"""

from __future__ import annotations

import logging
import os
import secrets
import time
from collections import deque
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.link_guard import DropLog  # noqa: E402
from swarm_common.signing import (  # noqa: E402
    SIGNATURE_EPOCH_UNIX_S,
    TIMESTAMP_UNITS_PER_S,
    frame_stream,
)

M = mavutil.mavlink
log = logging.getLogger(__name__)

# s: how far the vehicle's signing clock may lag this computer's wall clock at the
# daemon's start (NTP/GPS-disciplined clocks agree far better; MAVLink's own window is 60 s)
LOCK_CLOCK_TOLERANCE_S = 5.0
REPLAY_BEFORE_LOCK = "replay before lock"  # drop reason: signed before the daemon's start
UNPROVEN_ADDRESS = "unproven address"  # drop reason: a HEARTBEAT before a challenge answer
NONCES_PER_ADDRESS = 4  # challenges of one address still answerable (a late answer counts)
MAX_CANDIDATES = 8  # addresses with outstanding challenges (the oldest forgotten)
NONCE_BITS = 62  # a positive int64 for TIMESYNC.ts1

Address = tuple[str, int] | None


class LockGate:
    """The lock rules of one signed vehicle link (module docstring); all off unless
    ``signed``. ``challenge``: whether an address must answer one (a ``udpin`` link, which
    locks to an address; pymavlink's transports lock by system id only)."""

    def __init__(
        self,
        agent_id: int,
        drops: DropLog,
        signed: bool,
        challenge: bool = True,
        tolerance_s: float = LOCK_CLOCK_TOLERANCE_S,
        wall: Callable[[], float] = time.time,
    ) -> None:
        self.agent_id = agent_id
        self.drops = drops
        self.signed = signed
        self.challenging = signed and challenge
        self.tolerance_s = tolerance_s
        start = int((wall() - SIGNATURE_EPOCH_UNIX_S) * TIMESTAMP_UNITS_PER_S)  # 10 µs units
        # the oldest signing timestamp that may lock: the link's start minus the tolerance
        self.floor = start - int(tolerance_s * TIMESTAMP_UNITS_PER_S)
        self.start = start
        self.nonces: dict[Address, deque[int]] = {}
        self.proven: set[Address] = set()
        self.warned = False

    def _vehicle(self, msg: Any) -> bool:
        return (msg.get_srcSystem(), msg.get_srcComponent()) == (self.agent_id,
                                                                 M.MAV_COMP_ID_AUTOPILOT1)

    def fresh(self, msg: Any, addr: Address) -> bool:
        """False (counted, the first one logged) for a signed frame older than the floor;
        True for anything else and on an unsigned link."""
        if not self.signed:
            return True
        got = frame_stream(msg.get_msgbuf())
        if got is not None and got[1] >= self.floor:
            return True
        self.drops.counts[REPLAY_BEFORE_LOCK] = self.drops.counts.get(REPLAY_BEFORE_LOCK, 0) + 1
        if not self.warned:
            self.warned = True
            age = "unsigned" if got is None else (
                f"signed {(self.start - got[1]) / TIMESTAMP_UNITS_PER_S:.1f} s before")
            where = f"{addr[0]}:{addr[1]}" if addr else "the link"
            log.warning("%s: %s from %s %s this daemon started (clock tolerance %.0f s): a "
                        "replayed capture, or the vehicle's clock lags this computer's; "
                        "refused before the lock (%s, counted, not logged again)",
                        self.drops.what, msg.get_type(), where, age, self.tolerance_s,
                        REPLAY_BEFORE_LOCK)
        return False

    def challenge(self, addr: Address) -> Any:
        """A TIMESYNC request carrying a new nonce for ``addr`` (to be sent to it signed),
        or None when no challenge is needed (rules off, ``addr`` proven already)."""
        if not self.challenging or addr in self.proven:
            return None
        nonce = secrets.randbits(NONCE_BITS) | 1
        if addr not in self.nonces and len(self.nonces) >= MAX_CANDIDATES:
            del self.nonces[next(iter(self.nonces))]
        self.nonces.setdefault(addr, deque(maxlen=NONCES_PER_ADDRESS)).append(nonce)
        return M.MAVLink_timesync_message(0, nonce)

    def answered(self, msg: Any, addr: Address) -> bool:
        """True when ``msg`` (a verified frame) is the vehicle's TIMESYNC echoing a nonce
        sent to ``addr``: ``addr`` is proven from then on."""
        if not self.challenging or addr in self.proven or msg.get_type() != "TIMESYNC":
            return False
        if not self._vehicle(msg) or int(msg.ts1) not in self.nonces.get(addr, ()):
            return False
        self.proven.add(addr)
        return True

    def may_lock(self, addr: Address) -> bool:
        """Whether a (fresh, verified) HEARTBEAT of the vehicle from ``addr`` may lock the
        link; a refusal is counted."""
        if not self.challenging or addr in self.proven:
            others = sorted(f"{a[0]}:{a[1]}" for a in self.nonces if a and a != addr)
            if others:
                log.warning("%s: locking to the address that answered the challenge; "
                            "unproven address(es) also sent the vehicle's signed frames: %s",
                            self.drops.what, ", ".join(others))
            return True
        self.drops.counts[UNPROVEN_ADDRESS] = self.drops.counts.get(UNPROVEN_ADDRESS, 0) + 1
        return False
