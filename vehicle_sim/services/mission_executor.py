"""AUTO.MISSION: the stored mission turned into navigation targets (pure, no I/O).

:meth:`MissionExecutor.nav_target` is called every control step with the vehicle's ENU
position and velocity; it returns the :class:`~vehicle_sim.autopilot.nav.NavTarget` the vehicle's
own position controller flies, advances the items that are complete, and returns None once
the mission is over (the vehicle then holds, or it has landed). What it did for the wire
is left in :attr:`MissionExecutor.reached` (MISSION_ITEM_REACHED seqs) and
:attr:`MissionExecutor.current` (MISSION_CURRENT).

Items flown (MAVLink ``MAV_CMD_NAV_*``):

* TAKEOFF: climb straight up to its altitude over where it was when the item started;
  complete within :data:`ALT_ACCEPT_M` of that altitude (at once when already above it).
* WAYPOINT: fly to it; complete when horizontally within the acceptance radius (param2,
  else ``NAV_ACC_RAD``) and vertically within :data:`ALT_ACCEPT_M`, then after holding
  param1 seconds there.
* LOITER_TIME: fly to it (lat = lon = 0: here), hold param1 seconds.
* LAND: descend onto its x/y (lat = lon = 0: here); complete once landed, which ends the
  mission (its LAND target is still returned, for the touchdown and auto-disarm).
* RETURN_TO_LAUNCH: hand over to RTL (kind ``RTL``, over home); the mission is over once
  landed. No MISSION_ITEM_REACHED for it, as PX4 (which switches to AUTO.RTL there).

``MAV_CMD_DO_CHANGE_SPEED`` (param2 > 0, m/s) sets the cruise speed of the following
items; every other ``DO_*`` item is accepted and skipped. Each complete item but RTL is
reported reached.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from vehicle_sim.autopilot.nav import NavKind, NavTarget
from vehicle_sim.services.mission_items import Item, altitude_enu, item_position_enu, yaw_enu

ALT_ACCEPT_M = 0.8  # vertical acceptance (PX4 NAV_MC_ALT_RAD default), m
LANDED_Z_M = 0.05  # height under which, slow, the vehicle counts as landed, m
LANDED_SPEED_M_S = 0.3


class MissionExecutor:
    """Walks one stored mission; ``acc_radius()`` gives NAV_ACC_RAD (m) when asked."""

    def __init__(
        self, cfg: Any, items: list[Item], home_enu: np.ndarray, acc_radius: Callable[[], float]
    ) -> None:
        self.cfg = cfg
        self.items = list(items)
        self.home_enu = np.asarray(home_enu, dtype=float)
        self.acc_radius = acc_radius
        self.current = 0
        self.finished = False
        self.reached: list[int] = []  # drained by the service (MISSION_ITEM_REACHED)
        self.speed: float | None = None
        self._anchor: np.ndarray | None = None  # the active item's target (ENU, m)
        self._arrived_t: float | None = None  # when the active item's position was reached
        self._landing: NavTarget | None = None  # a finished mission's last LAND target

    # ----------------------------------------------------------------------------------
    def set_current(self, seq: int) -> bool:
        """Jump to item ``seq`` (MISSION_SET_CURRENT); False when out of range."""
        if not 0 <= seq < len(self.items):
            return False
        self.current = seq
        self.finished = False
        self._landing = None
        self._reset_item()
        return True

    def start(self) -> None:
        """Entering AUTO.MISSION: resume at the current item, from the start when finished."""
        if self.finished:
            self.current = 0
            self.finished = False
            self.speed = None
            self._landing = None
        self._reset_item()

    def _reset_item(self) -> None:
        self._anchor = None
        self._arrived_t = None

    # ----------------------------------------------------------------------------------
    def nav_target(self, p_enu: np.ndarray, v_enu: np.ndarray, sim_t: float) -> NavTarget | None:
        """The target to fly now; completes items on the way. None once the mission is over,
        except after a LAND item: its target stays, so that the vehicle's landing logic
        finishes the touchdown and disarms."""
        p = np.asarray(p_enu, dtype=float)
        v = np.asarray(v_enu, dtype=float)
        while not self.finished and self.current < len(self.items):
            it = self.items[self.current]
            target, done = self._step(it, p, v, sim_t)
            if not done:
                return target
            if it.command != M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                self.reached.append(it.seq)
            if it.command == M.MAV_CMD_NAV_LAND:
                self._landing = target
            if self.current + 1 >= len(self.items) or it.command in _ENDS_MISSION:
                self.finished = True
            else:
                self.current += 1
            self._reset_item()
        self.finished = True
        return self._landing

    def _step(
        self, it: Item, p: np.ndarray, v: np.ndarray, t: float
    ) -> tuple[NavTarget | None, bool]:
        """(target, complete) for the active item."""
        c = it.command
        if c == M.MAV_CMD_DO_CHANGE_SPEED:
            if math.isfinite(it.param2) and it.param2 > 0:
                self.speed = float(it.param2)
            return None, True
        if c not in _FLOWN:
            return None, True  # other DO_* items: accepted and skipped
        if self._anchor is None:
            self._anchor = self._anchor_of(it, p)
        a = self._anchor
        yaw = yaw_enu(it.param4) if c in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF) else None
        if c == M.MAV_CMD_NAV_TAKEOFF:
            done = p[2] >= a[2] - ALT_ACCEPT_M
            return NavTarget(NavKind.TAKEOFF, a.copy(), yaw, self.speed), bool(done)
        if c in (M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH):
            kind = NavKind.LAND if c == M.MAV_CMD_NAV_LAND else NavKind.RTL
            return NavTarget(kind, a.copy(), None, self.speed), landed(p, v)
        radius = it.param2 if c == M.MAV_CMD_NAV_WAYPOINT and it.param2 > 0 else self.acc_radius()
        hold = max(0.0, it.param1) if math.isfinite(it.param1) else 0.0
        tgt = NavTarget(NavKind.GOTO, a.copy(), yaw, self.speed)
        if self._arrived_t is None and _arrived(p, a, radius):
            self._arrived_t = t
        if self._arrived_t is None:
            return tgt, False
        hold_tgt = NavTarget(NavKind.LOITER, a.copy(), yaw, self.speed)
        return hold_tgt, t - self._arrived_t >= hold

    def _anchor_of(self, it: Item, p: np.ndarray) -> np.ndarray:
        """The active item's target in ENU (m), fixed when the item starts."""
        c = it.command
        if c == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self.home_enu.copy()
        pos = item_position_enu(self.cfg, it)
        if c == M.MAV_CMD_NAV_TAKEOFF:
            return np.array([p[0], p[1], altitude_enu(self.cfg, it)])
        if c == M.MAV_CMD_NAV_LAND:
            xy = p[:2] if pos is None else pos[:2]
            return np.array([xy[0], xy[1], 0.0])
        if pos is None:  # LOITER_TIME "here" at its altitude
            return np.array([p[0], p[1], altitude_enu(self.cfg, it)])
        return pos


_FLOWN = frozenset({
    M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LOITER_TIME,
    M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH,
})  # fmt: skip
_ENDS_MISSION = frozenset({M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH})


def _arrived(p: np.ndarray, target: np.ndarray, radius: float) -> bool:
    horizontal = math.hypot(float(p[0] - target[0]), float(p[1] - target[1]))
    return horizontal <= radius and abs(float(p[2] - target[2])) <= ALT_ACCEPT_M


def landed(p: np.ndarray, v: np.ndarray) -> bool:
    """On the ground (ENU z below :data:`LANDED_Z_M`) and nearly still."""
    return bool(p[2] <= LANDED_Z_M and float(np.linalg.norm(v)) <= LANDED_SPEED_M_S)
