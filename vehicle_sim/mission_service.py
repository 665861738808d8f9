"""The mission protocol (mission, geofence, rally) and the AUTO.MISSION executor.

Contract: :class:`vehicle_sim.nav.VehicleService`.
"""

from __future__ import annotations

from typing import Any


class MissionService:
    """Attached to one :class:`~vehicle_sim.vehicle.Vehicle` (``vehicle``)."""

    def __init__(self, vehicle: Any) -> None:
        self.vehicle = vehicle

    def handlers(self) -> dict[int, Any]:
        """MAVLink message id -> ``handler(msg, src, wall, sim_t)``."""
        return {}

    def command_handlers(self) -> dict[int, Any]:
        """MAV_CMD -> ``handler(vehicle, command) -> (MAV_RESULT, reply or None)``."""
        return {}

    def update(self, sim_t: float) -> None:
        """Once per simulation step."""

    # --- used by the vehicle's AUTO.MISSION mode (vehicle_sim.nav.NavSource) -------------
    def has_mission(self) -> bool:
        """True when a mission with at least one item is stored."""
        return False

    def start(self, sim_t: float) -> int:
        """MAV_CMD_MISSION_START / entering AUTO.MISSION: a MAV_RESULT."""
        from pymavlink.dialects.v20 import common as M

        return M.MAV_RESULT_DENIED

    def nav_target(self, p_enu: Any, v_enu: Any, sim_t: float) -> Any:
        """The current :class:`~vehicle_sim.nav.NavTarget` (None: mission over)."""
        return None

    def rally_points_enu(self) -> list[Any]:
        """Rally points (ENU, m) for RTL; empty when none are stored."""
        return []
