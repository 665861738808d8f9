"""The protocol services attached to every simulated vehicle.

Each service (:class:`vehicle_sim.nav.VehicleService`) owns one MAVLink microservice:
parameters, missions (mission, fence, rally), and information requests. The vehicle
merges their message handlers into its own and calls their ``update`` each step.
"""

from __future__ import annotations

from typing import Any


def attach_services(vehicle: Any) -> list[Any]:
    """Create every service for ``vehicle`` (the vehicle merges their handlers)."""
    return []
