"""Offboard setpoints to the formation vehicle: a MAVLink client flies the whole formation
live (docs/missions.md, "Flying the formation live").

A client streams ``SET_POSITION_TARGET_LOCAL_NED`` to the formation's vehicle, as it would to
one PX4 vehicle in OFFBOARD, and switches it to OFFBOARD (``DO_SET_MODE`` main mode 6) once
the stream has started. Each setpoint is a velocity (position ignored in ``type_mask``:
MAVSDK's ``set_velocity_ned``) or a position (MAVSDK's ``set_position_ned``), in the local
NED frame of the vehicle's ``LOCAL_POSITION_NED``. NED becomes ENU here, at the boundary.

:class:`LiveSetpoints` turns the stream into the velocity of the formation's centroid:

* a velocity setpoint is that velocity, refused above the mission's ``max_speed_mps``;
* a position setpoint becomes ``K · (target − centroid)`` capped at the mission's speed,
  with the centroid that the leaders' plan (the replica) holds at the command's start, so the
  formation slows into the target point;
* a setpoint older than :data:`SETPOINT_TIMEOUT_S` of wall time no longer counts: the
  vehicle leaves OFFBOARD for a hold, and the leaders' plan brakes to rest by itself
  (:data:`swarm_common.mission.live.LIVE_TIMEOUT_S` after the last velocity it got).

It sends a ``live`` command to the leaders at most every :data:`SEND_EVERY_S` of mission
time, and at once when the velocity changes by more than :data:`CHANGE_MPS`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames
from swarm_common.mission.config import MissionError

POSITION_GAIN = 0.5  # 1/s, a position setpoint's velocity per metre still to go
SETPOINT_TIMEOUT_S = 0.5  # s of wall time without a setpoint: offboard lost (PX4: 0.5 s)
SEND_EVERY_S = 0.25  # s of mission time between live commands of an unchanged velocity
CHANGE_MPS = 0.05  # m/s, a change of velocity that is sent at once
_POS_IGNORE = (M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
               | M.POSITION_TARGET_TYPEMASK_Z_IGNORE)
_VEL_IGNORE = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
               | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE)
_FRAMES = (M.MAV_FRAME_LOCAL_NED,)


@dataclass(frozen=True)
class Setpoint:
    """One setpoint, ENU: a velocity (m/s) or a position (m); exactly one is set."""

    velocity: np.ndarray | None
    position: np.ndarray | None
    received: float  # wall time (s, monotonic)


def parse_setpoint(m: Any, now: float) -> Setpoint:
    """The :class:`Setpoint` of a ``SET_POSITION_TARGET_LOCAL_NED``; :class:`MissionError`
    (one line) for a frame other than LOCAL_NED, a mask that sets neither a position nor a
    velocity, or numbers that are not finite."""
    frame = int(m.coordinate_frame)
    if frame not in _FRAMES:
        raise MissionError(f"setpoint frame {frame}: only MAV_FRAME_LOCAL_NED (1) is flown")
    mask = int(m.type_mask)
    pos = np.array([m.x, m.y, m.z], dtype=float)
    vel = np.array([m.vx, m.vy, m.vz], dtype=float)
    if mask & _POS_IGNORE == 0:
        if not np.all(np.isfinite(pos)):
            raise MissionError("setpoint position: not three finite numbers")
        return Setpoint(None, frames.ned_to_enu(pos), now)
    if mask & _VEL_IGNORE == 0:
        if not np.all(np.isfinite(vel)):
            raise MissionError("setpoint velocity: not three finite numbers")
        return Setpoint(frames.ned_to_enu(vel), None, now)
    raise MissionError(f"setpoint type_mask {mask:#x}: neither a position nor a velocity")


class LiveSetpoints:
    """The latest setpoint and when the last live command went (module docstring)."""

    def __init__(self, max_speed_mps: float) -> None:
        self.max_speed = float(max_speed_mps)
        self.latest: Setpoint | None = None
        self.sent_at = -math.inf  # mission time of the last live command (s)
        self.sent_velocity = np.zeros(3)

    def take(self, sp: Setpoint) -> None:
        """Keep ``sp``; a velocity above the speed limit raises :class:`MissionError`."""
        if sp.velocity is not None and float(np.linalg.norm(sp.velocity)) > self.max_speed:
            raise MissionError(f"setpoint speed {float(np.linalg.norm(sp.velocity)):.2f} m/s: "
                               f"above the mission's max_speed_mps {self.max_speed:g}")
        self.latest = sp

    def fresh(self, now: float) -> bool:
        """A setpoint came within :data:`SETPOINT_TIMEOUT_S` of wall time ``now``."""
        return self.latest is not None and now - self.latest.received <= SETPOINT_TIMEOUT_S

    def velocity(self, centroid: np.ndarray) -> np.ndarray:
        """The centroid velocity (m/s, ENU) the latest setpoint asks for, with ``centroid``
        (m) where the leaders' plan will be when it applies."""
        sp = self.latest
        if sp is None:
            return np.zeros(3)
        if sp.velocity is not None:
            return sp.velocity.copy()
        assert sp.position is not None
        v = POSITION_GAIN * (sp.position - centroid)
        speed = float(np.linalg.norm(v))
        return v * (self.max_speed / speed) if speed > self.max_speed else v

    def due(self, t: float, v: np.ndarray) -> bool:
        """A live command with velocity ``v`` should go at mission time ``t`` (s)."""
        return (t - self.sent_at >= SEND_EVERY_S
                or float(np.linalg.norm(v - self.sent_velocity)) > CHANGE_MPS)

    def restart(self) -> None:
        """The next live command goes at once (OFFBOARD was just entered)."""
        self.sent_at = -math.inf

    def sent(self, t: float, v: np.ndarray) -> None:
        self.sent_at, self.sent_velocity = float(t), np.array(v, dtype=float)
