"""The PX4 parameter protocol (PARAM_REQUEST_LIST/READ, PARAM_SET, PARAM_VALUE).

Contract: :class:`vehicle_sim.nav.VehicleService`.
"""

from __future__ import annotations

from typing import Any


class ParamService:
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
