"""The mission protocol (mission, geofence, rally), AUTO.MISSION and the geofence check.

Contract: :class:`vehicle_sim.autopilot.nav.VehicleService`. The pieces, each pure:
:mod:`vehicle_sim.services.mission_transfer` (upload/download/clear state machine),
:mod:`vehicle_sim.services.mission_items` (item validation and frames),
:mod:`vehicle_sim.services.mission_executor` (items ->
:class:`~vehicle_sim.autopilot.nav.NavTarget`),
:mod:`vehicle_sim.services.geofence` (inclusion/exclusion zones and PX4's distance limits).

This module wires them to one vehicle: MAVLink handlers, MISSION_CURRENT at
:data:`CURRENT_HZ` and on every change (its ``fence_id`` changes with the stored fence:
how the offboard daemons learn of an upload), MISSION_ITEM_REACHED, and once per step the
geofence (``fence_breached``, and ``GF_ACTION`` once per breach while flying).
A store is applied in the handler that commits it, before its MISSION_ACK is queued, so
the ACK always acknowledges the store that a following MISSION_START sees.
A client whose frames are unsigned on a signed link (``_restricted``) may download, not
upload, clear or set the current item: MAV_MISSION_DENIED.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames, px4
from swarm_common.world.mission_current import MissionCurrent
from vehicle_sim.autopilot import audit
from vehicle_sim.autopilot.nav import NavTarget
from vehicle_sim.services import mission_items as mi
from vehicle_sim.services.geofence import Geofence, fence_from_items, plan_id
from vehicle_sim.services.mission_executor import MissionExecutor
from vehicle_sim.services.mission_items import Item
from vehicle_sim.services.mission_transfer import MissionTransfer, ack

CURRENT_HZ = 1.0  # MISSION_CURRENT, as PX4 streams it (wall clock)
NO_MISSION_TOTAL = 0xFFFF  # MISSION_CURRENT.total when no mission is stored
GF_NONE, GF_WARN, GF_HOLD, GF_RTL, GF_TERMINATE, GF_LAND = range(6)  # PX4 GF_ACTION values
MISSION_MODE = px4.custom_mode(px4.MAIN_AUTO, px4.SUB_AUTO_MISSION)
Handler = Callable[[Any, Any, float, float], None]
# the audit trail's name of each write (vehicle_sim.autopilot.audit)
AUDIT_NAME = {
    M.MAVLINK_MSG_ID_MISSION_COUNT: "MISSION_UPLOAD",
    M.MAVLINK_MSG_ID_MISSION_ITEM_INT: "MISSION_UPLOAD",
    M.MAVLINK_MSG_ID_MISSION_ITEM: "MISSION_UPLOAD",
    M.MAVLINK_MSG_ID_MISSION_CLEAR_ALL: "MISSION_CLEAR_ALL",
    M.MAVLINK_MSG_ID_MISSION_SET_CURRENT: "MISSION_SET_CURRENT",
}


class MissionService:
    """Attached to one :class:`~vehicle_sim.vehicle.Vehicle` (``vehicle``)."""

    def __init__(self, vehicle: Any) -> None:
        self.vehicle = vehicle
        self.transfer = MissionTransfer(vehicle.cfg)
        self.executor: MissionExecutor | None = None
        self.geofence = Geofence()
        self._preloaded: list[Item] | None = None  # the scenario's fence, when it has one
        self.fence_breached = False
        self._breach_handled = False
        self.started = False  # AUTO.MISSION entered since the mission was stored
        self._next_current = 0.0
        self._last_current: tuple[int, int, int, int] | None = None
        self._fence_id = 0  # MISSION_CURRENT.fence_id of the stored fence (plan_id)
        # the outline of a fence stored since the last truth (Geofence.outline), for the
        # run's verdict; the server takes it (take_fence_news)
        self._fence_news: np.ndarray | None = None

    def handlers(self) -> dict[int, Handler]:
        """MAVLink message id -> ``handler(msg, src, wall, sim_t)``."""
        return {
            M.MAVLINK_MSG_ID_MISSION_COUNT: self._on_count,
            M.MAVLINK_MSG_ID_MISSION_ITEM_INT: self._on_item_int,
            M.MAVLINK_MSG_ID_MISSION_ITEM: self._on_item_float,
            M.MAVLINK_MSG_ID_MISSION_REQUEST_LIST: self._on_request_list,
            M.MAVLINK_MSG_ID_MISSION_REQUEST_INT: self._on_request_int,
            M.MAVLINK_MSG_ID_MISSION_REQUEST: self._on_request_float,
            M.MAVLINK_MSG_ID_MISSION_ACK: self._on_ack,
            M.MAVLINK_MSG_ID_MISSION_CLEAR_ALL: self._on_clear_all,
            M.MAVLINK_MSG_ID_MISSION_SET_CURRENT: self._on_set_current,
        }

    def command_handlers(self) -> dict[int, Any]:
        """MAV_CMD -> ``handler(vehicle, command) -> (MAV_RESULT, reply or None)``."""
        return {M.MAV_CMD_DO_SET_MISSION_CURRENT: self._cmd_set_current}

    # ---------------------------------------------------------------------------------
    # message handlers
    def _send(self, outs: list[tuple[Any, Any]]) -> None:
        self.vehicle.outbox.extend(outs)

    def _accepts(self, m: Any, src: Any, write: bool, sim_t: float = 0.0) -> bool:
        """For our autopilot component; a write from a restricted peer is DENIED (and
        audited)."""
        if getattr(m, "target_component", 0) not in (0, M.MAV_COMP_ID_AUTOPILOT1):
            return False
        if write and getattr(m, "_restricted", False):
            mt = int(getattr(m, "mission_type", mi.MISSION))
            outs = [(ack(m, M.MAV_MISSION_DENIED, mt), src)]
            self._audit(m, src, sim_t, outs)
            self._send(outs)
            return False
        return True

    def _audit(self, m: Any, src: Any, sim_t: float, outs: list[tuple[Any, Any]]) -> None:
        """The MISSION_ACKs a write answers with, in the vehicle's audit trail (an
        upload's final ACK, a clear's, a refusal's)."""
        name = AUDIT_NAME.get(m.get_msgId(), m.get_type())
        audit.record_mission_acks(self.vehicle, m, src, sim_t, name, outs)

    def _on_count(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=True, sim_t=sim_t):
            outs = self.transfer.on_count(m, src, wall)
            self._audit(m, src, sim_t, outs)
            self._send_applied(outs)

    def _on_item_int(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=True, sim_t=sim_t):
            outs = self.transfer.on_item(m, src, wall, is_int=True)
            self._audit(m, src, sim_t, outs)
            self._send_applied(outs)

    def _on_item_float(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=True, sim_t=sim_t):
            outs = self.transfer.on_item(m, src, wall, is_int=False)
            self._audit(m, src, sim_t, outs)
            self._send_applied(outs)

    def _send_applied(self, outs: list[tuple[Any, Any]]) -> None:
        """Apply a committed store *before* its MISSION_ACK is queued: a client that sends
        MISSION_START (or AUTO.MISSION) right after the ACK must find the new mission,
        whenever the next simulation step comes."""
        self._apply_changes()
        self._send(outs)

    def _on_request_list(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=False):
            self._send(self.transfer.on_request_list(m, src))

    def _on_request_int(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=False):
            self._send(self.transfer.on_request(m, src, is_int=True))

    def _on_request_float(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=False):
            self._send(self.transfer.on_request(m, src, is_int=False))

    def _on_ack(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=False):
            self.transfer.on_client_ack(m)

    def _on_clear_all(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if self._accepts(m, src, write=True, sim_t=sim_t):
            outs = self.transfer.on_clear_all(m, src)
            self._audit(m, src, sim_t, outs)
            self._send_applied(outs)

    def _on_set_current(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if not self._accepts(m, src, write=True, sim_t=sim_t):
            return
        if not self._set_current(int(m.seq)):
            self.vehicle.event(f"mission: no item {int(m.seq)}", M.MAV_SEVERITY_WARNING)
            outs = [(ack(m, M.MAV_MISSION_INVALID_SEQUENCE, mi.MISSION), src)]
            self._audit(m, src, sim_t, outs)
            self._send(outs)
            return
        audit.record(self.vehicle, m, src, sim_t, "MISSION_SET_CURRENT", [int(m.seq)],
                     "MAV_MISSION_ACCEPTED", True)

    def _cmd_set_current(self, vehicle: Any, c: Any) -> tuple[int, Any]:
        """MAV_CMD_DO_SET_MISSION_CURRENT: param1 = seq (-1 or NaN: keep), param2 = 1: reset."""
        seq = c.p[0]
        if self.executor is None:
            return M.MAV_RESULT_DENIED, None
        if c.p[1] == 1:
            self.executor.finished = False
            self.started = False
        if seq != seq or seq == -1:  # NaN or "no change"
            return M.MAV_RESULT_ACCEPTED, None
        if seq != int(seq) or not self._set_current(int(seq)):
            return M.MAV_RESULT_DENIED, None
        return M.MAV_RESULT_ACCEPTED, None

    def _set_current(self, seq: int) -> bool:
        if self.executor is None or not self.executor.set_current(seq):
            return False
        self._send_current(force=True)
        return True

    # ---------------------------------------------------------------------------------
    # per step
    def update(self, sim_t: float) -> None:
        """Upload retries, store changes, reached/current reports, the geofence."""
        now = time.monotonic()
        self._send(self.transfer.tick(now))
        self._apply_changes()
        ex = self.executor
        if ex is not None and ex.reached:
            for seq in ex.reached:
                self._send([(M.MAVLink_mission_item_reached_message(seq), None)])
            ex.reached.clear()
        self._send_current(force=now >= self._next_current)
        if now >= self._next_current:
            self._next_current = now + 1.0 / CURRENT_HZ
        self._check_fence(sim_t)

    def preload_fence(self, items: list[Item]) -> None:
        """Start with ``items`` as the stored fence (the scenario's ``[geofence]``,
        :func:`~vehicle_sim.services.geofence.scenario_fence_items`): a ground station lists
        it, and the breach check uses it, as the offboard filter does."""
        self.transfer.stores[mi.FENCE] = list(items)
        self.geofence = fence_from_items(self.vehicle.cfg, items)
        self._preloaded = list(items)
        self._fence_id = plan_id(items)

    def take_fence_news(self) -> np.ndarray | None:
        """The outline of a fence stored since the last call (empty: not one inclusion
        polygon), or None when the stored fence did not change."""
        news, self._fence_news = self._fence_news, None
        return news

    def _apply_changes(self) -> None:
        v = self.vehicle
        for line in self.transfer.errors:
            v.event(f"mission {line}", M.MAV_SEVERITY_WARNING)
        self.transfer.errors.clear()
        for mt in self.transfer.changed:
            items = self.transfer.stores[mt]
            if mt == mi.MISSION:
                self.executor = (
                    MissionExecutor(v.cfg, items, self._home_enu(), self._acc_radius)
                    if items
                    else None
                )
                self.started = False
            elif mt == mi.FENCE:
                self.geofence = fence_from_items(v.cfg, items)
                self._fence_id = plan_id(items)  # MISSION_CURRENT tells every peer at once
                self._fence_news = self.geofence.outline()
                if self._preloaded is not None and items != self._preloaded:
                    v.event(
                        "geofence changed: the offboard filter takes it if it is one convex "
                        "inclusion polygon, else keeps its own (docs/world.md)",
                        M.MAV_SEVERITY_WARNING,
                    )
        self.transfer.changed.clear()

    def _mission_state(self) -> tuple[int, int, int]:
        """(seq, total, MISSION_STATE) now."""
        ex = self.executor
        if ex is None:
            return 0, NO_MISSION_TOTAL, M.MISSION_STATE_NO_MISSION
        total = len(ex.items)
        if ex.finished:
            return total - 1, total, M.MISSION_STATE_COMPLETE
        if not self.started:
            return ex.current, total, M.MISSION_STATE_NOT_STARTED
        state = M.MISSION_STATE_ACTIVE if self._in_mission_mode() else M.MISSION_STATE_PAUSED
        return ex.current, total, state

    def _send_current(self, force: bool) -> None:
        """MISSION_CURRENT, with the stored fence's ``fence_id`` (PX4's plan-change
        signal, which the offboard daemon follows: swarm_common.world.mission_current)."""
        st = (*self._mission_state(), self._fence_id)
        if not force and st == self._last_current:
            return
        self._last_current = st
        mode = 1 if self._in_mission_mode() else 2  # 1: in mission mode, 2: suspended
        self._send([(MissionCurrent(st[0], st[1], st[2], mode, fence_id=st[3]), None)])

    def _in_mission_mode(self) -> bool:
        try:
            return int(self.vehicle.custom_mode) == MISSION_MODE
        except KeyError:  # a mode the telemetry table does not name yet
            return False

    def _home_enu(self) -> np.ndarray:
        """The vehicle's home (ENU, m): ``home_enu``, else its ``home_ned`` converted."""
        home = getattr(self.vehicle, "home_enu", None)
        if home is not None:
            return np.asarray(home, dtype=float)
        return np.asarray(frames.ned_to_enu(np.asarray(self.vehicle.home_ned, dtype=float)))

    def _acc_radius(self) -> float:
        return float(self.vehicle.params.get("NAV_ACC_RAD"))

    # ---------------------------------------------------------------------------------
    # geofence
    def _check_fence(self, sim_t: float) -> None:
        v = self.vehicle
        max_hor = float(v.params.get("GF_MAX_HOR_DIST"))
        max_ver = float(v.params.get("GF_MAX_VER_DIST"))
        if not self.geofence and max_hor <= 0 and max_ver <= 0:
            self.fence_breached = False
            self._breach_handled = False
            return
        reason = self.geofence.breach(v.p(), self._home_enu(), max_hor, max_ver)
        self.fence_breached = reason is not None
        if reason is None:
            self._breach_handled = False
            return
        if self._breach_handled or not v.armed or v.on_ground():
            return
        self._breach_handled = True
        self._fence_action(reason, sim_t)

    def _fence_action(self, reason: str, sim_t: float) -> None:
        v = self.vehicle
        action = int(v.params.get("GF_ACTION"))
        if action == GF_NONE:
            return
        names = {GF_WARN: "warning", GF_HOLD: "hold", GF_RTL: "RTL", GF_TERMINATE: "terminate",
                 GF_LAND: "land"}  # fmt: skip
        v.event(f"geofence breach: {reason}; {names.get(action, 'warning')}",
                M.MAV_SEVERITY_CRITICAL)  # fmt: skip
        if action == GF_HOLD:
            v.request_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER, sim_t)
        elif action == GF_RTL:
            res = v.request_mode(px4.MAIN_AUTO, px4.SUB_AUTO_RTL, sim_t)
            if res != M.MAV_RESULT_ACCEPTED:  # no RTL mode: hold instead
                v.request_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER, sim_t)
        elif action == GF_LAND:
            v.request_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LAND, sim_t)
        elif action == GF_TERMINATE:
            v.terminate()

    # ---------------------------------------------------------------------------------
    # used by the vehicle's AUTO.MISSION mode (vehicle_sim.autopilot.nav.NavSource) and RTL
    def has_mission(self) -> bool:
        """True when a mission with at least one item is stored."""
        return self.executor is not None

    def start(self, sim_t: float) -> int:
        """MAV_CMD_MISSION_START / entering AUTO.MISSION: a MAV_RESULT (DENIED without a
        mission; a finished mission starts again from item 0)."""
        if self.executor is None:
            return M.MAV_RESULT_DENIED
        self.executor.home_enu = self._home_enu()
        self.executor.start()
        self.started = True
        self._send_current(force=True)
        return M.MAV_RESULT_ACCEPTED

    def nav_target(self, p_enu: np.ndarray, v_enu: np.ndarray, sim_t: float) -> NavTarget | None:
        """The current :class:`~vehicle_sim.autopilot.nav.NavTarget` (None: mission over)."""
        if self.executor is None:
            return None
        return self.executor.nav_target(p_enu, v_enu, sim_t)

    def rally_points_enu(self) -> list[np.ndarray]:
        """Rally points (ENU, m) for RTL; empty when none are stored."""
        out = []
        for it in self.transfer.stores[mi.RALLY]:
            p = mi.item_position_enu(self.vehicle.cfg, it)
            if p is not None:
                out.append(p)
        return out
