"""The protocol services attached to every simulated vehicle.

Each service (:class:`vehicle_sim.autopilot.nav.VehicleService`) owns one MAVLink microservice:
parameters, missions (mission, fence, rally), and information requests. The vehicle
merges their message handlers and command handlers into its own and calls their
``update`` once per step.
"""

from __future__ import annotations

from typing import Any

from vehicle_sim.services.info import InfoService
from vehicle_sim.services.mission import MissionService
from vehicle_sim.services.param import ParamService


def attach_services(vehicle: Any) -> list[Any]:
    """Create every service for ``vehicle`` and name them on it: ``vehicle.param_service``,
    ``vehicle.mission``, ``vehicle.info``; returns them in update order."""
    vehicle.param_service = ParamService(vehicle)
    vehicle.mission = MissionService(vehicle)
    vehicle.info = InfoService(vehicle)
    return [vehicle.param_service, vehicle.mission, vehicle.info]
