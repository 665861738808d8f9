"""The vehicle's stored geofence, downloaded with the MAVLink mission protocol
(mission_type = MAV_MISSION_TYPE_FENCE; docs/world.md, "A fence uploaded over MAVLink").

A ground station may upload a fence to the vehicle at any time (QGroundControl, MAVProxy's
``fence`` module, pymavlink). PX4 tells every peer that its fence changed with
MISSION_CURRENT's ``fence_id`` (:mod:`swarm_common.world.mission_current`), so the daemon
downloads the fence once at the first MISSION_CURRENT (whatever is stored when it starts)
and again whenever ``fence_id`` changes:

    MISSION_REQUEST_LIST → MISSION_COUNT → MISSION_REQUEST_INT(seq) → MISSION_ITEM_INT(seq)
    … → MISSION_ACK(ACCEPTED)

Never blocking: each request is re-sent after :data:`RETRY_S` without an answer, and the
download fails after :data:`ATTEMPTS` tries of one step (or on the vehicle's error ACK, or
a count over :data:`~swarm_common.world.mavlink_fence.MAX_ITEMS`); it is tried again at
the next MISSION_CURRENT after :data:`RETRY_AFTER_S`. Only frames addressed to this
daemon with mission_type FENCE count. A completed list is handed over by :meth:`take`;
what it means is :mod:`offboard.daemon.fence_sync`'s. Pure: messages in, messages out
through ``send`` (the link's packing and signing).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from swarm_common.world.mavlink_fence import MAX_ITEMS, FenceItem  # noqa: E402
from swarm_common.world.mission_current import fence_id_of  # noqa: E402

mavlink = mavutil.mavlink
FENCE = mavlink.MAV_MISSION_TYPE_FENCE
COMP_AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1
COMP_ONBOARD = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
RETRY_S = 0.25  # s without an answer before a request goes again (PX4's own retry)
ATTEMPTS = 8  # tries of one request before the download fails
RETRY_AFTER_S = 2.0  # s after a failed download before a MISSION_CURRENT starts another


class FenceDownload:
    """The fence download of the daemon of vehicle (system) ``agent_id``."""

    def __init__(self, agent_id: int, send: Callable[[Any], None]) -> None:
        self.agent_id = agent_id
        self._send = send
        self.known_id: int | None = None  # fence_id of the last completed download
        self.pending_id: int | None = None  # fence_id the download under way answers
        self.count: int | None = None  # the vehicle's MISSION_COUNT, once it came
        self.items: list[FenceItem] = []
        self.tries = 0  # of the request now waiting for its answer
        self.sent_at = 0.0
        self.retry_at = 0.0  # no new download before this (after a failure)
        self._result: tuple[int, list[FenceItem]] | str | None = None
        self.completed = 0
        self.failed = 0

    @property
    def busy(self) -> bool:
        return self.pending_id is not None

    def take(self) -> tuple[int, list[FenceItem]] | str | None:
        """The last finished download, once: (fence_id, items), or why it failed; None
        when none finished since the last call."""
        out, self._result = self._result, None
        return out

    # -- from the vehicle -----------------------------------------------------------------
    def on_current(self, msg: Any, now: float) -> None:
        """MISSION_CURRENT: download when its ``fence_id`` is not the one held (the first
        one always), or restart when it changed under a download."""
        fid = fence_id_of(msg)
        if fid == (self.pending_id if self.busy else self.known_id):
            return
        if not self.busy and now < self.retry_at:
            return
        self.pending_id, self.count, self.items, self.tries = fid, None, [], 0
        self._request(now)

    def on_count(self, msg: Any, now: float) -> None:
        if not self._ours(msg) or self.count is not None:
            return
        count = int(msg.count)
        if not 0 <= count <= MAX_ITEMS:
            self._fail(f"MISSION_COUNT {count} (> {MAX_ITEMS})", now)
            return
        self.count, self.tries = count, 0
        if count == 0:
            self._finish(now)
        else:
            self._request(now)

    def on_item(self, msg: Any, now: float) -> None:
        if not self._ours(msg) or self.count is None or int(msg.seq) != len(self.items):
            return  # stray, or a late repeat of an item already held
        self.items.append(FenceItem(int(msg.seq), int(msg.frame), int(msg.command),
                                    float(msg.param1), int(msg.x), int(msg.y)))
        self.tries = 0
        if len(self.items) == self.count:
            self._finish(now)
        else:
            self._request(now)

    def on_ack(self, msg: Any, now: float) -> None:
        """The vehicle's MISSION_ACK during a download is its refusal of a request."""
        if self._ours(msg) and int(msg.type) != mavlink.MAV_MISSION_ACCEPTED:
            self._fail(f"the vehicle answered MISSION_ACK {int(msg.type)}", now)

    def tick(self, now: float) -> None:
        """Re-send the request waiting for its answer when due; give up after ATTEMPTS."""
        if not self.busy or now - self.sent_at < RETRY_S:
            return
        if self.tries >= ATTEMPTS:
            self._fail(f"no answer after {ATTEMPTS} requests", now)
            return
        self._request(now)

    # -- inside ---------------------------------------------------------------------------
    def _ours(self, msg: Any) -> bool:
        """A download frame for this daemon while one is under way."""
        return (self.busy and int(getattr(msg, "mission_type", 0)) == FENCE
                and int(msg.target_system) == self.agent_id
                and int(msg.target_component) in (0, COMP_ONBOARD))

    def _request(self, now: float) -> None:
        self.tries += 1
        self.sent_at = now
        if self.count is None:
            self._send(mavlink.MAVLink_mission_request_list_message(
                self.agent_id, COMP_AUTOPILOT, FENCE))
        else:
            self._send(mavlink.MAVLink_mission_request_int_message(
                self.agent_id, COMP_AUTOPILOT, len(self.items), FENCE))

    def _finish(self, now: float) -> None:
        self._send(mavlink.MAVLink_mission_ack_message(
            self.agent_id, COMP_AUTOPILOT, mavlink.MAV_MISSION_ACCEPTED, FENCE))
        assert self.pending_id is not None
        self.known_id = self.pending_id
        self._result = (self.pending_id, list(self.items))
        self.pending_id = None
        self.completed += 1

    def _fail(self, why: str, now: float) -> None:
        self.pending_id = None
        self.retry_at = now + RETRY_AFTER_S
        self._result = why
        self.failed += 1
