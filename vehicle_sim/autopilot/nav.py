"""Navigation targets: what the vehicle's own position controller flies in the AUTO modes.

The mode logic (:mod:`vehicle_sim.autopilot.modes`) and the mission executor
(:mod:`vehicle_sim.services.mission`) speak this small vocabulary, so a mission item, a
MAVSDK ``goto_location``, a ``DO_REPOSITION`` or an RTL all become one
:class:`NavTarget` in the simulator's local ENU frame (metres, z up, origin = the
scenario's origin, which is also the MAVLink home's horizontal reference).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from swarm_common.enums import NavKind

__all__ = ["MissionControl", "NavKind", "NavSource", "NavTarget", "VehicleService"]


@dataclass(frozen=True)
class NavTarget:
    """One target for the onboard position controller.

    ``position_enu``: metres, ENU z-up local frame; ``yaw_rad``: ENU yaw (None: keep);
    ``speed_m_s``: horizontal cruise speed (None: the vehicle's default)."""

    kind: NavKind
    position_enu: np.ndarray
    yaw_rad: float | None = None
    speed_m_s: float | None = None


class NavSource(Protocol):
    """Something that tells AUTO.MISSION where to fly (the mission executor)."""

    def nav_target(self, p_enu: np.ndarray, v_enu: np.ndarray, sim_t: float) -> NavTarget | None:
        """The current target, advancing items that are reached (None: mission over)."""
        ...


class MissionControl(NavSource, Protocol):
    """What the mode logic asks of the vehicle's mission service
    (:class:`vehicle_sim.services.mission.MissionService`)."""

    def start(self, sim_t: float) -> int:
        """(Re)start the stored mission; a MAV_RESULT (ACCEPTED, or why not)."""
        ...

    def rally_points_enu(self) -> list[np.ndarray]:
        """The stored rally points (ENU, m): where an RTL may return to."""
        ...


class VehicleService(Protocol):
    """A protocol service attached to one vehicle (parameters, missions, information).

    ``handlers`` maps a MAVLink message id to ``handler(msg, src, wall, sim_t)``;
    ``update`` runs once per simulation step (after the vehicle's own update)."""

    def handlers(self) -> dict[int, Any]: ...

    def update(self, sim_t: float) -> None: ...
