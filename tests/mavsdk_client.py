"""An unmodified MAVSDK (the ``mavsdk`` package, native binding) connected to one
vehicle's API link of a test ``vehicle-sim`` over 127.0.0.1, shared by the tests that
drive the simulator as a PX4 client would."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from swarm_common.ports import vehicle_ports


@contextmanager
def mavsdk_autopilot(sim: Any, vehicle: int = 1) -> Iterator[Any]:
    """The MAVSDK ``System`` of ``vehicle`` (skips the test when mavsdk is missing);
    the MAVSDK instance is destroyed on exit."""
    mavsdk = pytest.importorskip("mavsdk")
    cfg = mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION)
    m = mavsdk.Mavsdk(cfg)
    try:
        m.add_any_connection(f"udpin://127.0.0.1:{vehicle_ports(vehicle, sim.offset).api_remote}")
        system = m.first_autopilot(10.0)
        assert system is not None
        yield system
    finally:
        m.destroy()


def position_ready(tel: Any) -> bool:
    """MAVSDK ``Telemetry`` reports a global position: the health flag and a finite
    latitude and longitude. MAVSDK raises the flag before its first position arrives
    (NaN until then), so a test that reads the position at once can get (NaN, NaN)."""
    pos = tel.position()
    return bool(tel.health().is_global_position_ok and math.isfinite(pos.latitude_deg)
                and math.isfinite(pos.longitude_deg))
