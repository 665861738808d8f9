"""The MAVLink mission transfer protocol, vehicle side (pure: messages in, messages out).

Three stores, one per ``mission_type`` (MISSION, FENCE, RALLY), kept separately.

* Upload: MISSION_COUNT → MISSION_REQUEST_INT for each seq in turn (re-sent every
  :data:`RETRY_S` while the item does not come, the upload dropped after
  :data:`TIMEOUT_S` of silence, like PX4) → MISSION_ITEM_INT → a final MISSION_ACK.
  A client that answers with the float MISSION_ITEM is asked with MISSION_REQUEST from
  then on. The store changes only when the whole list is accepted. Errors end the
  upload with their MAV_MISSION_RESULT: MAV_MISSION_NO_SPACE (count above
  :data:`~vehicle_sim.services.mission_items.CAPACITY`), MAV_MISSION_INVALID_SEQUENCE (an item out
  of order; a repeat of the previous item is ignored), MAV_MISSION_UNSUPPORTED(_FRAME),
  MAV_MISSION_INVALID_PARAM*, MAV_MISSION_ERROR (busy with another client's upload).
  MISSION_COUNT 0 clears the store.
* Download: MISSION_REQUEST_LIST → MISSION_COUNT → MISSION_REQUEST_INT (or MISSION_REQUEST)
  per seq → MISSION_ITEM_INT (MISSION_ITEM) → the client's MISSION_ACK. Requests are
  served from the store without a session, so a client may retry any of them.
* MISSION_CLEAR_ALL (one type or MAV_MISSION_TYPE_ALL) → MISSION_ACK.

Every method returns the replies as ``(message, dest)`` with ``dest`` the requester.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as M

from vehicle_sim.services import mission_items as mi
from vehicle_sim.services.mission_items import Item

log = logging.getLogger(__name__)

RETRY_S = 0.25  # re-send the pending MISSION_REQUEST(_INT) after this long (s, wall)
TIMEOUT_S = 5.0  # drop an upload after this long without an item (s, wall)

Out = list[tuple[Any, Any]]


@dataclass
class Upload:
    """One upload in progress."""

    mission_type: int
    count: int
    partner: tuple[int, int]  # (sysid, compid) of the client
    dest: Any
    last_rx: float
    last_tx: float
    use_int: bool = True
    items: list[Item] = field(default_factory=list)


def partner_of(m: Any) -> tuple[int, int]:
    return int(m.get_srcSystem()), int(m.get_srcComponent())


def ack(m: Any, result: int, mission_type: int) -> M.MAVLink_mission_ack_message:
    """MISSION_ACK to the sender of ``m``."""
    ts, tc = partner_of(m)
    return M.MAVLink_mission_ack_message(ts, tc, result, mission_type)


class MissionTransfer:
    """The three stores and at most one upload; ``cfg`` has the geodetic origin."""

    def __init__(self, cfg: Any) -> None:
        self.cfg = cfg
        self.stores: dict[int, list[Item]] = {t: [] for t in mi.MISSION_TYPES}
        self.upload: Upload | None = None
        self.changed: list[int] = []  # mission types whose store changed (drained by owner)
        self.errors: list[str] = []  # one line per failed upload (drained by owner)

    # ---------------------------------------------------------------------------------
    # upload
    def on_count(self, m: Any, dest: Any, now: float) -> Out:
        mt = int(getattr(m, "mission_type", mi.MISSION))
        if mt not in mi.MISSION_TYPES:
            return [(ack(m, M.MAV_MISSION_UNSUPPORTED, mt), dest)]
        up = self.upload
        if up is not None and up.partner != partner_of(m) and now - up.last_rx < TIMEOUT_S:
            return [(ack(m, M.MAV_MISSION_ERROR, mt), dest)]  # busy with someone else
        self.upload = None
        count = int(m.count)
        if count > mi.CAPACITY[mt]:
            self._fail(f"upload refused: {count} items > {mi.CAPACITY[mt]}")
            return [(ack(m, M.MAV_MISSION_NO_SPACE, mt), dest)]
        if count == 0:
            self._commit(mt, [])
            return [(ack(m, M.MAV_MISSION_ACCEPTED, mt), dest)]
        self.upload = Upload(mt, count, partner_of(m), dest, now, now)
        return [(self._request(self.upload), dest)]

    def on_item(self, m: Any, dest: Any, now: float, is_int: bool) -> Out:
        up = self.upload
        mt = int(getattr(m, "mission_type", mi.MISSION))
        if up is None or up.partner != partner_of(m):
            return []  # a stray item (PX4 ignores it too)
        if mt != up.mission_type:
            return self._abort(m, M.MAV_MISSION_ERROR, "mission type changed")
        it = mi.item_from_int(m) if is_int else mi.item_from_float(m)
        if it is None:
            return self._abort(m, M.MAV_MISSION_INVALID_PARAM5_X, f"item {m.seq}: bad x/y")
        expected = len(up.items)
        if it.seq == expected - 1:
            return []  # a repeat of the previous item (our request was re-sent)
        if it.seq != expected:
            return self._abort(m, M.MAV_MISSION_INVALID_SEQUENCE, f"got {it.seq}, want {expected}")
        res = mi.check_item(self.cfg, it, mt)
        if res != M.MAV_MISSION_ACCEPTED:
            return self._abort(m, res, f"item {it.seq} (command {it.command}) rejected")
        up.items.append(it)
        up.last_rx = now
        up.use_int = is_int
        if len(up.items) < up.count:
            up.last_tx = now
            return [(self._request(up), up.dest)]
        self.upload = None
        res = mi.check_list(up.items, mt)
        if res != M.MAV_MISSION_ACCEPTED:
            self._fail(f"upload rejected: inconsistent list (type {mt})")
            return [(ack(m, res, mt), dest)]
        self._commit(mt, up.items)
        return [(ack(m, M.MAV_MISSION_ACCEPTED, mt), dest)]

    def on_client_ack(self, m: Any) -> None:
        """A MISSION_ACK from the uploading client cancels its upload (download ACKs and
        others are only the end of a download: nothing to do)."""
        up = self.upload
        if up is not None and up.partner == partner_of(m):
            self.upload = None
            self._fail(f"upload cancelled by the client (result {m.type})")

    def tick(self, now: float) -> Out:
        """Re-send the pending request, or drop a silent upload."""
        up = self.upload
        if up is None:
            return []
        if now - up.last_rx > TIMEOUT_S:
            self.upload = None
            self._fail(f"upload timed out at item {len(up.items)} of {up.count}")
            return []
        if now - up.last_tx >= RETRY_S:
            up.last_tx = now
            return [(self._request(up), up.dest)]
        return []

    def _request(self, up: Upload) -> Any:
        seq = len(up.items)
        if up.use_int:
            return M.MAVLink_mission_request_int_message(*up.partner, seq, up.mission_type)
        return M.MAVLink_mission_request_message(*up.partner, seq, up.mission_type)

    def _abort(self, m: Any, result: int, why: str) -> Out:
        up = self.upload
        assert up is not None
        self.upload = None
        self._fail(f"upload rejected: {why}")
        return [(ack(m, result, up.mission_type), up.dest)]

    def _fail(self, line: str) -> None:
        log.info("mission %s", line)
        self.errors.append(line)

    def _commit(self, mt: int, items: list[Item]) -> None:
        self.stores[mt] = list(items)
        self.changed.append(mt)

    # ---------------------------------------------------------------------------------
    # download, clear
    def on_request_list(self, m: Any, dest: Any) -> Out:
        mt = int(getattr(m, "mission_type", mi.MISSION))
        if mt not in mi.MISSION_TYPES:
            return [(ack(m, M.MAV_MISSION_UNSUPPORTED, mt), dest)]
        ts, tc = partner_of(m)
        count = len(self.stores[mt])
        return [(M.MAVLink_mission_count_message(ts, tc, count, mt), dest)]

    def on_request(self, m: Any, dest: Any, is_int: bool) -> Out:
        mt = int(getattr(m, "mission_type", mi.MISSION))
        if mt not in mi.MISSION_TYPES:
            return [(ack(m, M.MAV_MISSION_UNSUPPORTED, mt), dest)]
        store = self.stores[mt]
        seq = int(m.seq)
        if not 0 <= seq < len(store):
            return [(ack(m, M.MAV_MISSION_INVALID_SEQUENCE, mt), dest)]
        to_msg = mi.to_int_message if is_int else mi.to_float_message
        return [(to_msg(store[seq], partner_of(m)), dest)]

    def on_clear_all(self, m: Any, dest: Any) -> Out:
        mt = int(getattr(m, "mission_type", mi.MISSION))
        if mt == M.MAV_MISSION_TYPE_ALL:
            for t in mi.MISSION_TYPES:
                self._commit(t, [])
        elif mt in mi.MISSION_TYPES:
            self._commit(mt, [])
        else:
            return [(ack(m, M.MAV_MISSION_UNSUPPORTED, mt), dest)]
        if self.upload is not None and mt in (self.upload.mission_type, M.MAV_MISSION_TYPE_ALL):
            self.upload = None
        return [(ack(m, M.MAV_MISSION_ACCEPTED, mt), dest)]
