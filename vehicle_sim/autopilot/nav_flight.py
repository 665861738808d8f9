"""AUTO-mode flight: a :class:`~vehicle_sim.autopilot.nav.NavTarget` -> a position setpoint and
limits.

The parameters read here (PX4 names, ``vehicle.params``): ``MPC_XY_CRUISE`` (horizontal
speed, m/s, unless the target or DO_CHANGE_SPEED gives one), ``MPC_TKO_SPEED`` (climb in
a take-off, m/s), ``MPC_LAND_SPEED`` (descent in a landing, m/s), ``RTL_RETURN_ALT``
(m above home), and the ceilings ``MPC_XY_VEL_MAX``, ``MPC_Z_VEL_MAX_UP``,
``MPC_Z_VEL_MAX_DN`` (m/s): as on PX4, no AUTO speed exceeds them (a cruise, take-off or
land speed above its ceiling flies at the ceiling), and :func:`velocity_ceiling` is what
the position controller applies in every mode, OFFBOARD included
(:meth:`~vehicle_sim.physics.position_control.PositionController.set_ceiling`). The
constants below are PX4's defaults of those ceilings.

RTL (:class:`RtlPlan`), as PX4 flies it without a mission: climb over the current point
to ``max(current altitude, RTL_RETURN_ALT)``, fly there to the destination (home, or the
nearest rally point), descend at the land speed, land (the vehicle disarms after
``COM_DISARM_LAND``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import StrEnum
from typing import Any

import numpy as np

from vehicle_sim.autopilot.nav import NavKind, NavTarget
from vehicle_sim.physics.position_control import PositionSetpoint, SpeedLimits

Z_VEL_MAX_UP = 3.0  # m/s, PX4 MPC_Z_VEL_MAX_UP default
Z_VEL_MAX_DN = 1.5  # m/s, PX4 MPC_Z_VEL_MAX_DN default
XY_VEL_MAX = 12.0  # m/s, PX4 MPC_XY_VEL_MAX default: the ceiling of offboard velocities
OFFBOARD_LIMITS = SpeedLimits(XY_VEL_MAX, Z_VEL_MAX_UP, Z_VEL_MAX_DN)
TAKEOFF_ALT_TOL = 0.3  # m: a take-off is complete this close to its altitude
ARRIVE_XY_TOL = 0.5  # m: RTL starts descending this close over its destination …
ARRIVE_SPEED = 0.5  # m/s: … and this slow horizontally
CLIMB_ALT_TOL = 0.3  # m: RTL's climb is over this close to the return altitude


def _p(params: Any, name: str) -> float:
    return float(params.get(name))


def velocity_ceiling(params: Any) -> SpeedLimits:
    """PX4's speed ceilings (m/s): ``MPC_XY_VEL_MAX``, ``MPC_Z_VEL_MAX_UP``,
    ``MPC_Z_VEL_MAX_DN``."""
    return SpeedLimits(
        _p(params, "MPC_XY_VEL_MAX"), _p(params, "MPC_Z_VEL_MAX_UP"),
        _p(params, "MPC_Z_VEL_MAX_DN"),
    )  # fmt: skip


def nav_setpoint(
    target: NavTarget, params: Any, speed_override: float | None = None
) -> tuple[PositionSetpoint, SpeedLimits]:
    """What the position controller flies for ``target`` (TAKEOFF, GOTO, LOITER, LAND;
    an RTL target is resolved by :class:`RtlPlan` first); every speed within
    :func:`velocity_ceiling`."""
    top = velocity_ceiling(params)
    xy_speed = target.speed_m_s or speed_override or _p(params, "MPC_XY_CRUISE")
    xy_speed = min(max(0.1, float(xy_speed)), top.xy)
    pos = np.array(target.position_enu, dtype=float)
    yaw = target.yaw_rad
    if target.kind == NavKind.TAKEOFF:
        lim = SpeedLimits(xy_speed, min(_p(params, "MPC_TKO_SPEED"), top.up), top.down)
        return PositionSetpoint(pos=pos, yaw=yaw), lim
    if target.kind == NavKind.LAND:
        land = min(_p(params, "MPC_LAND_SPEED"), top.down)
        sp = PositionSetpoint(
            pos=np.array([pos[0], pos[1], math.nan]), vel=np.array([math.nan, math.nan, -land]),
            yaw=yaw,
        )  # fmt: skip
        return sp, SpeedLimits(xy_speed, top.up, land)
    return PositionSetpoint(pos=pos, yaw=yaw), SpeedLimits(xy_speed, top.up, top.down)


def takeoff_reached(target: NavTarget, p: np.ndarray) -> bool:
    """A take-off target's altitude is reached (within :data:`TAKEOFF_ALT_TOL`)."""
    return bool(abs(float(p[2]) - float(target.position_enu[2])) <= TAKEOFF_ALT_TOL)


def nearest_xy(p: np.ndarray, home_xy: np.ndarray, rally: Sequence[Any]) -> np.ndarray:
    """The RTL destination (x, y): the rally point nearest to ``p``, else home."""
    best = np.asarray(home_xy, dtype=float)[:2]
    if rally:
        pts = [np.asarray(r, dtype=float)[:2] for r in rally]
        best = min(pts, key=lambda q: float(np.hypot(*(q - p[:2]))))
    return np.array(best, dtype=float)


class RtlPhase(StrEnum):
    CLIMB = "climb"
    RETURN = "return"
    LAND = "land"


class RtlPlan:
    """One return-to-launch from position ``p`` (module docstring)."""

    def __init__(self, p: np.ndarray, dest_xy: np.ndarray, return_alt: float) -> None:
        self.start = np.array(p, dtype=float)
        self.dest = np.asarray(dest_xy, dtype=float)[:2]
        self.alt = max(float(p[2]), float(return_alt))
        self.phase = RtlPhase.CLIMB

    def target(self, p: np.ndarray, v: np.ndarray) -> NavTarget:
        """The target for this step (position ``p``, velocity ``v``, ENU), advancing the
        phase when one is done."""
        if self.phase == RtlPhase.CLIMB and float(p[2]) >= self.alt - CLIMB_ALT_TOL:
            self.phase = RtlPhase.RETURN
        arrived = float(np.hypot(*(self.dest - p[:2]))) <= ARRIVE_XY_TOL
        if self.phase == RtlPhase.RETURN and arrived and float(np.hypot(*v[:2])) <= ARRIVE_SPEED:
            self.phase = RtlPhase.LAND
        if self.phase == RtlPhase.CLIMB:
            return NavTarget(NavKind.GOTO, np.array([self.start[0], self.start[1], self.alt]))
        if self.phase == RtlPhase.RETURN:
            return NavTarget(NavKind.GOTO, np.array([self.dest[0], self.dest[1], self.alt]))
        return NavTarget(NavKind.LAND, np.array([self.dest[0], self.dest[1], 0.0]))
